"""The program library: programs, revisions and their release workflow, search, import.

A service that knows nothing of HTTP. Every change is one transaction that also writes its
audit entry and its outbox event, so a change is never visible without its history, and the
event stream never announces a change that was rolled back.

Release workflow: draft -> released -> obsolete. Only a draft whose NC check passed can be
released, and releasing needs an approval comment. Releasing a revision obsoletes the
program's previously released one (a program has at most one released revision), so a
dispatch by program number is never ambiguous.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import Integer, and_, column, exists, func, literal_column, or_, select, table
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from cam.chain import APT_SUFFIXES, CL_SUFFIXES
from cnc.gcode.calls import Call, program_calls
from dnc import models as m
from dnc.content import iter_text, read_text, split_text, store
from dnc.cursor import decode_cursor, encode_cursor
from dnc.db import transaction
from dnc.dependencies import LibraryPrograms, called_by, calls_of, dependencies, record_calls
from dnc.diff import unified_diff
from dnc.errors import Conflict, InvalidUpload, NotFound, WorkflowError
from dnc.events import record
from dnc.posting import (
    GCODE,
    MachineConfigs,
    Posted,
    check_source,
    default_machine_configs,
    derived_info,
    kind_of_upload,
    partno_header,
    posted_for,
    store_derived,
)
from dnc.tape import (
    MAX_PROGRAM_NUMBER,
    check_size,
    count_lines,
    decode_program,
    normalise_text,
    read_header,
    sha256_of,
)
from dnc.upload import ProgramUpload

DRAFT, RELEASED, OBSOLETE = "draft", "released", "obsolete"
IMPORT_SUFFIXES = {".nc", ".ngc", ".tap", ".txt", ".iso", ".cnc"}
_IMPORTED = IMPORT_SUFFIXES | APT_SUFFIXES | CL_SUFFIXES  # APT and CL: sources (dnc/posting.py)
DEFAULT_UPLOAD_LIMIT = 16 * 1024 * 1024

Checker = Callable[[str, str], list[dict[str, Any]]]
"""(text, machine_kind) -> list of {"line", "col", "message"}; empty when the program is valid.
A checker with `resolves_calls` also takes `programs=` (the library's programs by O number)."""


@dataclass(frozen=True, slots=True)
class Checked:
    errors: list[dict[str, Any]]
    calls: list[Call]  # the calls of other programs, stored with the revision
    # the axes a machine needs to run it (dnc.checker.Findings), None when not known
    axes: tuple[str, ...] | None = None


@dataclass(frozen=True, slots=True)
class ProgramInfo:
    id: int
    number: int
    name: str
    machine_kind: str
    description: str
    tags: tuple[str, ...]
    created_at: datetime
    released_revision_id: int | None
    latest_revision_id: int | None


@dataclass(frozen=True, slots=True)
class RevisionInfo:
    id: int
    program_id: int
    seq: int
    sha256: str
    size: int
    lines: int
    author: str
    comment: str
    source: str
    status: str
    created_at: datetime
    status_changed_at: datetime | None
    approved_by: str | None
    approval_comment: str | None
    check_ok: bool
    check_errors: list[dict[str, Any]] = field(default_factory=list)
    kind: str = "gcode"  # gcode | apt | cl (dnc/posting.py)
    post_kinds: list[str] = field(default_factory=list)  # apt | cl: the kinds it is meant for
    # gcode: the axes a machine needs to run it, from the upload check (dnc/requirements.py)
    axes: list[str] | None = None


@dataclass(frozen=True, slots=True)
class Page:
    items: list
    next_cursor: str | None


def _utcnow() -> datetime:
    return datetime.now(UTC)


class Library:
    def __init__(
        self,
        sessions: sessionmaker[Session],
        *,
        checker: Checker | None = None,
        upload_limit: int = DEFAULT_UPLOAD_LIMIT,
        now: Callable[[], datetime] = _utcnow,
        machine_configs: MachineConfigs = default_machine_configs,
    ) -> None:
        self._sessions = sessions
        self._checker = checker
        self.machine_configs = machine_configs  # for posting APT/CL revisions (dnc/posting.py)
        self.upload_limit = upload_limit
        self._now = now
        # Which side drives a text search on SQLite (see _text_drives_from_index): "auto",
        # or "index" / "programs" to pin it (the tests check both give the same pages).
        self.text_search_from = "auto"

    # ----------------------------------------------------------------- programs and revisions

    def create_program(
        self,
        *,
        number: int,
        name: str,
        text: str | bytes | ProgramUpload,
        machine_kind: str = "mill",
        description: str = "",
        tags: Iterable[str] = (),
        author: str = "unknown",
        comment: str = "",
        source: str = "upload",
        kind: str = GCODE,
        post_kinds: Iterable[str] | None = None,
    ) -> tuple[ProgramInfo, RevisionInfo]:
        """A new program with its first revision (a draft). `kind`: gcode, or apt / cl for
        a source posted at dispatch for the machine kinds in `post_kinds` (dnc/posting.py)."""
        if not 1 <= number <= MAX_PROGRAM_NUMBER:
            raise InvalidUpload(
                f"program number must be 1..{MAX_PROGRAM_NUMBER} (O number), got {number}"
            )
        if not name.strip():
            raise InvalidUpload("program name must not be empty")
        text = self._decode(text, name)
        kinds, check = self._check_kind(text, kind, machine_kind, post_kinds, name)
        with transaction(self._sessions) as s:
            taken = s.scalar(
                select(m.Program.id).where(
                    m.Program.number == number, m.Program.machine_kind == machine_kind
                )
            )
            if taken is not None:
                raise Conflict(
                    f"program O{number:04d} already exists for {machine_kind} machines "
                    f"(id {taken}); add a revision to it instead",
                    program_id=taken,
                )
            prog = m.Program(
                number=number,
                name=name.strip(),
                machine_kind=machine_kind,
                description=description,
                created_at=self._now(),
            )
            s.add(prog)
            try:
                s.flush()
            except IntegrityError as exc:  # a concurrent writer took the number first
                raise Conflict(f"program O{number:04d} already exists") from exc
            for tag in sorted({t.strip() for t in tags if t.strip()}):
                s.add(m.ProgramTag(program_id=prog.id, tag=tag))
            rev = self._add_revision(s, prog, text, check, author, comment, source, kind, kinds)
            self._record(s, author, "program.create", "program", prog.id, number=number, name=name)
            return self._program_info(s, prog), _revision_info(rev)

    def add_revision(
        self,
        program_id: int,
        text: str | bytes | ProgramUpload,
        *,
        author: str = "unknown",
        comment: str = "",
        source: str = "upload",
        kind: str = GCODE,
        post_kinds: Iterable[str] | None = None,
    ) -> RevisionInfo:
        with transaction(self._sessions) as s:
            prog = self._get_program(s, program_id)
            machine_kind, name = prog.machine_kind, prog.name
        text = self._decode(text, name)
        kinds, check = self._check_kind(text, kind, machine_kind, post_kinds, name)
        with transaction(self._sessions) as s:
            prog = self._get_program(s, program_id)
            rev = self._add_revision(s, prog, text, check, author, comment, source, kind, kinds)
            return _revision_info(rev)

    def receive_from_machine(self, machine: str, text: str | bytes) -> RevisionInfo:
        """A program punched from a machine lands as a candidate (draft) revision.

        It never overwrites anything: if no program with its O number exists for the
        machine's kind, a new program is created to hold it. A program identical to the
        latest revision creates nothing and returns that revision.
        """
        with transaction(self._sessions) as s:
            mach = s.scalar(select(m.Machine).where(m.Machine.name == machine))
            if mach is None:
                raise NotFound(f"unknown machine {machine!r}")
            kind = mach.kind
        text = self._decode(text, f"upload from {machine}")
        header = read_header(text)
        if header.number is None:
            raise InvalidUpload(f"program from {machine} has no O number in its first block")
        source = f"machine:{machine}"
        with transaction(self._sessions) as s:
            prog_id = s.scalar(
                select(m.Program.id).where(
                    m.Program.number == header.number, m.Program.machine_kind == kind
                )
            )
        if prog_id is None:
            _, rev = self.create_program(
                number=header.number,
                name=header.title or f"O{header.number:04d} from {machine}",
                text=text,
                machine_kind=kind,
                author=source,
                comment=f"received from {machine}",
                source=source,
            )
            return rev
        with transaction(self._sessions) as s:
            latest = s.scalar(
                select(m.Revision)
                .where(m.Revision.program_id == prog_id)
                .order_by(m.Revision.seq.desc())
                .limit(1)
            )
            if latest is not None and latest.sha256 == sha256_of(text):
                # Compare on receive: the machine holds exactly the latest revision.
                self._record(s, source, "revision.received_unchanged", "revision", latest.id)
                return _revision_info(latest)
        return self.add_revision(
            prog_id, text, author=source, comment=f"received from {machine}", source=source
        )

    def release(self, revision_id: int, *, approver: str, comment: str) -> RevisionInfo:
        if not comment.strip():
            raise WorkflowError("releasing a revision needs an approval comment")
        with transaction(self._sessions) as s:
            rev = self._get_revision(s, revision_id, lock=True)
            if rev.status != DRAFT:
                raise WorkflowError(
                    f"revision {revision_id} is {rev.status}; only a draft can be released"
                )
            if not rev.check_ok:
                first = rev.check_errors[0] if rev.check_errors else {}
                raise WorkflowError(
                    f"revision {revision_id} failed the NC check ({len(rev.check_errors)} "
                    f"error(s), first: line {first.get('line')}: {first.get('message')}); "
                    "it cannot be released",
                    errors=rev.check_errors,
                )
            now = self._now()
            previous = s.scalars(
                select(m.Revision).where(
                    m.Revision.program_id == rev.program_id, m.Revision.status == RELEASED
                )
            ).all()
            for old in previous:
                old.status, old.status_changed_at = OBSOLETE, now
                old.approved_by, old.approval_comment = approver, f"superseded by rev {rev.seq}"
                self._record(s, approver, "revision.obsolete", "revision", old.id, seq=old.seq)
            rev.status, rev.status_changed_at = RELEASED, now
            rev.approved_by, rev.approval_comment = approver, comment.strip()
            self._record(s, approver, "revision.release", "revision", rev.id, comment=comment)
            return _revision_info(rev)

    def obsolete(self, revision_id: int, *, approver: str, comment: str) -> RevisionInfo:
        if not comment.strip():
            raise WorkflowError("making a revision obsolete needs an approval comment")
        with transaction(self._sessions) as s:
            rev = self._get_revision(s, revision_id, lock=True)
            if rev.status == OBSOLETE:
                raise WorkflowError(f"revision {revision_id} is already obsolete")
            rev.status, rev.status_changed_at = OBSOLETE, self._now()
            rev.approved_by, rev.approval_comment = approver, comment.strip()
            self._record(s, approver, "revision.obsolete", "revision", rev.id, comment=comment)
            return _revision_info(rev)

    # ------------------------------------------------------------------------------- reading

    def get_program(self, program_id: int) -> ProgramInfo:
        with transaction(self._sessions) as s:
            return self._program_info(s, self._get_program(s, program_id))

    def get_revision(self, revision_id: int) -> RevisionInfo:
        with transaction(self._sessions) as s:
            return _revision_info(self._get_revision(s, revision_id))

    def revisions(self, program_id: int) -> list[RevisionInfo]:
        with transaction(self._sessions) as s:
            self._get_program(s, program_id)
            rows = s.scalars(
                select(m.Revision)
                .where(m.Revision.program_id == program_id)
                .order_by(m.Revision.seq)
            )
            return [_revision_info(r) for r in rows]

    def revision_text(self, revision_id: int) -> str:
        with transaction(self._sessions) as s:
            return read_text(s, self._get_revision(s, revision_id).sha256)

    def revision_chunks(self, revision_id: int) -> tuple[RevisionInfo, Iterator[str]]:
        """The revision and its text chunk by chunk (whole lines, dnc.content): a reader
        that streams it holds one chunk at a time, whatever the program's size."""
        info = self.get_revision(revision_id)
        return info, iter_text(self._sessions, info.sha256)

    def calls(self, revision_id: int) -> list[dict]:
        """The other programs the revision calls (M98 P, G65 P, G66 P), one entry per call:
        code, number, line, col, and the program and released revision it reaches today
        (program_id None: the library has no such program)."""
        with transaction(self._sessions) as s:
            rev = self._get_revision(s, revision_id)
            kind = s.get(m.Program, rev.program_id).machine_kind
            return calls_of(s, revision_id, kind)

    def called_by(self, program_id: int) -> list[dict]:
        """The programs whose current revision (released, else newest) calls this one."""
        with transaction(self._sessions) as s:
            return called_by(s, self._get_program(s, program_id))

    def dependencies(self, revision_id: int) -> list:
        """The released revisions a dispatch of the revision brings along, deepest first
        (dnc.dependencies.Dependency); MissingDependency when one has none."""
        with transaction(self._sessions) as s:
            self._get_revision(s, revision_id)
            return dependencies(s, revision_id)

    def posted_preview(self, revision_id: int, machine: str) -> Posted:
        """An APT/CL revision posted for a machine as a dispatch would post it, nothing
        stored (`PostRefused` with the line and why when the post refuses)."""
        with transaction(self._sessions) as s:
            rev, mach, posted = posted_for(s, revision_id, machine, self.machine_configs)
            if posted is None:
                raise InvalidUpload(
                    f"revision {revision_id} is G-code: it is sent as it is, not posted",
                    revision_id=revision_id,
                )
            return posted

    def text_for_machine(self, revision_id: int, machine: str, *, actor: str = "dnc") -> str:
        """What the machine is sent of a revision: G-code as it is; an APT/CL revision
        posted for the machine, stored as a derived revision (a remote request)."""
        with transaction(self._sessions) as s:
            rev, _, posted = posted_for(s, revision_id, machine, self.machine_configs)
            if posted is None:
                return read_text(s, rev.sha256)
            store_derived(s, rev, posted, actor=actor, now=self._now())
            return posted.text

    def derived_revisions(self, revision_id: int) -> list[dict]:
        """The G-code an APT/CL revision was posted to at dispatch, oldest first."""
        with transaction(self._sessions) as s:
            self._get_revision(s, revision_id)
            rows = s.scalars(
                select(m.DerivedRevision)
                .where(m.DerivedRevision.source_revision_id == revision_id)
                .order_by(m.DerivedRevision.id)
            )
            return [derived_info(d) for d in rows]

    def derived_text(self, derived_id: int) -> str:
        with transaction(self._sessions) as s:
            d = s.get(m.DerivedRevision, derived_id)
            if d is None:
                raise NotFound(f"no derived revision with id {derived_id}")
            return read_text(s, d.sha256)

    def released_revision(self, number: int, machine_kind: str) -> RevisionInfo:
        """The revision a machine gets when it requests program `number` (remote request)."""
        with transaction(self._sessions) as s:
            rev = s.scalar(
                select(m.Revision)
                .join(m.Program, m.Program.id == m.Revision.program_id)
                .where(
                    m.Program.number == number,
                    m.Program.machine_kind == machine_kind,
                    m.Revision.status == RELEASED,
                )
            )
            if rev is None:
                raise NotFound(f"no released revision of O{number:04d} for {machine_kind}")
            return _revision_info(rev)

    def diff(
        self,
        a_id: int,
        b_id: int,
        *,
        ignore_numbers: bool = False,
        ignore_whitespace: bool = False,
        ignore_comments: bool = False,
    ) -> str:
        a, b = self.get_revision(a_id), self.get_revision(b_id)
        return unified_diff(
            self.revision_text(a_id),
            self.revision_text(b_id),
            a_name=f"revision {a_id} (rev {a.seq})",
            b_name=f"revision {b_id} (rev {b.seq})",
            ignore_numbers=ignore_numbers,
            ignore_whitespace=ignore_whitespace,
            ignore_comments=ignore_comments,
        )

    def search(
        self,
        *,
        query: str | None = None,
        number: int | None = None,
        tag: str | None = None,
        text: str | None = None,
        machine_kind: str | None = None,
        limit: int = 50,
        cursor: str | None = None,
    ) -> Page:
        """Programs by name/number (`query`), exact number, tag, or text in any revision.

        `text` is a case-insensitive substring of any revision's text (every revision, not
        only the released one: finding which program ever used a tool is the point).
        Cursor pagination over program id: stable under concurrent inserts.
        """
        limit = max(1, min(limit, 500))
        stmt = select(m.Program).order_by(m.Program.id).limit(limit + 1)
        if cursor:
            stmt = stmt.where(m.Program.id > decode_cursor("p", cursor))
        if machine_kind:
            stmt = stmt.where(m.Program.machine_kind == machine_kind)
        if number is not None:
            stmt = stmt.where(m.Program.number == number)
        if query:
            like = f"%{_escape_like(query.lower())}%"
            name = m.Program.name
            bind = self._sessions.kw.get("bind")
            if bind is None or bind.dialect.name != "sqlite":
                # SQLite's LIKE folds ASCII case itself, exactly as its lower() would (both
                # leave other letters alone); lower() on every name doubled the scan's cost.
                name = func.lower(name)
            conds = [name.like(like, escape="\\")]
            digits = query.upper().removeprefix("O")
            if digits.isdigit() and int(digits) <= MAX_PROGRAM_NUMBER:  # beyond: no such O
                conds.append(m.Program.number == int(digits))
            stmt = stmt.where(or_(*conds))
        if tag:
            stmt = stmt.where(
                exists().where(
                    and_(m.ProgramTag.program_id == m.Program.id, m.ProgramTag.tag == tag)
                )
            )
        with transaction(self._sessions) as s:
            if text and _text_drives_from_index(s, text, number, query, self.text_search_from):
                after = decode_cursor("p", cursor) if cursor else 0
                ids = _first_programs_with_text(s, text, stmt.whereclause, after, limit + 1)
                rows = (
                    list(s.scalars(select(m.Program).where(m.Program.id.in_(ids)))) if ids else []
                )
                rows.sort(key=lambda p: p.id)
            else:
                if text:
                    stmt = stmt.where(_programs_with_text(s, text))
                rows = list(s.scalars(stmt))
            more = len(rows) > limit
            rows = rows[:limit]
            items = self._program_infos(s, rows)
        return Page(items, encode_cursor("p", rows[-1].id) if more else None)

    def audit(self, *, entity: str | None = None, entity_id: int | None = None) -> list[dict]:
        stmt = select(m.AuditEntry).order_by(m.AuditEntry.id)
        if entity:
            stmt = stmt.where(m.AuditEntry.entity == entity)
        if entity_id is not None:
            stmt = stmt.where(m.AuditEntry.entity_id == entity_id)
        with transaction(self._sessions) as s:
            return [
                dict(
                    at=a.at,
                    actor=a.actor,
                    action=a.action,
                    entity=a.entity,
                    entity_id=a.entity_id,
                    detail=a.detail,
                )
                for a in s.scalars(stmt)
            ]

    # -------------------------------------------------------------------------------- import

    def import_path(
        self,
        path: Path,
        *,
        machine_kind: str = "mill",
        author: str = "import",
        tags: Sequence[str] = (),
        post_kinds: Sequence[str] = (),
    ) -> list[tuple[Path, RevisionInfo | Exception]]:
        """Import one file or every program file under a directory.

        A file whose O number already exists becomes a new revision of that program; each
        file's outcome is reported separately, so one bad file does not stop the rest.
        APT (`.apt`) and CL files (`.cl` `.cls` ...) are imported as sources posted at
        dispatch, their number from PARTNO; `post_kinds` names the machine kinds they are for.
        """
        files = (
            sorted(p for p in path.rglob("*") if p.suffix.lower() in _IMPORTED)
            if path.is_dir()
            else [path]
        )
        results: list[tuple[Path, RevisionInfo | Exception]] = []
        for file in files:
            try:
                results.append(
                    (file, self._import_file(file, machine_kind, author, tags, post_kinds))
                )
            except (InvalidUpload, Conflict, OSError) as exc:
                results.append((file, exc))
        return results

    def _import_file(
        self,
        file: Path,
        machine_kind: str,
        author: str,
        tags: Sequence[str],
        post_kinds: Sequence[str] = (),
    ) -> RevisionInfo:
        if file.suffix.lower() not in _IMPORTED:
            raise InvalidUpload(f"{file}: not a program file (expected one of {sorted(_IMPORTED)})")
        check_size(file.stat().st_size, limit=self.upload_limit, name=str(file))
        text = decode_program(file.read_bytes(), limit=self.upload_limit, name=str(file))
        kind = kind_of_upload(None, file.name)
        header = read_header(text) if kind == GCODE else partno_header(text)
        if header.number is None:
            where = "in the first block" if kind == GCODE else "ending its PARTNO text"
            raise InvalidUpload(f"{file}: no O number {where}; cannot file it")
        source = dict(kind=kind, post_kinds=list(post_kinds) or None) if kind != GCODE else {}
        with transaction(self._sessions) as s:
            prog_id = s.scalar(
                select(m.Program.id).where(
                    m.Program.number == header.number, m.Program.machine_kind == machine_kind
                )
            )
        comment = f"imported from {file.name}"
        if prog_id is not None:
            return self.add_revision(
                prog_id, text, author=author, comment=comment, source="import", **source
            )
        _, rev = self.create_program(
            number=header.number,
            name=header.title or file.stem,
            text=text,
            machine_kind=machine_kind,
            tags=tags,
            author=author,
            comment=comment,
            source="import",
            **source,
        )
        return rev

    # ------------------------------------------------------------------------------ machines

    def register_machine(
        self,
        name: str,
        kind: str,
        *,
        dnc_address: str = "",
        modbus_address: str = "",
        status_address: str = "",
        memory_bytes: int = 0,
        dnc_profile: dict | None = None,
        axes: Sequence[str] | None = None,
        actor: str = "system",
    ) -> dict:
        """Create or update a machine's registry entry (idempotent by name). `axes`: its
        configured axes (what a job's program needs is matched to; None = not known)."""
        with transaction(self._sessions) as s:
            mach = s.scalar(select(m.Machine).where(m.Machine.name == name))
            if mach is None:
                mach = m.Machine(name=name, created_at=self._now())
                s.add(mach)
            mach.kind, mach.memory_bytes = kind, memory_bytes
            mach.dnc_profile = dict(dnc_profile or {})
            mach.dnc_address, mach.modbus_address = dnc_address, modbus_address
            mach.status_address = status_address
            mach.axes = list(axes) if axes is not None else None
            s.flush()
            self._record(s, actor, "machine.register", "machine", mach.id, name=name, kind=kind)
            return _machine_dict(mach)

    def machines(self) -> list[dict]:
        with transaction(self._sessions) as s:
            return [_machine_dict(x) for x in s.scalars(select(m.Machine).order_by(m.Machine.name))]

    def machine(self, name: str) -> dict:
        with transaction(self._sessions) as s:
            mach = s.scalar(select(m.Machine).where(m.Machine.name == name))
            if mach is None:
                raise NotFound(f"unknown machine {name!r}")
            return _machine_dict(mach)

    def note_transfer(self, machine: str, action: str, *, actor: str = "dnc", **detail) -> None:
        """Record a transfer-side event (remote request served or refused, upload...)."""
        with transaction(self._sessions) as s:
            mach = s.scalar(select(m.Machine).where(m.Machine.name == machine))
            self._record(
                s, actor, action, "machine", mach.id if mach else None, machine=machine, **detail
            )

    # ----------------------------------------------------------------- tools, fixtures, stock

    def add_resource(
        self, kind: str, code: str, *, description: str = "", data: dict | None = None
    ) -> int:
        if kind not in ("tool", "fixture", "material"):
            raise InvalidUpload(f"resource kind must be tool, fixture or material, got {kind!r}")
        with transaction(self._sessions) as s:
            res = s.scalar(
                select(m.Resource).where(m.Resource.kind == kind, m.Resource.code == code)
            )
            if res is None:
                res = m.Resource(kind=kind, code=code)
                s.add(res)
            res.description, res.data = description, data or {}
            s.flush()
            self._record(s, "system", "resource.upsert", "resource", res.id, kind=kind, code=code)
            return res.id

    def link_resource(self, program_id: int, resource_id: int, *, actor: str = "system") -> None:
        with transaction(self._sessions) as s:
            self._get_program(s, program_id)
            if s.get(m.Resource, resource_id) is None:
                raise NotFound(f"no resource with id {resource_id}")
            if s.get(m.ProgramResource, (program_id, resource_id)) is None:
                s.add(m.ProgramResource(program_id=program_id, resource_id=resource_id))
                self._record(
                    s, actor, "program.link", "program", program_id, resource_id=resource_id
                )

    def resources(self, program_id: int) -> list[dict]:
        with transaction(self._sessions) as s:
            self._get_program(s, program_id)
            rows = s.scalars(
                select(m.Resource)
                .join(m.ProgramResource, m.ProgramResource.resource_id == m.Resource.id)
                .where(m.ProgramResource.program_id == program_id)
                .order_by(m.Resource.kind, m.Resource.code)
            )
            return [
                dict(id=r.id, kind=r.kind, code=r.code, description=r.description, data=r.data)
                for r in rows
            ]

    # ------------------------------------------------------------------------------ internals

    def _decode(self, text: str | bytes | ProgramUpload, name: str) -> str | ProgramUpload:
        if isinstance(text, ProgramUpload):
            return text if text.finished else text.finish()
        if isinstance(text, bytes):
            return decode_program(text, limit=self.upload_limit, name=name)
        check_size(len(text.encode("utf-8", "surrogatepass")), limit=self.upload_limit, name=name)
        return normalise_text(text, name=name)

    def _check(self, text: str | ProgramUpload, machine_kind: str) -> Checked:
        """The NC check's errors and the calls of other programs (dnc.dependencies)."""
        if isinstance(text, ProgramUpload):
            with text.line_file() as lines:
                calls = program_calls(lines).calls
        else:
            calls = program_calls(text.splitlines()).calls
        if self._checker is None:
            return Checked([], calls)
        extra: dict[str, Any] = {}
        if calls and getattr(self._checker, "resolves_calls", False):
            library = LibraryPrograms(self._sessions, machine_kind)
            extra["programs"] = library.stand_in_for(calls)
        if isinstance(text, ProgramUpload):
            if getattr(self._checker, "reads_files", False):
                with text.line_file() as lines:
                    return _checked(self._checker(lines, machine_kind, **extra), calls)
            return _checked(self._checker(text.text(), machine_kind, **extra), calls)
        return _checked(self._checker(text, machine_kind, **extra), calls)

    def _check_kind(
        self,
        text: str | ProgramUpload,
        kind: str,
        machine_kind: str,
        post_kinds: Iterable[str] | None,
        name: str,
    ) -> tuple[list[str], Checked]:
        """(kinds a source is meant for, check): the NC check for G-code; for APT and CL
        the processor (malformed: refused) and a trial post per kind (a source calls no
        other program: its posted G-code has no M98)."""
        kind = kind_of_upload(kind, None)  # refuses a kind that is none of them
        if kind == GCODE:
            if post_kinds:
                raise InvalidUpload(
                    "post_kinds is for APT and CL revisions (kind apt or cl), not G-code",
                    pointer="#/post_kinds",
                )
            return [], self._check(text, machine_kind)
        with transaction(self._sessions) as s:
            cell = sorted(set(s.scalars(select(m.Machine.kind))))
        source = text.text() if isinstance(text, ProgramUpload) else text
        kinds, errors = check_source(source, kind, name, post_kinds, cell or [machine_kind])
        return kinds, Checked(errors, [])

    def _add_revision(
        self,
        s: Session,
        prog: m.Program,
        text: str | ProgramUpload,
        checked: Checked,
        author: str,
        comment: str,
        source: str,
        kind: str = GCODE,
        post_kinds: list[str] | None = None,
    ) -> m.Revision:
        if isinstance(text, ProgramUpload):
            # hashed and counted as it streamed in; stored from its file a chunk at a time,
            # never whole in memory (dnc.content)
            digest, size, lines = text.sha256, text.stored_size, text.lines
            chunks = text.chunks()
        else:
            # stored text is ASCII (dnc.tape.normalise_text): characters are bytes
            digest, lines = sha256_of(text), count_lines(text)
            size = len(text) if text.isascii() else len(text.encode("utf-8"))
            chunks = split_text(text)
        try:
            store(s, digest, size, chunks)
        except IntegrityError as exc:  # a concurrent upload stored the same text first
            raise Conflict(
                f"the same text was stored concurrently for program {prog.id}; retry the upload"
            ) from exc
        seq = (
            s.scalar(select(func.max(m.Revision.seq)).where(m.Revision.program_id == prog.id)) or 0
        ) + 1
        rev = m.Revision(
            program_id=prog.id,
            seq=seq,
            sha256=digest,
            size=size,
            lines=lines,
            author=author,
            comment=comment,
            source=source,
            status=DRAFT,
            created_at=self._now(),
            check_ok=not checked.errors,
            check_errors=checked.errors,
            kind=kind,
            post_kinds=list(post_kinds or []),
            axes=list(checked.axes) if checked.axes is not None else None,
        )
        s.add(rev)
        try:
            s.flush()
        except IntegrityError as exc:  # a concurrent revision took the same seq
            raise Conflict(f"program {prog.id} was changed concurrently; retry the upload") from exc
        record_calls(s, rev.id, checked.calls)
        self._record(
            s,
            author,
            "revision.create",
            "revision",
            rev.id,
            program_id=prog.id,
            seq=seq,
            sha256=digest,
            source=source,
            check_ok=rev.check_ok,
            kind=kind,
        )
        return rev

    def _record(
        self, s: Session, actor: str, action: str, entity: str, entity_id: int | None, **detail
    ) -> None:
        record(
            s,
            now=self._now(),
            actor=actor,
            action=action,
            entity=entity,
            entity_id=entity_id,
            **detail,
        )

    def _get_program(self, s: Session, program_id: int) -> m.Program:
        prog = s.get(m.Program, program_id)
        if prog is None:
            raise NotFound(f"no program with id {program_id}")
        return prog

    def _get_revision(self, s: Session, revision_id: int, *, lock: bool = False) -> m.Revision:
        stmt = select(m.Revision).where(m.Revision.id == revision_id)
        if lock:
            stmt = stmt.with_for_update()
        rev = s.scalar(stmt)
        if rev is None:
            raise NotFound(f"no revision with id {revision_id}")
        return rev

    def _program_info(self, s: Session, prog: m.Program) -> ProgramInfo:
        return self._program_infos(s, [prog])[0]

    def _program_infos(self, s: Session, progs: list[m.Program]) -> list[ProgramInfo]:
        """Infos for a page of programs in three queries, however long the page."""
        ids = [p.id for p in progs]
        tags: dict[int, list[str]] = {i: [] for i in ids}
        for pid, tag in s.execute(
            select(m.ProgramTag.program_id, m.ProgramTag.tag)
            .where(m.ProgramTag.program_id.in_(ids))
            .order_by(m.ProgramTag.tag)
        ):
            tags[pid].append(tag)
        released = dict(
            s.execute(
                select(m.Revision.program_id, m.Revision.id).where(
                    m.Revision.program_id.in_(ids), m.Revision.status == RELEASED
                )
            ).all()
        )
        newest = (
            select(m.Revision.program_id, func.max(m.Revision.seq).label("seq"))
            .where(m.Revision.program_id.in_(ids))
            .group_by(m.Revision.program_id)
            .subquery()
        )
        latest = dict(
            s.execute(
                select(m.Revision.program_id, m.Revision.id).join(
                    newest,
                    and_(
                        m.Revision.program_id == newest.c.program_id,
                        m.Revision.seq == newest.c.seq,
                    ),
                )
            ).all()
        )
        return [
            ProgramInfo(
                p.id,
                p.number,
                p.name,
                p.machine_kind,
                p.description,
                tuple(tags[p.id]),
                p.created_at,
                released.get(p.id),
                latest.get(p.id),
            )
            for p in progs
        ]


def _revision_info(r: m.Revision) -> RevisionInfo:
    return RevisionInfo(
        r.id,
        r.program_id,
        r.seq,
        r.sha256,
        r.size,
        r.lines,
        r.author,
        r.comment,
        r.source,
        r.status,
        r.created_at,
        r.status_changed_at,
        r.approved_by,
        r.approval_comment,
        r.check_ok,
        list(r.check_errors or []),
        r.kind or GCODE,
        list(r.post_kinds or []),
        list(r.axes) if r.axes is not None else None,
    )


def _checked(found: list[dict[str, Any]], calls: list[Call]) -> Checked:
    """A checker that knows what the program needs of a machine (dnc.checker.Findings)
    says so in `axes`; another's revisions have no axes known."""
    return Checked(list(found), calls, getattr(found, "axes", None))


def _machine_dict(x: m.Machine) -> dict:
    return dict(
        name=x.name,
        kind=x.kind,
        dnc_address=x.dnc_address,
        modbus_address=x.modbus_address,
        status_address=x.status_address,
        memory_bytes=x.memory_bytes,
        dnc_profile=dict(x.dnc_profile or {}),
        axes=list(x.axes) if x.axes is not None else None,
    )


# SQLite's trigram index of every revision's text (migrations 0005, 0011), contentless: an
# entry per chunk of each distinct text of a program, its rowid program_id << 32 | chunk id,
# so its hits come grouped by program, in program order.
_REVISION_TEXT = table("revision_text", column("rowid", Integer))
_PROGRAM_SHIFT = 32


def _match(text: str):
    """FTS5 phrase for `text`: with the trigram tokenizer, a case-folded substring match."""
    return literal_column("revision_text").op("MATCH")('"' + text.replace('"', '""') + '"')


def _text_drives_from_index(
    s: Session, text: str, number: int | None, query: str | None, pinned: str
) -> bool:
    """Walk the index's hits (program order) rather than the programs?

    The index needs 3 characters or more. With a number or a name to look for, few programs
    qualify and each is checked against the index directly; otherwise the hits are walked,
    which reaches a page of programs after about a page of hits however rare the text is.
    """
    if s.get_bind().dialect.name != "sqlite" or len(text) < 3:
        return False
    if pinned != "auto":
        return pinned == "index"
    return number is None and not query


def _first_programs_with_text(s: Session, text: str, where, after: int, want: int) -> list[int]:
    """Ids of the first `want` programs past `after` that pass `where` and have `text` in a
    revision, in id order: read off the index hits, stopping as soon as there are enough."""
    key = _REVISION_TEXT.c.rowid
    owner = key.op(">>")(_PROGRAM_SHIFT)
    programs = m.Program.__table__
    # Core on the tables: an ORM-enabled select would buffer every hit before the first
    # one is looked at, and text in every revision has a million of them.
    hits = (
        select(owner)
        .select_from(_REVISION_TEXT)
        .join(programs, programs.c.id == owner)
        .where(_match(text), key >= (after + 1) << _PROGRAM_SHIFT)
        .order_by(key)
    )
    if where is not None:
        hits = hits.where(where)
    ids: list[int] = []
    result = s.execute(hits)  # rows are stepped as they are read: the walk stops early
    try:
        for (program_id,) in result:
            if not ids or ids[-1] != program_id:
                ids.append(program_id)
                if len(ids) == want:
                    break
    finally:
        result.close()
    return ids


def _programs_with_text(s: Session, text: str):
    """A condition on Program.id: some revision of the program contains `text` (any case).

    SQLite: the program's own range of the trigram index, probed per program (the index's
    rowid carries the program id). Under 3 characters, which the trigram index cannot
    answer, a LIKE over the program's revisions (SQLite's LIKE folds ASCII case, as the
    index does). PostgreSQL: ILIKE, answered by the pg_trgm GIN index when the extension
    is there.
    """
    like = f"%{_escape_like(text)}%"
    if s.get_bind().dialect.name != "sqlite":
        chunks = m.ContentChunk
        matching = select(chunks.sha256).where(chunks.text.ilike(like, escape="\\"))
        in_any_revision = select(m.Revision.program_id)
        return m.Program.id.in_(in_any_revision.where(m.Revision.sha256.in_(matching)))
    if len(text) >= 3:
        key = _REVISION_TEXT.c.rowid
        first = m.Program.id.op("<<")(_PROGRAM_SHIFT)
        past = (m.Program.id + 1).op("<<")(_PROGRAM_SHIFT)
        return exists(
            select(1).select_from(_REVISION_TEXT).where(_match(text), key >= first, key < past)
        )
    return exists(
        select(1)
        .select_from(m.Revision)
        .join(m.ContentChunk, m.ContentChunk.sha256 == m.Revision.sha256)
        .where(m.Revision.program_id == m.Program.id, m.ContentChunk.text.like(like, escape="\\"))
    )


def _escape_like(s: str) -> str:
    return s.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_")
