"""The DNC host's tables (SQLAlchemy 2). Alembic migrations in dnc/migrations own the schema.

Content is stored once per sha256 (`contents`, its text in chunks of whole lines in
`content_chunks`), and revisions point at it: a library of many revisions of the same
program costs one copy of each distinct text.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class UtcDateTime(TypeDecorator):
    """Timestamps are stored and returned as aware UTC datetimes on every backend.

    SQLite has no time zone type and hands back naive values; without this, comparing a
    due date read from SQLite with `now` would fail on one backend and pass on the other.
    """

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect) -> datetime | None:
        if value is not None:
            if value.tzinfo is None:
                raise ValueError("naive datetime given to a UTC timestamp column")
            value = value.astimezone(UTC)
        return value

    def process_result_value(self, value: datetime | None, dialect) -> datetime | None:
        if value is not None and value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value


Timestamp = UtcDateTime()


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)


class Machine(Base):
    __tablename__ = "machines"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    kind: Mapped[str] = mapped_column(String(32))
    dnc_address: Mapped[str] = mapped_column(String(255), default="")
    modbus_address: Mapped[str] = mapped_column(String(255), default="")
    status_address: Mapped[str] = mapped_column(String(255), default="")
    memory_bytes: Mapped[int] = mapped_column(Integer, default=0)
    # Per-port protocol profile, CIMCO style: parity, chunk size, time-outs.
    dnc_profile: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # its configured axes (X Y Z A), what a job's program needs is matched to
    # (dnc/requirements.py); None = not known (judged by its kind alone)
    axes: Mapped[list[str] | None] = mapped_column(JSON, nullable=True)
    created_at: Mapped[datetime] = mapped_column(Timestamp)


class Program(Base):
    __tablename__ = "programs"
    __table_args__ = (UniqueConstraint("number", "machine_kind", name="uq_programs_number_kind"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    number: Mapped[int] = mapped_column(Integer, index=True)
    name: Mapped[str] = mapped_column(String(255), index=True)
    machine_kind: Mapped[str] = mapped_column(String(32))
    description: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(Timestamp)


class ProgramTag(Base):
    __tablename__ = "program_tags"
    program_id: Mapped[int] = mapped_column(
        ForeignKey("programs.id", ondelete="CASCADE"), primary_key=True
    )
    tag: Mapped[str] = mapped_column(String(64), primary_key=True, index=True)


class Content(Base):
    """A distinct program text, by its sha256; the text itself is in `content_chunks`."""

    __tablename__ = "contents"
    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    size: Mapped[int] = mapped_column(Integer)


class ContentChunk(Base):
    """One chunk of a content's text, whole lines (dnc/content.py)."""

    __tablename__ = "content_chunks"
    __table_args__ = (UniqueConstraint("sha256", "seq", name="uq_content_chunks_sha256_seq"),)
    # the search index on SQLite keys a chunk of a program's revisions by this id
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    sha256: Mapped[str] = mapped_column(ForeignKey("contents.sha256", ondelete="CASCADE"))
    seq: Mapped[int] = mapped_column(Integer)
    text: Mapped[str] = mapped_column(Text)


class Revision(Base):
    __tablename__ = "revisions"
    __table_args__ = (
        UniqueConstraint("program_id", "seq", name="uq_revisions_program_seq"),
        Index("ix_revisions_program_status", "program_id", "status"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    program_id: Mapped[int] = mapped_column(ForeignKey("programs.id"))
    seq: Mapped[int] = mapped_column(Integer)
    sha256: Mapped[str] = mapped_column(ForeignKey("contents.sha256"), index=True)
    size: Mapped[int] = mapped_column(Integer)
    lines: Mapped[int] = mapped_column(Integer)
    author: Mapped[str] = mapped_column(String(128))
    comment: Mapped[str] = mapped_column(Text, default="")
    source: Mapped[str] = mapped_column(String(128), default="upload")
    status: Mapped[str] = mapped_column(String(16), default="draft")
    created_at: Mapped[datetime] = mapped_column(Timestamp)
    status_changed_at: Mapped[datetime | None] = mapped_column(Timestamp, nullable=True)
    approved_by: Mapped[str | None] = mapped_column(String(128), nullable=True)
    approval_comment: Mapped[str | None] = mapped_column(Text, nullable=True)
    check_ok: Mapped[bool] = mapped_column(Boolean, default=False)
    check_errors: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list)
    # gcode: the NC program itself; apt | cl: a source posted for each machine at dispatch
    kind: Mapped[str] = mapped_column(String(8), default="gcode")
    # apt | cl: the machine kinds the source is meant for (dnc/posting.py)
    post_kinds: Mapped[list[str]] = mapped_column(JSON, default=list)
    # gcode: the axes a machine needs to run it (its kind's linear axes and the rotary
    # axes its blocks move), from the upload check; None = not known, or an APT/CL source
    axes: Mapped[list[str] | None] = mapped_column(JSON, nullable=True)


class DerivedRevision(Base):
    """The G-code an APT or CL revision was posted to for one machine kind.

    One row per distinct posted text (sha256) of a source and kind: dispatching the same
    source to another machine of the same kind finds the row with the same hash again.
    """

    __tablename__ = "derived_revisions"
    __table_args__ = (
        UniqueConstraint(
            "source_revision_id", "machine_kind", "sha256", name="uq_derived_revisions_post"
        ),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    source_revision_id: Mapped[int] = mapped_column(ForeignKey("revisions.id"), index=True)
    machine_kind: Mapped[str] = mapped_column(String(32))
    post_name: Mapped[str] = mapped_column(String(64))
    post_version: Mapped[str] = mapped_column(String(32))
    tolerance_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    sha256: Mapped[str] = mapped_column(ForeignKey("contents.sha256"))
    size: Mapped[int] = mapped_column(Integer)
    lines: Mapped[int] = mapped_column(Integer)
    machine: Mapped[str] = mapped_column(String(64))  # the machine it was first posted for
    created_at: Mapped[datetime] = mapped_column(Timestamp)


class Resource(Base):
    """Tool, fixture or material data a program needs (set-up sheet)."""

    __tablename__ = "resources"
    __table_args__ = (UniqueConstraint("kind", "code", name="uq_resources_kind_code"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))  # tool | fixture | material
    code: Mapped[str] = mapped_column(String(64))
    description: Mapped[str] = mapped_column(Text, default="")
    data: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)


class ProgramResource(Base):
    __tablename__ = "program_resources"
    program_id: Mapped[int] = mapped_column(
        ForeignKey("programs.id", ondelete="CASCADE"), primary_key=True
    )
    resource_id: Mapped[int] = mapped_column(
        ForeignKey("resources.id", ondelete="CASCADE"), primary_key=True
    )


class AuditEntry(Base):
    """Append-only: the migration installs triggers that refuse UPDATE and DELETE."""

    __tablename__ = "audit_log"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[datetime] = mapped_column(Timestamp, index=True)
    actor: Mapped[str] = mapped_column(String(128))
    action: Mapped[str] = mapped_column(String(64))
    entity: Mapped[str] = mapped_column(String(32))
    entity_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    detail: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)


class OutboxEvent(Base):
    """Events written in the same transaction as the change they describe (outbox pattern)."""

    __tablename__ = "outbox"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[datetime] = mapped_column(Timestamp)
    topic: Mapped[str] = mapped_column(String(128))
    payload: Mapped[dict[str, Any]] = mapped_column(JSON)
    published_at: Mapped[datetime | None] = mapped_column(Timestamp, nullable=True, index=True)


class Job(Base):
    """A production order: make `quantity` parts from a released revision."""

    __tablename__ = "jobs"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    revision_id: Mapped[int] = mapped_column(ForeignKey("revisions.id"))
    quantity: Mapped[int] = mapped_column(Integer)
    done: Mapped[int] = mapped_column(Integer, default=0)
    priority: Mapped[int] = mapped_column(Integer, default=0)
    due_at: Mapped[datetime | None] = mapped_column(Timestamp, nullable=True)
    machine_kind: Mapped[str] = mapped_column(String(32))
    machine_group: Mapped[str | None] = mapped_column(String(64), nullable=True)
    cycle_time_s: Mapped[float] = mapped_column(Float, default=60.0)
    status: Mapped[str] = mapped_column(String(16), default="queued", index=True)
    # the kinds and axes a machine needs to make its parts ({"kinds": [...], "axes": [...]},
    # dnc/requirements.py), fixed when queued; None = its machine kind alone
    needs: Mapped[dict[str, list[str]] | None] = mapped_column(JSON, nullable=True)
    created_at: Mapped[datetime] = mapped_column(Timestamp)
    updated_at: Mapped[datetime] = mapped_column(Timestamp)


class Allocation(Base):
    """One part of a job on one machine (one program run)."""

    __tablename__ = "allocations"
    # a machine's last allocation (setup-aware dispatch rules) is one index seek
    __table_args__ = (Index("ix_allocations_machine_id", "machine", "id"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    machine: Mapped[str] = mapped_column(String(64), index=True)
    parts_at_start: Mapped[int] = mapped_column(Integer)
    # dispatched | running | completed | interrupted | rerouted | failed (dnc/allocation.py)
    status: Mapped[str] = mapped_column(String(16), index=True)
    dispatch_id: Mapped[int | None] = mapped_column(ForeignKey("dispatches.id"), nullable=True)
    reason: Mapped[str] = mapped_column(Text, default="")
    # the last alarm or warning noted while the machine cut on (not interrupting)
    note: Mapped[str] = mapped_column(Text, default="")
    # the allocation that makes this one's part again (status rerouted)
    rerouted_to: Mapped[int | None] = mapped_column(Integer, nullable=True)
    created_at: Mapped[datetime] = mapped_column(Timestamp)
    ended_at: Mapped[datetime | None] = mapped_column(Timestamp, nullable=True)


class Decision(Base):
    """Why the scheduler did what it did: one row per action it took."""

    __tablename__ = "decisions"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[datetime] = mapped_column(Timestamp, index=True)
    rule: Mapped[str] = mapped_column(String(64))  # same_program_first then edd
    action: Mapped[str] = mapped_column(String(32))
    job_id: Mapped[int | None] = mapped_column(Integer, nullable=True, index=True)
    machine: Mapped[str | None] = mapped_column(String(64), nullable=True)
    reason: Mapped[str] = mapped_column(Text)


class Dispatch(Base):
    """A request to put a released revision on a machine; executed by the transfer worker."""

    __tablename__ = "dispatches"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    idempotency_key: Mapped[str] = mapped_column(String(128), unique=True)
    request_hash: Mapped[str] = mapped_column(String(64))
    revision_id: Mapped[int] = mapped_column(ForeignKey("revisions.id"))
    machine: Mapped[str] = mapped_column(String(64), index=True)
    mode: Mapped[str] = mapped_column(String(16))  # memory | drip_feed
    start: Mapped[bool] = mapped_column(Boolean, default=False)
    state: Mapped[str] = mapped_column(String(16), index=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    next_attempt_at: Mapped[datetime | None] = mapped_column(Timestamp, nullable=True)
    bytes_sent: Mapped[int] = mapped_column(Integer, default=0)
    verified: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    requested_by: Mapped[str] = mapped_column(String(128))
    created_at: Mapped[datetime] = mapped_column(Timestamp)
    updated_at: Mapped[datetime] = mapped_column(Timestamp)
    # an APT/CL revision: the G-code posted for this machine, which is what is sent
    derived_id: Mapped[int | None] = mapped_column(Integer, nullable=True)


class RevisionCall(Base):
    """A call of another program (M98 P, G65 P, G66 P) in a revision, by O number
    (cnc.gcode.calls; resolved to a released revision when the revision is dispatched)."""

    __tablename__ = "revision_calls"
    revision_id: Mapped[int] = mapped_column(
        ForeignKey("revisions.id", ondelete="CASCADE"), primary_key=True
    )
    line: Mapped[int] = mapped_column(Integer, primary_key=True)
    col: Mapped[int] = mapped_column(Integer, primary_key=True)
    code: Mapped[str] = mapped_column(String(3))  # M98 | G65 | G66
    number: Mapped[int] = mapped_column(Integer, index=True)
    packed: Mapped[bool] = mapped_column(Boolean, default=False)  # M98 Pxxxxnnnn without L
    # the O number a packed call means when the 8-digit one does not exist (nnnn), else NULL
    short_number: Mapped[int | None] = mapped_column(Integer, nullable=True, index=True)
