"""Program text stored in chunks of whole lines: written and read a chunk at a time.

A revision's text used to be one row (`contents.text`): storing a 15 MB program bound the
whole text to one statement, and SQLite's trigram index tokenised it as one document, all
in memory at once (some 6 bytes of host memory per byte of program). Here a text is cut
into chunks of at most `CHUNK_CHARS` characters that end at a line end, one row each in
`content_chunks` (migration 0011): an upload streamed from a file is stored without ever
being whole in memory, the search index takes one chunk at a time, and a reader can
stream it back (the REST text does; a dispatch, the NC check and posting read it whole,
once: `read_text`).

A chunk ends at a line end (LF) unless a single line is longer than a chunk; the text
search looks for a substring within a chunk, so it finds every match that lies within
one line of up to `CHUNK_CHARS` characters (a search text never holds a line end).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

from sqlalchemy import insert, select
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.db import transaction

CHUNK_CHARS = 1 << 18  # 256 KiB: a 16 MiB program is 64 rows

_CHUNKS = m.ContentChunk.__table__
_INSERT = insert(_CHUNKS)


def split_text(text: str, size: int = CHUNK_CHARS) -> Iterator[str]:
    """`text` in chunks of at most `size` characters, each ending at a line end where a
    line end is within reach (a longer line is cut at `size`)."""
    start, end = 0, len(text)
    while end - start > size:
        cut = text.rfind("\n", start, start + size)
        stop = cut + 1 if cut >= start else start + size
        yield text[start:stop]
        start = stop
    if start < end:
        yield text[start:]


def line_chunks(pieces: Iterable[str], size: int = CHUNK_CHARS) -> Iterator[str]:
    """Pieces of a text (any cut) re-cut as `split_text` cuts the whole text: a streamed
    text is stored in exactly the chunks the same text given whole is."""
    held = ""
    for piece in pieces:
        held += piece
        if len(held) > size:
            parts = list(split_text(held, size))
            held = parts.pop()  # the last part may go on in the next piece
            yield from parts
    if held:
        yield held


def store(s: Session, sha256: str, size: int, chunks: Iterable[str]) -> bool:
    """Store a text under its sha256 a chunk at a time (in the caller's transaction);
    False, reading nothing of `chunks`, when the library holds it already."""
    if s.get(m.Content, sha256) is not None:
        return False
    s.add(m.Content(sha256=sha256, size=size))
    s.flush()
    # Core inserts, one chunk each: the ORM would keep every chunk's text in the session
    for seq, chunk in enumerate(chunks):
        s.execute(_INSERT, dict(sha256=sha256, seq=seq, text=chunk))
    return True


def read_text(s: Session, sha256: str) -> str:
    """The whole text (one copy) for the readers that need it whole (the NC check of a
    dispatch, posting, a called program)."""
    rows = s.scalars(
        select(_CHUNKS.c.text).where(_CHUNKS.c.sha256 == sha256).order_by(_CHUNKS.c.seq)
    )
    return "".join(rows)


def iter_text(sessions: sessionmaker[Session], sha256: str) -> Iterator[str]:
    """The text chunk by chunk, each read in its own short transaction: a text never
    changes under its sha256, so the chunks read apart are the text stored."""
    with transaction(sessions) as s:
        ids = list(
            s.scalars(
                select(_CHUNKS.c.id).where(_CHUNKS.c.sha256 == sha256).order_by(_CHUNKS.c.seq)
            )
        )
    for chunk_id in ids:
        with transaction(sessions) as s:
            yield s.scalar(select(_CHUNKS.c.text).where(_CHUNKS.c.id == chunk_id))
