"""The chain's entry points: APT source or CL data -> CL records -> a machine's program."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

from cam.apt import process
from cam.cl import ClRecord, read_cl
from cam.errors import WarningSink, ignore_warning

APT_SUFFIXES = {".apt"}
CL_SUFFIXES = {".cl", ".cls", ".aptsource", ".cldata", ".clf"}
_APT_HINT = re.compile(
    r"^\s*(?:[A-Z][A-Z0-9]{0,5}\s*\)\s*)?(?:[A-Z][A-Z0-9]*\s*=|(?:TL(?:LFT|RGT|ON)\s*,\s*)?GO(?:LFT|RGT|FWD|BACK|UP|DOWN)?\s*/|GODLTA|ZSURF|TL(?:LFT|RGT|ON)\b|INDIR[VP])",
    re.IGNORECASE | re.MULTILINE,
)


def detect_format(path: str | Path, head: str) -> str:
    """`apt` or `cl`: by the file's suffix, else by its first statements (definitions and
    contouring statements exist only in APT source)."""
    suffix = Path(path).suffix.lower()
    if suffix in APT_SUFFIXES:
        return "apt"
    if suffix in CL_SUFFIXES:
        return "cl"
    return "apt" if _APT_HINT.search(head) else "cl"


def records_from_text(
    text: str, fmt: str, file: str = "<input>", warn: WarningSink = ignore_warning
) -> Iterator[ClRecord]:
    if fmt == "apt":
        return process(text, file, warn)
    return read_cl(text, file, warn)


def records_from_file(
    path: str | Path, fmt: str | None = None, warn: WarningSink = ignore_warning
) -> tuple[str, Iterator[ClRecord]]:
    """(format, records) of a file; CL data is streamed line by line."""
    path = Path(path)
    with open(path, encoding="utf-8", errors="strict") as fh:
        head = fh.read(65536)
    fmt = fmt or detect_format(path, head)
    if fmt == "apt":
        return fmt, process(path.read_text(encoding="utf-8"), str(path), warn)
    return fmt, _stream(path, warn)


def _stream(path: Path, warn: WarningSink) -> Iterator[ClRecord]:
    with open(path, encoding="utf-8") as fh:
        yield from read_cl(fh, str(path), warn)
