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
from dnc.errors import InvalidUpload, UploadTooLarge

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
        raise UploadTooLarge(
            f"{name}: {size} bytes exceeds the upload limit of {limit} bytes "
            "(configure dnc.max_upload_bytes, or drip-feed the program)",
            size=size,
            limit=limit,
        )


#: the first character outside what a stored program may hold: ISO 6983 / EIA tape carries
#: the 7-bit ISO 646 code (printable 0x20..0x7E) and, as block ends and spacing, LF, CR, TAB;
#: DC1-DC4 are stripped (tape reader control). Anything else is refused with where it is.
_OUTSIDE = re.compile(r"[^\t\n\r\x11-\x14\x20-\x7e]")
_STRIP_CONTROL = dict.fromkeys(_STRIPPED_CONTROL)


def normalise_text(text: str, *, name: str = "upload") -> str:
    """The stored form of a program text, or InvalidUpload naming the first character
    outside the ISO 6983 / EIA character set: its byte offset (in the UTF-8 text), line and
    column (1-based), and what it is. A non-ASCII character would be stored, pass the NC
    check and then fail the 7-bit tape at dispatch."""
    bad = _OUTSIDE.search(text)
    if bad is not None:
        raise _outside(text, bad.start(), name)
    text = text.translate(_STRIP_CONTROL).replace("\r\n", "\n").replace("\r", "\n")
    if not text.strip() or not text.strip("%\n \t"):
        raise InvalidUpload(f"{name}: the program is empty")
    return text


def _outside(text: str, at: int, name: str) -> InvalidUpload:
    ch = text[at]
    code = ord(ch)
    before = text[:at]
    line = before.count("\n") + 1
    column = at - (before.rfind("\n") + 1) + 1
    offset = len(before.encode("utf-8", "surrogatepass"))
    where = dict(offset=offset, line=line, column=column)
    if code < 0x20 or code == 0x7F:
        return InvalidUpload(
            f"{name}: binary data (control character 0x{code:02X}) at offset {offset} "
            f"(line {line}, column {column})",
            **where,
        )
    utf8 = ch.encode("utf-8", "surrogatepass").hex(" ").upper()
    return InvalidUpload(
        f"{name}: character {ch!r} (U+{code:04X}, bytes {utf8}) at byte offset {offset}, "
        f"line {line}, column {column} is outside the ISO 6983 / EIA character set "
        "(7-bit ISO code: printable ASCII, TAB, LF, CR); a machine's tape cannot carry it",
        character=f"U+{code:04X}",
        **where,
    )


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
