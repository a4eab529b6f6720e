"""Which other programs a program calls: `M98 P`, `G65 P`, `G66 P` read off its text.

A static scan, one pass over the lines, no interpretation: every call with a literal
program number counts, taken or not (an `IF [...] GOTO` may skip it at the machine, but the
program needs it wherever it may go). A call whose P is a variable or an expression
(`G65 P#1`) is named only when the program runs. Calls to an O block of the same text are
in-file subprograms, not dependencies.

Fanuc's 4-digit form `M98 P00051000` (no L: repeat 5 times, program O1000) is ambiguous
with an 8-digit O number; as the interpreter does, the number itself is taken when such a
program exists, else its last four digits (`Call.candidates`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from cnc.gcode.source import _O_LINE_TEXT

_COMMENT = re.compile(r"\([^)]*\)|;.*")
# the call code, not part of a longer word or number (G90G65 is a call, #1M98 or M980 not)
_CALL = re.compile(r"(?<![A-Z#])(M\s*0*98|G\s*0*6[56])(?![0-9.])")
_P = re.compile(r"P\s*(\d+)(?![0-9.#\[])")
_L = re.compile(r"(?<![A-Z])L\s*[0-9#\[]")


@dataclass(frozen=True, slots=True)
class Call:
    code: str  # M98 | G65 | G66
    number: int  # the P word as written
    line: int
    col: int  # column of the P word
    packed: bool = False  # M98 Pxxxxnnnn without L: may be 'repeat xxxx, program Onnnn'

    @property
    def candidates(self) -> tuple[int, ...]:
        """The O numbers the call may mean, in the order the interpreter tries them."""
        if self.packed and self.number >= 10000:
            return (self.number, self.number % 10000)
        return (self.number,)

    @property
    def short(self) -> int | None:
        """The 4-digit O number a packed call means when its own number does not exist."""
        c = self.candidates
        return c[1] if len(c) > 1 else None

    def resolve(self, exists: Callable[[int], bool]) -> int | None:
        """The O number the call reaches given which programs exist, or None (missing)."""
        for n in self.candidates:
            if exists(n):
                return n
        return None

    def named(self) -> int:
        """The number an alarm names when nothing answers (the interpreter's last try)."""
        return self.candidates[-1]


@dataclass(slots=True)
class ProgramCalls:
    defined: set[int] = field(default_factory=set)  # O blocks of the text itself
    calls: list[Call] = field(default_factory=list)  # calls to other programs

    @property
    def numbers(self) -> list[int]:
        return sorted({c.number for c in self.calls})


def program_calls(lines: Iterable[str]) -> ProgramCalls:
    """Scan a program's lines (a file object, a list, or a str's splitlines) once."""
    found = ProgramCalls()
    every: list[Call] = []
    for lineno, raw in enumerate(lines, 1):
        if "O" in raw or "o" in raw or ":" in raw:
            m = _O_LINE_TEXT.match(raw)
            if m:
                found.defined.add(int(m.group(1)))
        if "P" not in raw and "p" not in raw:
            continue  # most blocks: no P word, no call
        text = _COMMENT.sub(lambda c: " " * len(c.group(0)), raw.upper())
        code = _CALL.search(text)
        if code is None:
            continue
        p = _P.search(text, code.end()) or _P.search(text, 0, code.start())
        if p is None:
            continue
        name = code.group(1)[0] + code.group(1)[-2:]
        packed = name == "M98" and not _L.search(text)
        every.append(Call(name, int(p.group(1)), lineno, p.start() + 1, packed))
    found.calls = [c for c in every if not any(n in found.defined for n in c.candidates)]
    return found
