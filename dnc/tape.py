"""Part program text as it arrives: decoding uploads and reading the ISO tape header.

Stored text is UTF-8 with `\\n` line ends; the sha256 that identifies content is taken over
exactly that form, so a program punched back from a machine with CR LF line ends compares
equal to the revision that was sent.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

from cnc.program_memory import MAX_PROGRAM_NUMBER
from dnc.errors import InvalidUpload

__all__ = ["MAX_PROGRAM_NUMBER"]  # the O number range 1..99999999, for the REST schemas

# Control characters a tape may legitimately carry: TAB, LF, CR, and DC1-DC4 (XON/XOFF and
# tape reader control) which we strip. Anything else below 0x20 means binary data.
_ALLOWED_CONTROL = {0x09, 0x0A, 0x0D}
_STRIPPED_CONTROL = {0x11, 0x12, 0x13, 0x14}


def decode_program(data: bytes, *, limit: int, name: str = "upload") -> str:
    """Validate and decode an uploaded program; refuse with the exact byte offset and reason."""
    check_size(len(data), limit=limit, name=name)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        hint = ""
        if all(_even_parity(b) for b in data[:256]):  # ISO 7-bit even parity on every byte
            hint = " (this looks like ISO 7-bit tape with the parity bit set; strip parity first)"
        raise InvalidUpload(
            f"{name}: invalid UTF-8 at byte offset {exc.start}: {exc.reason}{hint}",
            offset=exc.start,
        ) from None
    return normalise_text(text, name=name)


def check_size(size: int, *, limit: int, name: str = "upload") -> None:
    if size > limit:
        raise InvalidUpload(
            f"{name}: {size} bytes exceeds the upload limit of {limit} bytes "
            "(configure dnc.max_upload_bytes, or drip-feed the program)",
            size=size,
            limit=limit,
        )


def normalise_text(text: str, *, name: str = "upload") -> str:
    out = []
    for offset, ch in enumerate(text):
        code = ord(ch)
        if code < 0x20 or code == 0x7F:
            if code in _STRIPPED_CONTROL:
                continue
            if code not in _ALLOWED_CONTROL:
                raise InvalidUpload(
                    f"{name}: binary data (control character 0x{code:02X}) at offset {offset}",
                    offset=offset,
                )
        out.append(ch)
    text = "".join(out).replace("\r\n", "\n").replace("\r", "\n")
    if not text.strip() or not text.strip("%\n \t"):
        raise InvalidUpload(f"{name}: the program is empty")
    return text


def _even_parity(byte: int) -> bool:
    return bin(byte).count("1") % 2 == 0


def sha256_of(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def count_lines(text: str) -> int:
    return text.count("\n") + (0 if text.endswith("\n") else 1)


@dataclass(frozen=True, slots=True)
class TapeHeader:
    number: int | None  # O number (or ':' number) of the first program block
    title: str  # the comment on that block, if any


_O_BLOCK = re.compile(r"^\s*(?:N\d+\s*)?[O:]\s*(\d+)\s*(?:\((?P<title>[^)]*)\))?", re.I)


def read_header(text: str) -> TapeHeader:
    """The program number and title an ISO tape declares in its first O block."""
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line == "%" or line.startswith(("(", ";")):
            continue
        m = _O_BLOCK.match(line)
        if m:
            return TapeHeader(int(m.group(1)), (m.group("title") or "").strip())
        break
    return TapeHeader(None, "")
