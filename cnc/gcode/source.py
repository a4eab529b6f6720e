"""Where program lines come from: the streamed main program and subprograms found by O number.

The main program is consumed lazily, line by line. Subprograms (M98 P...) are looked up on
demand, first among the O blocks of the main program's own text, then in the `programs`
mapping the interpreter was given. Finding an O block never stores the program: an index
keeps only (O number -> where its first line starts), one small entry per program, and is
filled by scanning forward from where the previous search stopped:

* a real file (an object with `.name` naming a file on disk, e.g. `open(path)`): a second,
  independent binary handle scans for O lines and records byte offsets; the subprogram is
  then read through its own handle seeked to that offset (O(1) memory per subprogram);
* a list/tuple of lines or a str: the index records list positions;
* any other iterable (a generator, a socket): in-file O blocks cannot be revisited without
  buffering the stream, so M98 finds subprograms only in the `programs` mapping.
"""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import NamedTuple

from cnc.errors import NcError
from cnc.gcode.lexer import parse_line

Lines = Iterator[tuple[int, str]]  # (1-based line number, text)

_O_LINE_TEXT = re.compile(r"\s*(?:/\d?\s*)?[Oo:]\s*(\d+)")
_O_LINE_BYTES = re.compile(rb"\s*(?:/\d?\s*)?[Oo:]\s*(\d+)")


class _SequenceIndex:
    def __init__(self, seq: Sequence[str]) -> None:
        self.seq = seq
        self.found: dict[int, int] = {}
        self.scanned = 0

    def find(self, number: int) -> Lines | None:
        idx = self.found.get(number)
        seq = self.seq
        while idx is None and self.scanned < len(seq):
            i = self.scanned
            self.scanned += 1
            m = _O_LINE_TEXT.match(seq[i])
            if m:
                self.found.setdefault(int(m.group(1)), i)
                if int(m.group(1)) == number:
                    idx = i
        if idx is None:
            return None
        return ((i + 1, seq[i]) for i in range(idx, len(seq)))


class _FileIndex:
    """Byte-offset index of O lines in a file on disk, filled by a forward scan on demand."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.found: dict[int, tuple[int, int]] = {}  # O number -> (byte offset, line number)
        self.offset = 0
        self.lineno = 0
        self.done = False

    def find(self, number: int) -> Lines | None:
        hit = self.found.get(number)
        if hit is None and not self.done:
            with open(self.path, "rb") as fh:
                fh.seek(self.offset)
                for raw in fh:
                    self.lineno += 1
                    m = _O_LINE_BYTES.match(raw)
                    if m:
                        num = int(m.group(1))
                        self.found.setdefault(num, (self.offset, self.lineno))
                    self.offset += len(raw)
                    if m and num == number:
                        hit = self.found[number]
                        break
                else:
                    self.done = True
        if hit is None:
            return None
        return _read_file_from(self.path, *hit)


def _read_file_from(path: str, offset: int, lineno: int) -> Lines:
    with open(path, "rb") as fh:
        fh.seek(offset)
        for raw in fh:
            yield lineno, raw.decode("latin-1").rstrip("\r\n")
            lineno += 1


def _index_for(lines: object) -> _SequenceIndex | _FileIndex | None:
    if isinstance(lines, str):
        return _SequenceIndex(lines.splitlines())
    if isinstance(lines, Sequence):
        return _SequenceIndex(lines)  # type: ignore[arg-type]
    name = getattr(lines, "name", None)
    if isinstance(name, str) and os.path.isfile(name):
        return _FileIndex(name)
    return None


def main_lines(lines: Iterable[str] | str) -> Lines:
    """Number the main program's lines without reading ahead."""
    if isinstance(lines, str):
        lines = lines.splitlines()
    return enumerate(lines, 1)


LEADER_LOOKAHEAD = 64  # lines searched for the '%' that ends a tape leader


def skip_leader(numbered: Lines) -> Lines:
    """Drop a tape leader: text before the program-start '%' (DIN 66025, 000 REQ-PRG-1).

    Only when the first non-blank line is not a block (it does not lex) is anything read
    ahead: up to LEADER_LOOKAHEAD lines are searched for a lone '%'. If one is found and
    nothing before it is a block, the lines before it are dropped; otherwise every line is
    handed on unchanged (and the bad first line gets its error as usual).
    """
    it = iter(numbered)
    buffered: list[tuple[int, str]] = []
    for item in it:
        buffered.append(item)
        text = item[1].strip()
        if not text:
            continue
        if text.startswith("%"):
            break
        try:
            is_block = parse_line(item[1], item[0]) is not None
        except NcError:
            is_block = False
        if is_block:
            break
        # leader candidate: look for the '%' within the window
        for nxt in it:
            buffered.append(nxt)
            t = nxt[1].strip()
            if t.startswith("%") and not t.strip("% \t"):
                buffered = buffered[-1:]  # everything before the '%' is leader
                break
            if len(buffered) >= LEADER_LOOKAHEAD:
                break
            if t:
                try:
                    if parse_line(nxt[1], nxt[0]) is not None:
                        break  # a real block: there is no leader
                except NcError:
                    pass
        break
    return itertools.chain(buffered, it)


_M99_AT_END = re.compile(r"(?<![A-Z0-9.])M0*99(?![0-9.])")
_COMMENTS = re.compile(r"\([^)]*\)|;.*")
TAIL_BYTES = 4096  # the end of a file read to find its last block


def ends_with_m99(source: Sequence[str] | str | None) -> bool:
    """Whether the program's last block (blanks, comments and '%' aside) holds M99: a
    subprogram file. `source` is the main program's lines or a file path (only its last
    TAIL_BYTES are read); None (a stream) answers False."""
    if source is None:
        return False
    if isinstance(source, str):
        with open(source, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - TAIL_BYTES))
            lines: Sequence[str] = fh.read().decode("latin-1").splitlines()
    else:
        lines = source
    for raw in reversed(lines):
        text = _COMMENTS.sub("", raw).strip().upper()
        if text and not text.startswith("%"):
            return bool(_M99_AT_END.search(text))
    return False


class ProgramLibrary:
    """Resolves program numbers for M98: in-file O blocks first, then the `programs` mapping."""

    def __init__(self, programs: Mapping[int, str | Iterable[str]] | None) -> None:
        # kept, not copied: a program memory or a library database answers `in` and `[]`
        # when a call needs the program, not every program's text up front
        self.programs: Mapping[int, str | Iterable[str]] = programs if programs is not None else {}
        self.in_file: _SequenceIndex | _FileIndex | None = None
        self.main_file = "<program>"
        self._mapped: dict[int, _SequenceIndex | _FileIndex] = {}

    def attach(self, lines: object, file: str) -> None:
        self.in_file = _index_for(lines)
        self.main_file = file

    def main_source(self) -> list[str] | str | None:
        """The main program's lines for jumps (GOTO, WHILE): a list, a file path or None."""
        return _source_of(self.in_file)

    def open(self, number: int) -> Opened | None:
        """Program O`number`: its lines, file name, source for jumps and first line number."""
        if self.in_file is not None:
            hit = self.in_file.find(number)
            if hit is not None:
                return Opened(
                    hit, self.main_file, _source_of(self.in_file), _first(self.in_file, number)
                )
        if number not in self.programs:
            return None
        idx = self._mapped.get(number)
        if idx is None:
            prog = self.programs[number]
            idx = _index_for(prog)
            if idx is None:  # a one-shot iterable: it is in memory already, keep it as a list
                idx = _SequenceIndex(list(prog))
            self._mapped[number] = idx
        if isinstance(idx, _FileIndex):
            hit = idx.find(number)  # a library file may hold several programs
            if hit is not None:
                return Opened(hit, idx.path, idx.path, idx.found[number][1])
            return Opened(_read_file_from(idx.path, 0, 1), idx.path, idx.path, 1)
        seq = idx.seq
        return Opened(((i + 1, seq[i]) for i in range(len(seq))), f"O{number}", seq, 1)


class Opened(NamedTuple):
    lines: Lines
    file: str
    source: list[str] | str | None  # random access for jumps: lines, a file path, or None
    start: int  # line number of the program's first line (its O line)


def _source_of(idx: _SequenceIndex | _FileIndex | None):
    if isinstance(idx, _SequenceIndex):
        return idx.seq
    if isinstance(idx, _FileIndex):
        return idx.path
    return None


def _first(idx: _SequenceIndex | _FileIndex, number: int) -> int:
    if isinstance(idx, _FileIndex):
        return idx.found[number][1]
    return idx.found[number] + 1


class ProgramFile:
    """A program file on disk, as a `programs` mapping value: read when called, by offset."""

    __slots__ = ("name",)

    def __init__(self, path: str) -> None:
        self.name = path

    def __iter__(self) -> Iterator[str]:
        with open(self.name, encoding="latin-1") as fh:
            yield from fh

    def __repr__(self) -> str:
        return f"ProgramFile({self.name!r})"


def library_programs(folder: str) -> tuple[dict[int, ProgramFile], list[str]]:
    """The programs of a folder by O number (every O line of every file in it).

    Returns the mapping for the interpreter's `programs` and warnings: an O number found in
    two files is taken from the first (by file name) and named in a warning.
    """
    found: dict[int, ProgramFile] = {}
    warnings: list[str] = []
    for entry in sorted(os.scandir(folder), key=lambda e: e.name):
        if not entry.is_file():
            continue
        pf = ProgramFile(entry.path)
        with open(entry.path, "rb") as fh:
            for lineno, raw in enumerate(fh, 1):
                m = _O_LINE_BYTES.match(raw)
                if not m:
                    continue
                number = int(m.group(1))
                prev = found.get(number)
                if prev is None:
                    found[number] = pf
                elif prev.name != entry.path:
                    warnings.append(
                        f"{entry.path}:{lineno}:1: warning: O{number} is also in {prev.name} "
                        "(that one is used)"
                    )
    return found, warnings


class Pushback:
    """A line iterator that takes lines back (`push`): a lathe cycle looks at the block after
    it for its contour (N P) and returns the lines when the contour is elsewhere."""

    __slots__ = ("_it", "_back", "last")

    def __init__(self, it: Iterable[tuple[int, str]]) -> None:
        self._it = iter(it)
        self._back: list[tuple[int, str]] = []
        # the line last handed out, comments and all (G47 engraves its block's comment)
        self.last: tuple[int, str] | None = None

    def __iter__(self) -> Pushback:
        return self

    def __next__(self) -> tuple[int, str]:
        item = self._back.pop() if self._back else next(self._it)
        self.last = item
        return item

    def push(self, item: tuple[int, str]) -> None:
        self._back.append(item)
