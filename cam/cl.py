"""CL data: the cutter-location file between the processor and the post-processor.

The text form CAM systems export as "APT source" / "CL source" (CATIA `.aptsource`, NX
`.cls`): one statement a line, `MAJOR/arg,arg,...`, a trailing `$` continues the statement
on the next line, `$$` starts a comment. Motion records carry the tool tip and, in
multi-axis data, the tool-axis direction cosines: `GOTO/x,y,z[,i,j,k]`.

Records this module knows the shape of (the posts decide what they can execute):

    PARTNO text   PPRINT text   INSERT text        free text to the end of the line
    MACHIN/name,n   UNITS/INCHES|MM   CUTTER/d[,r,...]   MULTAX[/ON|OFF]
    FROM/x,y,z[,i,j,k]   GOTO/x,y,z[,i,j,k]   TLAXIS/i,j,k
    CIRCLE/xc,yc,zc,i,j,k,r[,...]   (the next GOTO ends the arc; i,j,k is its axis,
                                     counter-clockwise about it)
    RAPID   FEDRAT/f[,IPM|IPR|MMPM|MMPR]   LOADTL/n   SPINDL/n,CLW|CCLW | SPINDL/OFF
    COOLNT/ON|FLOOD|MIST|OFF   CUTCOM/LEFT|RIGHT|OFF   DELAY/s   STOP   OPSTOP   END   FINI

The reader is a generator (memory flat in the file's size); the writer formats numbers
with `repr` so that records -> text -> records is exact, and so is the writer's own text ->
records -> text. Comments and the original spelling of numbers are not kept.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TextIO

from cam.errors import CamError, CamWarning, WarningSink, ignore_warning

__all__ = [
    "ClRecord",
    "LINE_WIDTH",
    "TEXT_WORDS",
    "VECTOR_TOLERANCE",
    "format_record",
    "read_cl",
    "write_cl",
]

TEXT_WORDS = frozenset({"PARTNO", "PPRINT", "INSERT", "REMARK"})
VECTOR_TOLERANCE = 1e-3  # | |v| - 1 | accepted (and normalised) for a tool-axis vector
VECTOR_EXACT = 1e-9  # closer than this to unit length: kept as written
VECTOR_PRINTED = 1e-6  # closer than this: the rounding of 6-7 printed decimals, normalised silently
LINE_WIDTH = 72  # the card width CL writers keep to; longer statements continue with `$`

_WORD = re.compile(r"[A-Z][A-Z0-9]*\Z")
_NUMBER_START = frozenset("+-.0123456789")


@dataclass(slots=True, eq=False)
class ClRecord:
    """One CL statement: the major word, its arguments (numbers as float, minor words as
    upper-case str), free text for PARTNO/PPRINT/INSERT, and the source line (not part of
    equality). Treat it as immutable (not frozen only because a frozen dataclass is slow to
    build, and a post builds one per CL line)."""

    word: str
    args: tuple[float | str, ...] = ()
    text: str | None = None
    line: int = 0

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ClRecord):
            return NotImplemented
        return (self.word, self.args, self.text) == (other.word, other.args, other.text)

    def __hash__(self) -> int:
        return hash((self.word, self.args, self.text))

    @property
    def numbers(self) -> tuple[float, ...]:
        return tuple(a for a in self.args if isinstance(a, float))

    @property
    def words(self) -> tuple[str, ...]:
        return tuple(a for a in self.args if isinstance(a, str))


# --- writer ---------------------------------------------------------------------------------


def _num(x: float) -> str:
    return repr(float(x))


def format_record(rec: ClRecord) -> list[str]:
    """The record as text lines (several when it is longer than LINE_WIDTH)."""
    if rec.word in TEXT_WORDS:
        return [f"{rec.word} {rec.text or ''}".rstrip()]
    if not rec.args:
        return [rec.word]
    parts = [a if isinstance(a, str) else _num(a) for a in rec.args]
    lines: list[str] = []
    cur = rec.word + "/" + parts[0]
    for p in parts[1:]:
        if len(cur) + 1 + len(p) + 1 > LINE_WIDTH:  # +1 for the comma, +1 for the `$`
            lines.append(cur + ",$")
            cur = p
        else:
            cur += "," + p
    lines.append(cur)
    return lines


def write_cl(records: Iterable[ClRecord], out: TextIO) -> int:
    """Write records, one statement a line; returns the number of records written."""
    n = 0
    for rec in records:
        for ln in format_record(rec):
            out.write(ln)
            out.write("\n")
        n += 1
    return n


# --- reader ---------------------------------------------------------------------------------


def _statements(lines: Iterable[str], file: str) -> Iterator[tuple[int, Any]]:
    """(first line number, statement text) with continuations joined, comments and blank
    lines dropped."""
    pending: list[str] = []
    start = 0
    n = 0
    for n, raw in enumerate(lines, 1):  # noqa: B007 - n is used after the loop
        if not pending and raw.startswith("GOTO/"):
            # the fast path for the commonest record by far; anything unusual in it
            # (continuation, comment, a bad number) takes the general path below
            body = raw[5:].rstrip()
            if body.isascii() and "$" not in body and "_" not in body:
                try:
                    vals = [float(x) for x in body.split(",")]
                except ValueError:
                    vals = None
                if vals is not None and len(vals) in (3, 6) and math.isfinite(sum(vals)):
                    yield n, vals
                    continue
        s = raw.rstrip("\r\n")
        head = s.lstrip()[:6].upper()
        if not pending and any(head.startswith(w) for w in TEXT_WORDS):
            yield n, s.strip()
            continue
        cut = s.find("$$")
        if cut >= 0:
            s = s[:cut]
        s = s.strip()
        if not s:
            continue
        if not pending:
            start = n
        if s.endswith("$"):
            pending.append(s[:-1])
            continue
        if pending:
            pending.append(s)
            s = "".join(pending)
            pending = []
        yield start, s
    if pending:
        raise CamError(
            "the last statement continues ('$') past the end of the file", start, 1, file
        )


def _vector(vals: list[float], at: int, line: int, file: str, warn: WarningSink, what: str) -> None:
    """Normalise vals[at:at+3] in place: within VECTOR_TOLERANCE of unit length with a
    warning, refused beyond."""
    i, j, k = vals[at], vals[at + 1], vals[at + 2]
    n = math.sqrt(i * i + j * j + k * k)
    if abs(n - 1.0) <= VECTOR_EXACT:
        return
    if abs(n - 1.0) <= VECTOR_PRINTED:
        vals[at], vals[at + 1], vals[at + 2] = i / n, j / n, k / n
        return
    if not abs(n - 1.0) <= VECTOR_TOLERANCE:
        raise CamError(
            f"{what} tool-axis vector ({i:g}, {j:g}, {k:g}) is not a unit vector"
            f" (|v| = {n:.7g}; accepted within {VECTOR_TOLERANCE:g})",
            line,
            1,
            file,
        )
    warn(CamWarning(f"{what} tool-axis vector normalised (|v| = {n:.9g})", line, 1, file))
    vals[at], vals[at + 1], vals[at + 2] = i / n, j / n, k / n


def _parse(line: int, s: str, file: str, warn: WarningSink) -> ClRecord:
    slash = s.find("/")
    if slash < 0:
        word = s.strip().upper()
        if not _WORD.match(word):
            raise CamError(f"not a CL statement: {s!r}", line, 1, file)
        return ClRecord(word, (), None, line)
    word = s[:slash].strip().upper()
    if not _WORD.match(word):
        raise CamError(f"not a CL major word: {s[:slash].strip()!r}", line, 1, file)
    args: list[float | str] = []
    col = slash + 2
    for part in s[slash + 1 :].split(","):
        p = part.strip()
        if not p:
            raise CamError(f"{word}: empty argument", line, col, file)
        if p[0] in _NUMBER_START:
            try:
                v = float(p)
            except ValueError:
                raise CamError(f"{word}: not a number: {p!r}", line, col, file) from None
            if not math.isfinite(v) or "_" in p:
                raise CamError(f"{word}: not a finite number: {p!r}", line, col, file)
            args.append(v)
        else:
            w = p.upper()
            if not _WORD.match(w):
                raise CamError(f"{word}: not a number or minor word: {p!r}", line, col, file)
            args.append(w)
        col += len(part) + 1
    if word in ("GOTO", "FROM", "TLAXIS", "CIRCLE", "INDIRV"):
        want = {"GOTO": (3, 6), "FROM": (3, 6), "TLAXIS": (3,), "INDIRV": (3,)}.get(word)
        if any(isinstance(a, str) for a in args):
            raise CamError(f"{word} takes numbers only", line, slash + 2, file)
        vals = [float(a) for a in args]  # type: ignore[arg-type]
        if want is not None and len(vals) not in want:
            counts = " or ".join(str(w) for w in want)
            raise CamError(f"{word} needs {counts} numbers, got {len(vals)}", line, slash + 2, file)
        if word == "CIRCLE" and len(vals) < 7:
            raise CamError(
                f"CIRCLE needs xc,yc,zc,i,j,k,r (7 numbers), got {len(vals)}", line, slash + 2, file
            )
        if len(vals) >= 6 and word in ("GOTO", "FROM"):
            _vector(vals, 3, line, file, warn, word)
        elif word == "TLAXIS":
            _vector(vals, 0, line, file, warn, word)
        elif word == "CIRCLE":
            _vector(vals, 3, line, file, warn, "CIRCLE axis")
        return ClRecord(word, tuple(vals), None, line)
    return ClRecord(word, tuple(args), None, line)


def read_cl(
    source: Iterable[str] | str,
    file: str = "<cl>",
    warn: WarningSink = ignore_warning,
) -> Iterator[ClRecord]:
    """The records of CL text, one at a time (a file object is read line by line)."""
    lines = source.splitlines() if isinstance(source, str) else source
    for line, s in _statements(lines, file):
        if s.__class__ is list:  # a GOTO read by the fast path
            if len(s) == 6:
                i, j, k = s[3], s[4], s[5]
                n2 = i * i + j * j + k * k
                if not -2 * VECTOR_EXACT <= n2 - 1.0 <= 2 * VECTOR_EXACT:
                    if -2 * VECTOR_PRINTED <= n2 - 1.0 <= 2 * VECTOR_PRINTED:
                        n = math.sqrt(n2)
                        s[3], s[4], s[5] = i / n, j / n, k / n
                    else:
                        _vector(s, 3, line, file, warn, "GOTO")
            yield ClRecord("GOTO", tuple(s), None, line)
            continue
        head = s[:6].upper()
        for w in TEXT_WORDS:
            if head.startswith(w) and (len(s) == len(w) or s[len(w)] in " /"):
                yield ClRecord(w, (), s[len(w) + 1 :] if len(s) > len(w) else "", line)
                break
        else:
            yield _parse(line, s, file, warn)
