"""Unified diff between revisions, with the normalisations programmers ask for."""

from __future__ import annotations

import difflib
import re

_SEQUENCE = re.compile(r"^(\s*/?\s*)N\d+\s*", re.I)
_PAREN_COMMENT = re.compile(r"\([^)]*\)")
_SEMI_COMMENT = re.compile(r";.*$")


def normalise_line(
    line: str, *, ignore_numbers: bool, ignore_whitespace: bool, ignore_comments: bool
) -> str:
    if ignore_numbers:
        line = _SEQUENCE.sub(r"\1", line)
    if ignore_comments:
        line = _SEMI_COMMENT.sub("", _PAREN_COMMENT.sub("", line)).strip()
    if ignore_whitespace:
        line = "".join(line.split())
    return line


def unified_diff(
    a: str,
    b: str,
    *,
    a_name: str = "a",
    b_name: str = "b",
    ignore_numbers: bool = False,
    ignore_whitespace: bool = False,
    ignore_comments: bool = False,
    context: int = 3,
) -> str:
    """Diff of `a` against `b`; ignored differences do not appear, the lines shown are b's own.

    Comparison runs on normalised lines but the output prints the original lines, so the
    programmer sees real text, not the normalised form.
    """
    opts = dict(
        ignore_numbers=ignore_numbers,
        ignore_whitespace=ignore_whitespace,
        ignore_comments=ignore_comments,
    )
    a_num, a_lines, a_norm = _compared(a, opts)
    b_num, b_lines, b_norm = _compared(b, opts)
    out: list[str] = []
    matcher = difflib.SequenceMatcher(None, a_norm, b_norm, autojunk=False)
    for group in matcher.get_grouped_opcodes(context):
        if not out:
            out += [f"--- {a_name}", f"+++ {b_name}"]
        i1, i2, j1, j2 = group[0][1], group[-1][2], group[0][3], group[-1][4]
        out.append(f"@@ -{_range(a_num, i1, i2)} +{_range(b_num, j1, j2)} @@")
        for tag, ai1, ai2, bj1, bj2 in group:
            if tag == "equal":
                out += [" " + ln for ln in b_lines[bj1:bj2]]
                continue
            out += ["-" + ln for ln in a_lines[ai1:ai2]]
            out += ["+" + ln for ln in b_lines[bj1:bj2]]
    return "\n".join(out) + ("\n" if out else "")


def _compared(text: str, opts: dict) -> tuple[list[int], list[str], list[str]]:
    """Original line numbers, original lines and normalised lines of the lines compared.

    When comments or whitespace are ignored, lines that normalise to nothing (pure comments,
    blank lines) are left out of the comparison; hunk headers still count original lines.
    """
    skip_empty = opts["ignore_comments"] or opts["ignore_whitespace"]
    numbers, lines, norm = [], [], []
    for number, line in enumerate(text.splitlines(), start=1):
        n = normalise_line(line, **opts)
        if skip_empty and not n:
            continue
        numbers.append(number)
        lines.append(line)
        norm.append(n)
    return numbers, lines, norm


def _range(numbers: list[int], start: int, stop: int) -> str:
    """A hunk range in original line numbers (unified format: `first,count`)."""
    if start == stop:
        before = numbers[start - 1] if start > 0 else 0
        return f"{before},0"
    first, last = numbers[start], numbers[stop - 1]
    count = last - first + 1
    return f"{first}" if count == 1 else f"{first},{count}"
