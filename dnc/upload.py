"""An uploaded program streamed to a temporary file, validated and hashed as it arrives.

A 15 MB upload used to be held in memory several times over (the request body, the decoded
text, its normalised copies, a list of its lines for the NC check, the encoded forms for the
hash and the size): four at once took the host to almost 1 GB. Here each chunk is checked
against the ISO 6983 / EIA character set, normalised (DC1-DC4 stripped, CR LF and CR to LF)
and hashed on the way to a temporary file; the NC check reads its lines from that file, and
the store reads it back a chunk at a time (dnc.content).

The rules and messages are those of `dnc.tape.decode_program`: the first byte outside the
character set is refused with its byte offset, line and column.
"""

from __future__ import annotations

import contextlib
import hashlib
import re
import tempfile
from collections.abc import Iterator
from typing import IO

from dnc.content import line_chunks
from dnc.errors import InvalidUpload
from dnc.tape import check_size

CHUNK = 1 << 20
_OUTSIDE = re.compile(rb"[^\t\n\r\x11-\x14\x20-\x7e]")
_TAPE_CONTROL = b"\x11\x12\x13\x14"  # DC1-DC4: tape reader control, stripped
_HEAD = 4096  # kept for the tape header (number, title) and the parity hint


def _whole_utf8(data: bytes) -> bool:
    """Whether `data` starts with one complete UTF-8 character (or a byte that starts none,
    which no further byte can mend)."""
    lead = data[0]
    need = (
        2 if lead >> 5 == 0b110 else 3 if lead >> 4 == 0b1110 else 4 if lead >> 3 == 0b11110 else 1
    )
    return len(data) >= need


class ProgramUpload:
    """Feed bytes with `feed()` (any chunking), then `finish()`; use as a context manager
    (the temporary file goes with it)."""

    def __init__(self, *, limit: int, name: str = "upload") -> None:
        self.limit, self.name = limit, name
        self.size = 0  # bytes received
        self.stored_size = 0  # bytes of the stored (normalised) form
        self.newlines = 0  # LFs in the stored form
        self.head = b""  # the first _HEAD bytes received
        self._file: IO[bytes] = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed by close()
            prefix="fmscell-upload-", suffix=".nc"
        )
        self._sha = hashlib.sha256()
        self._line = 1  # line of the next received byte (LFs received + 1)
        self._line_start = 0  # offset of the first byte of that line
        self._cr = False  # a CR held back: CR LF may be split between two chunks
        self._content = False  # something other than blanks and % seen
        self._last = b""
        self._held: tuple[int, bytes] | None = None  # (offset, bytes) of a split refusal
        self._held_where: tuple[int, int, bytes] | None = None
        self.finished = False

    # ------------------------------------------------------------------ receiving
    def feed(self, chunk: bytes) -> None:
        if not chunk:
            return
        at = self.size
        self.size += len(chunk)
        check_size(self.size, limit=self.limit, name=self.name)
        if len(self.head) < _HEAD:
            self.head += chunk[: _HEAD - len(self.head)]
        if self._held is not None:  # a refused character split between two chunks
            held_at, held = self._held
            raise self._refusal(held + chunk[:3], 0, held_at, final=True)
        bad = _OUTSIDE.search(chunk)
        if bad is not None:
            i = bad.start()
            if chunk[i] >= 0x80 and len(chunk) - i < 4 and not _whole_utf8(chunk[i:]):
                # its UTF-8 sequence may go on in the next chunk: name it then (or at finish)
                self._held = (at + i, chunk[i:])
                self._held_where = (self._line, self._line_start, chunk[:i])
                return
            raise self._refusal(chunk, i, at)
        lf = chunk.count(b"\n")
        if lf:
            self._line += lf
            self._line_start = at + chunk.rfind(b"\n") + 1
        data = chunk.translate(None, _TAPE_CONTROL)
        if self._cr:
            data = b"\r" + data
        self._cr = data.endswith(b"\r")
        if self._cr:
            data = data[:-1]
        if b"\r" in data:
            data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        self._store(data)

    def _store(self, data: bytes) -> None:
        if not data:
            return
        if not self._content and data.strip(b"%\n \t"):
            self._content = True
        self._sha.update(data)
        self._file.write(data)
        self.stored_size += len(data)
        self.newlines += data.count(b"\n")
        self._last = data[-1:]

    def finish(self) -> ProgramUpload:
        """End of the upload: InvalidUpload if it holds no program."""
        if self._held is not None:
            held_at, held = self._held
            raise self._refusal(held, 0, held_at, final=True)
        if self._cr:
            self._cr = False
            self._store(b"\n")
        if not self._content:
            raise InvalidUpload(f"{self.name}: the program is empty")
        self._file.flush()
        self.finished = True
        return self

    def _refusal(self, chunk: bytes, i: int, at: int, final: bool = False) -> InvalidUpload:
        offset = at + i
        if final and self._held_where is not None:
            # the line counters stopped before the chunk that held the character
            line0, start0, before = self._held_where
            at, i = offset - len(before), len(before)
            chunk = before + chunk
        else:
            line0, start0 = self._line, self._line_start
        before = chunk[:i]
        lf = before.count(b"\n")
        line = line0 + lf
        start = at + before.rfind(b"\n") + 1 if lf else start0
        column = offset - start + 1
        code = chunk[i]
        where = dict(offset=offset, line=line, column=column)
        if code < 0x80:
            return InvalidUpload(
                f"{self.name}: binary data (control character 0x{code:02X}) at offset "
                f"{offset} (line {line}, column {column})",
                **where,
            )
        for n in (2, 3, 4):
            with contextlib.suppress(UnicodeDecodeError):
                ch = chunk[i : i + n].decode("utf-8")
                return InvalidUpload(
                    f"{self.name}: character {ch!r} (U+{ord(ch):04X}, bytes "
                    f"{chunk[i : i + n].hex(' ').upper()}) at byte offset {offset}, line {line}, "
                    f"column {column} is outside the ISO 6983 / EIA character set (7-bit ISO "
                    "code: printable ASCII, TAB, LF, CR); a machine's tape cannot carry it",
                    character=f"U+{ord(ch):04X}",
                    **where,
                )
        hint = ""
        if all(bin(b).count("1") % 2 == 0 for b in self.head[:256]):
            hint = " (this looks like ISO 7-bit tape with the parity bit set; strip parity first)"
        return InvalidUpload(
            f"{self.name}: invalid UTF-8 at byte offset {offset}: byte 0x{code:02X} starts no "
            f"character (line {line}, column {column}){hint}",
            **where,
        )

    # ------------------------------------------------------------------ reading back
    @property
    def sha256(self) -> str:
        return self._sha.hexdigest()

    @property
    def lines(self) -> int:
        """Lines of the stored form (as dnc.tape.count_lines counts them)."""
        return self.newlines + (0 if self._last == b"\n" else 1)

    def text(self) -> str:
        """The stored form, read back once (ASCII by construction)."""
        self._file.seek(0)
        return self._file.read().decode("ascii")

    def chunks(self) -> Iterator[str]:
        """The stored form read back a file block at a time, in the chunks of whole lines
        the library stores (dnc.content): never the whole text in memory."""
        with open(self._file.name, "rb") as f:
            yield from line_chunks(iter(lambda: f.read(CHUNK).decode("ascii"), ""))

    @contextlib.contextmanager
    def line_file(self) -> Iterator[IO[str]]:
        """The stored form as a text file of lines with its path as `name` (the NC check
        reads it lazily and finds subprograms in it by position)."""
        with open(self._file.name, encoding="ascii", newline="\n") as f:
            yield f

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> ProgramUpload:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
