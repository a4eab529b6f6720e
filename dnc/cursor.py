"""Cursor pagination, for every list the host and the REST API page through.

A cursor is opaque to clients: the last id a page showed, behind a one-letter prefix naming
the list (`p` programs, `j` jobs, `d` dispatches), so pages stay stable under concurrent
inserts and a cursor of one list is refused by another.
"""

from __future__ import annotations

import base64

from dnc.errors import InvalidCursor

_MAX_ID = 2**31 - 1  # ids are 32-bit integers in the database


def encode_cursor(prefix: str, last_id: int) -> str:
    return base64.urlsafe_b64encode(f"{prefix}{last_id}".encode()).decode().rstrip("=")


def decode_cursor(prefix: str, cursor: str) -> int:
    """The id inside a cursor of the `prefix` list; InvalidCursor if it is not one."""
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode("ascii")
        if not raw.startswith(prefix) or not raw[len(prefix) :].isdigit():
            raise ValueError
        value = int(raw[len(prefix) :])
        if value > _MAX_ID:
            raise ValueError
        return value
    except (ValueError, UnicodeDecodeError):
        raise InvalidCursor(
            f"cursor {cursor[:80]!r} is not a cursor this list gave out; "
            "start again without a cursor"
        ) from None
