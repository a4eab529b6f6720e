"""APT lexer: source text -> statements of tokens, each with its line and column.

A statement ends at the end of a line or at `;` (the thesis writes `;`); a line whose last
non-blank character is `$` continues on the next line; `$$` starts a comment. After
PARTNO, PPRINT, REMARK and INSERT the rest of the line is free text.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from cam.errors import CamError

TEXT_MAJORS = frozenset({"PARTNO", "PPRINT", "REMARK", "INSERT"})
NAME_MAX = 6  # APT: names and words are at most six characters


@dataclass(frozen=True, slots=True)
class Token:
    kind: str  # NAME NUMBER OP TEXT
    value: str
    line: int
    col: int


_OPS = {"=", "/", ",", "(", ")", "+", "-", "*", ";"}


def _line_tokens(s: str, ln: int, file: str, first: bool) -> tuple[list[Token], bool]:
    """Tokens of one physical line and whether it continues ('$')."""
    out: list[Token] = []
    i, n = 0, len(s)
    at_start = first
    while i < n:
        ch = s[i]
        col = i + 1
        if ch in " \t\r\f":
            i += 1
            continue
        if ch == "$":
            if s.startswith("$$", i):
                break  # comment to the end of the line
            rest = s[i + 1 :].strip()
            if rest and not rest.startswith("$$"):
                raise CamError("'$' continues a statement: nothing may follow it", ln, col, file)
            return out, True
        if ch.isalpha():
            j = i
            while j < n and (s[j].isalnum()):
                j += 1
            word = s[i:j].upper()
            if j < n and s[j] == "." and j + 1 < n and s[j + 1].isdigit():
                k = j + 1
                while k < n and s[k].isalnum():
                    k += 1
                raise CamError(
                    f"invalid name {s[i:k]!r}: names hold only letters and digits (no '.')",
                    ln,
                    col,
                    file,
                )
            out.append(Token("NAME", word, ln, col))
            i = j
            if at_start and word in TEXT_MAJORS and (not out[:-1] or _after_label(out)):
                text = s[i:].strip()
                if text.startswith("/"):
                    text = text[1:].strip()
                out.append(Token("TEXT", text, ln, i + 1))
                return out, False
            at_start = False
            continue
        if ch.isdigit() or (ch == "." and i + 1 < n and s[i + 1].isdigit()):
            j = i
            while j < n and s[j].isdigit():
                j += 1
            if j < n and s[j] == ".":
                j += 1
                while j < n and s[j].isdigit():
                    j += 1
            if j < n and s[j] in "eE":  # an exponent: 1.5E-3
                k = j + 1
                if k < n and s[k] in "+-":
                    k += 1
                if k < n and s[k].isdigit():
                    while k < n and s[k].isdigit():
                        k += 1
                    j = k
            if j < n and s[j].isalpha():
                k = j
                while k < n and s[k].isalnum():
                    k += 1
                raise CamError(
                    f"invalid name {s[i:k]!r}: a name must start with a letter", ln, col, file
                )
            out.append(Token("NUMBER", s[i:j], ln, col))
            i = j
            at_start = False
            continue
        if ch == "*" and s.startswith("**", i):
            out.append(Token("OP", "**", ln, col))
            i += 2
            continue
        if ch in _OPS:
            out.append(Token("OP", ch, ln, col))
            if ch == ";":
                at_start = True
            elif ch == ")" and len(out) == 2 and out[0].kind == "NAME":
                at_start = True  # after a statement label
            else:
                at_start = False
            i += 1
            continue
        raise CamError(f"invalid character {ch!r}", ln, col, file)
    return out, False


def _after_label(out: list[Token]) -> bool:
    return len(out) == 3 and out[0].kind == "NAME" and out[1].value == ")"


def statements(text: str, file: str = "<apt>") -> Iterator[list[Token]]:
    """The statements of APT source, as token lists (never empty)."""
    pending: list[Token] = []
    for ln, raw in enumerate(text.splitlines(), 1):
        toks, cont = _line_tokens(raw, ln, file, not pending)
        pending.extend(toks)
        if cont:
            continue
        stmt: list[Token] = []
        for t in pending:
            if t.kind == "OP" and t.value == ";":
                if stmt:
                    yield stmt
                stmt = []
            else:
                stmt.append(t)
        if stmt:
            yield stmt
        pending = []
    if pending:
        t = pending[-1]
        raise CamError(
            "the last statement continues ('$') past the end of the file", t.line, t.col, file
        )
