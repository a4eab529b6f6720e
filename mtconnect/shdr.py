"""Reading SHDR on the agent side: the tokenizer and the line parser (pure).

The tokenizer reads values the way the reference agent does: tokens are split at `|`,
trimmed; a token that starts with `"` runs to a closing `"` followed by `|` or the end of the
line, and inside it a backslash makes the next character literal (so `"a\\|b"` is `a|b`).
"""

from __future__ import annotations

from dataclasses import dataclass

UNAVAILABLE_VALUES = frozenset({"UNAVAILABLE", "@UNAVAILABLE@"})
CONDITION_LEVELS = frozenset({"NORMAL", "WARNING", "FAULT", "UNAVAILABLE"})


def tokenize(line: str) -> list[str]:
    tokens: list[str] = []
    i, n = 0, len(line)
    while i < n:
        while i < n and line[i].isspace():
            i += 1
        if i < n and line[i] == '"':
            token, j, closed = _quoted(line, i + 1)
            if closed:
                tokens.append(token.rstrip())
                i = j
            else:  # no closing quote: the raw text up to the next `|`, quote included
                j = line.find("|", i)
                j = n if j < 0 else j
                tokens.append(line[i:j].rstrip())
                i = j
        else:
            j = line.find("|", i)
            j = n if j < 0 else j
            tokens.append(line[i:j].rstrip())
            i = j
        if i < n and line[i] == "|":
            if i + 1 == n:
                tokens.append("")  # a terminal `|` ends with an empty token
            i += 1
    return tokens


def _quoted(line: str, i: int) -> tuple[str, int, bool]:
    """Text of a quoted token starting after its `"`: (text, index of the `|` or end after
    the closing quote, closed)."""
    out: list[str] = []
    n = len(line)
    while i < n:
        c = line[i]
        if c == "\\" and i + 1 < n:
            out.append(line[i + 1])
            i += 2
            continue
        if c == "|":
            return "", i, False
        if c == '"':
            k = i + 1
            while k < n and line[k].isspace():
                k += 1
            if k == n or line[k] == "|":
                return "".join(out), k, True
            return "", i, False
        out.append(c)
        i += 1
    return "", n, False


@dataclass(frozen=True, slots=True)
class ShdrValue:
    key: str
    value: str
    level: str = ""
    native_code: str = ""
    native_severity: str = ""
    qualifier: str = ""


def parse_line(line: str, conditions: frozenset[str] | set[str]) -> tuple[str, list[ShdrValue]]:
    """(timestamp token, values) of one data line. `conditions` are the keys that take the
    five condition fields; every other key takes one value."""
    tokens = tokenize(line)
    if not tokens:
        return "", []
    ts, rest = tokens[0], tokens[1:]
    out: list[ShdrValue] = []
    i = 0
    while i < len(rest):
        key = rest[i]
        if key in conditions:
            fields = rest[i + 1 : i + 6]
            fields += [""] * (5 - len(fields))
            level = fields[0].upper()
            out.append(ShdrValue(key, fields[4], level, fields[1], fields[2], fields[3]))
            i += 6
        else:
            value = rest[i + 1] if i + 1 < len(rest) else ""
            out.append(ShdrValue(key, value))
            i += 2
    return ts, out
