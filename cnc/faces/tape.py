"""ISO 6983 tape code on a byte stream: even parity, flow control and program framing.

Pure functions and an incremental decoder, shared by the machine's DNC port and the host's
transfer client so that both ends agree byte for byte.

The character set is ISO 7-bit. Without parity, a byte with bit 7 set cannot be tape code: the
decoder reports it (`eight_bit`, with its offset and line) and stops, so the program is
rejected instead of stored with a replacement character. With parity on, bit 7 of every byte is set so that the byte
holds an even number of ones (ISO 840 / EIA RS-358 tape, "7E" on a serial line); a byte with
odd parity is a parity error, which the seed (000_nc_book.md, DNC) says must reject the
program. Flow and punch control use the device control characters a Fanuc remote buffer
uses: DC1 resume (XON), DC3 stop (XOFF), DC2 start of punch output, DC4 end of punch output.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

NUL, LF, CR = 0x00, 0x0A, 0x0D
DC1 = XON = 0x11
DC2 = PUNCH_ON = 0x12
DC3 = XOFF = 0x13
DC4 = PUNCH_OFF = 0x14
PERCENT = 0x25
CONTROL = frozenset({DC1, DC2, DC3, DC4})

_ONES = bytes(bin(i).count("1") for i in range(256))
_ODD_MARK = bytes(_ONES[i] % 2 for i in range(256))  # 1 where a byte has odd parity
_STRIP = bytes(i & 0x7F for i in range(256))
# Bytes that need the byte-by-byte path inside a block: controls, NUL, CR and `%`.
_SPECIAL = bytes([0x11, 0x12, 0x13, 0x14, 0x00, 0x0D, 0x25])
_WITH_PARITY = bytes(((i | 0x80) if _ONES[i] % 2 else i) & 0xFF for i in range(128)) + bytes(128)


def add_parity(data: bytes) -> bytes:
    """Set bit 7 where needed so every byte has even parity. Input must be 7-bit."""
    if any(b > 0x7F for b in data):
        raise ValueError("tape text must be 7-bit ASCII before parity is added")
    return data.translate(_WITH_PARITY)


def parity_error_at(data: bytes) -> int | None:
    """Offset of the first byte with odd parity, or None."""
    i = data.translate(_ODD_MARK).find(1)
    return None if i < 0 else i


def strip_parity(data: bytes) -> bytes:
    return data.translate(_STRIP)


def encode_program(text: str, *, parity: bool = False, leader: int = 0) -> bytes:
    """A program as tape bytes: optional NUL leader, `%`, the blocks with LF ends, `%`.

    A text that already carries its `%` marks is sent as it is (they are not doubled).
    """
    if text.startswith("%\n") and text.endswith("\n%\n") and "\r" not in text:
        # Already in stored form (what the library and program memory keep): framing it
        # again would give the same bytes, so it is only encoded.
        raw = b"\0" * leader + text.encode("ascii")
        return add_parity(raw) if parity else raw
    body = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = [ln for ln in body.split("\n")]
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines or lines[0].strip() != "%":
        lines.insert(0, "%")
    if len(lines) == 1 or lines[-1].strip() != "%":
        lines.append("%")
    raw = b"\0" * leader + ("\n".join(lines) + "\n").encode("ascii")
    return add_parity(raw) if parity else raw


@dataclass(frozen=True, slots=True)
class TapeEvent:
    kind: str  # start | line | lines | end | control | parity_error | eight_bit | overlong
    text: str = ""
    offset: int = 0  # byte offset in the stream
    code: int = 0  # the control character (control), the offending byte (eight_bit)
    lines: Sequence[str] = ()  # for kind == "lines" (feed_runs only): consecutive blocks
    line: int = 0  # eight_bit: the line of the stream it is on (1 = the first)


# Decoder states
_LEADER, _PERCENT_LINE, _BODY, _DONE, _FAILED = range(5)


@dataclass
class TapeDecoder:
    """Incremental decoder: bytes in, tape events out.

    Leader (NULs, blank lines, anything) before the first `%` is skipped, as is the rest of
    the `%` line; CR is ignored; DC1-DC4 are reported as control events and never appear in
    text. A block that is just `%` ends the tape; everything after it (trailer) is ignored.
    With parity on, the first parity error ends decoding: the program must be rejected.
    """

    parity: bool = False
    max_block: int = 4096
    offset: int = 0
    line: int = 1  # line of the stream the next byte is on (LFs fed so far + 1)
    _state: int = _LEADER
    _block: bytearray = field(default_factory=bytearray)

    @property
    def started(self) -> bool:
        return self._state != _LEADER

    @property
    def ended(self) -> bool:
        return self._state == _DONE

    @property
    def failed(self) -> bool:
        return self._state == _FAILED

    def feed(self, data: bytes) -> list[TapeEvent]:
        """Events for `data`, one `line` event per block."""
        return self._feed(data, runs=False)

    def feed_runs(self, data: bytes) -> list[TapeEvent]:
        """Like feed(), but consecutive plain blocks come as one `lines` event.

        A 100 KB program is some 4000 blocks: one event and one str.split for a run of them,
        instead of an event object per block, is what lets a receiver keep up at line speed.
        """
        return self._feed(data, runs=True)

    def _feed(self, data: bytes, runs: bool) -> list[TapeEvent]:
        if not self.parity:
            if data.isascii() or self._state >= _DONE:
                self.line += data.count(b"\n")
                return self._feed_plain(data, runs)
            return self._feed_eight_bit(data, runs)
        bad = data.translate(_ODD_MARK).find(1)
        if bad < 0:
            return self._feed_plain(data.translate(_STRIP), runs)
        events = self._feed_plain(data[:bad].translate(_STRIP), runs)
        if self._state < _DONE:
            self._state = _FAILED
            events.append(TapeEvent("parity_error", offset=self.offset))
        self.offset += len(data) - bad
        return events

    def _feed_eight_bit(self, data: bytes, runs: bool) -> list[TapeEvent]:
        """Without parity every byte must be 7-bit: decode up to the first that is not,
        then fail there (after the closing `%` the trailer is ignored, as always)."""
        bad = next(i for i, b in enumerate(data) if b > 0x7F)
        head = data[:bad]
        events = self._feed_plain(head, runs)
        line = self.line + head.count(b"\n")
        self.line = line + data.count(b"\n", bad)
        if self._state < _DONE:
            self._state = _FAILED
            events.append(TapeEvent("eight_bit", offset=self.offset, code=data[bad], line=line))
        self.offset += len(data) - bad
        return events

    def _feed_plain(self, data: bytes, runs: bool = False) -> list[TapeEvent]:
        """Parity already checked and stripped. Whole blocks without special characters go
        through at C speed, a run of them at once; anything else takes the byte-by-byte
        path."""
        events: list[TapeEvent] = []
        i, n = 0, len(data)
        while i < n:
            if self._state >= _DONE:
                self.offset += n - i
                break
            if self._state == _BODY:
                i = self._run_of_blocks(data, i, events, runs)
                if i >= n:
                    break
            j = data.find(b"\n", i)
            stop = j + 1 if j >= 0 else n
            if self._state == _BODY:
                seg = data[i : j if j >= 0 else n]
                if (
                    len(seg.translate(None, _SPECIAL)) == len(seg)
                    and len(self._block) + len(seg) <= self.max_block
                ):
                    self._block += seg
                    self.offset += len(seg)
                    if j >= 0:
                        events.append(
                            TapeEvent("line", self._block.decode("ascii", "replace"), self.offset)
                        )
                        self._block.clear()
                        self.offset += 1
                    i = stop
                    continue
            events += self._feed_bytes(data[i:stop])
            i = stop
        return events

    def _run_of_blocks(self, data: bytes, i: int, events: list[TapeEvent], runs: bool) -> int:
        """Decode the complete blocks from `i` up to the next special character in one go;
        returns where decoding goes on. Does nothing if a block is too long (the slow path
        reports exactly where)."""
        last_lf = data.rfind(b"\n", i)
        if last_lf < 0:
            return i
        # The first special character before it, by one memchr per kind (a character class
        # regex walked a 4 KB read at a tenth of the speed).
        for code in _SPECIAL:
            at = data.find(code, i, last_lf)
            if at >= 0:
                last_lf = data.rfind(b"\n", i, at)
                if last_lf < 0:
                    return i
        parts = data[i:last_lf].decode("ascii", "replace").split("\n")
        # One character per byte after decoding (a bad byte becomes one U+FFFD), so
        # character counts are the byte counts the block limit is about.
        carried = len(self._block)
        if carried + len(parts[0]) > self.max_block or max(map(len, parts)) > self.max_block:
            return i
        if carried:
            parts[0] = self._block.decode("ascii", "replace") + parts[0]
            self._block.clear()
        if runs:
            self.offset += last_lf + 1 - i
            events.append(TapeEvent("lines", offset=self.offset - 1, lines=parts))
        else:
            pos = self.offset - carried - 1
            for text in parts:
                pos += len(text) + 1  # the block's LF
                events.append(TapeEvent("line", text, pos))
            self.offset += last_lf + 1 - i
        return last_lf + 1

    def _feed_bytes(self, data: bytes) -> list[TapeEvent]:
        events: list[TapeEvent] = []
        for b in data:
            pos = self.offset
            self.offset += 1
            state = self._state
            if state >= _DONE:
                continue
            if b in CONTROL:
                events.append(TapeEvent("control", offset=pos, code=b))
            elif b in (NUL, CR):
                pass
            elif state == _LEADER:
                if b == PERCENT:
                    self._state = _PERCENT_LINE
                    events.append(TapeEvent("start", offset=pos))
            elif state == _PERCENT_LINE:
                if b == LF:
                    self._state = _BODY
            elif b == LF:
                block = self._block.decode("ascii", "replace")
                self._block.clear()
                events.append(TapeEvent("line", block, offset=pos))
            elif b == PERCENT and not self._block.strip():
                self._state = _DONE
                events.append(TapeEvent("end", offset=pos))
            elif len(self._block) >= self.max_block:
                self._state = _FAILED
                events.append(TapeEvent("overlong", offset=pos))
            else:
                self._block.append(b)
        return events
