"""Programs across files in the library: who calls whom, by O number, per machine kind.

A revision's calls (`M98 P`, `G65 P`, `G66 P` with a literal number, cnc.gcode.calls) are
stored at upload (table revision_calls). They are kept by O number: the upload's NC check
resolves them against the library's programs of that moment, a dispatch against the
released revisions of its moment.

* Upload: a called program the library holds is checked through (its released revision,
  else its newest); one it does not hold yet does not fail the check (programs may be
  uploaded in any order): the check goes on past the call as if the subprogram were empty,
  and the call shows as unresolved.
* Dispatch: every program the revision calls, and every program those call, needs a
  released revision; the transfer sends them, deepest first, before the program itself. A
  missing one refuses the dispatch before anything is recorded or sent
  (`MissingDependency`, problem type `missing-dependency`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from sqlalchemy import or_, select
from sqlalchemy.orm import Session, sessionmaker

from cnc.gcode.calls import Call, program_calls
from dnc import models as m
from dnc.content import read_text
from dnc.db import transaction
from dnc.errors import DncError

RELEASED, OBSOLETE = "released", "obsolete"


class MissingDependency(DncError):
    """A program the dispatched revision calls (directly or through another) has no
    released revision: nothing is sent."""

    kind = "missing-dependency"


@dataclass(frozen=True, slots=True)
class Dependency:
    """A released revision a dispatch brings along."""

    number: int
    program_id: int
    revision_id: int
    sha256: str


def record_calls(s: Session, revision_id: int, calls: Iterable[Call]) -> None:
    for c in calls:
        s.add(m.RevisionCall(revision_id=revision_id, line=c.line, col=c.col, code=c.code,
                             number=c.number, packed=c.packed, short_number=c.short))  # fmt: skip


def _calls(s: Session, revision_id: int) -> list[Call]:
    rows = s.scalars(
        select(m.RevisionCall)
        .where(m.RevisionCall.revision_id == revision_id)
        .order_by(m.RevisionCall.line, m.RevisionCall.col)
    )
    return [Call(r.code, r.number, r.line, r.col, r.packed) for r in rows]


def _programs(s: Session, numbers: Iterable[int], kind: str) -> dict[int, m.Program]:
    wanted = sorted(set(numbers))
    if not wanted:
        return {}
    rows = s.scalars(
        select(m.Program).where(m.Program.number.in_(wanted), m.Program.machine_kind == kind)
    )
    return {p.number: p for p in rows}


def _released(s: Session, program_ids: Iterable[int]) -> dict[int, m.Revision]:
    ids = sorted(set(program_ids))
    if not ids:
        return {}
    rows = s.scalars(
        select(m.Revision).where(m.Revision.program_id.in_(ids), m.Revision.status == RELEASED)
    )
    return {r.program_id: r for r in rows}


def calls_of(s: Session, revision_id: int, kind: str) -> list[dict]:
    """The revision's calls, each resolved to the program it reaches today (or not)."""
    calls = _calls(s, revision_id)
    progs = _programs(s, (n for c in calls for n in c.candidates), kind)
    released = _released(s, (p.id for p in progs.values()))
    out = []
    for c in calls:
        number = c.resolve(progs.__contains__)
        prog = progs.get(number) if number is not None else None
        rel = released.get(prog.id) if prog is not None else None
        out.append(
            dict(
                code=c.code,
                number=number if number is not None else c.named(),
                line=c.line,
                col=c.col,
                program_id=prog.id if prog is not None else None,
                released_revision_id=rel.id if rel is not None else None,
            )
        )
    return out


def called_by(s: Session, program: m.Program) -> list[dict]:
    """The programs of the same kind whose current revision (released, or the newest when
    none is released) calls `program`, with the calling line."""
    n = program.number
    rows = s.execute(
        select(m.RevisionCall, m.Revision, m.Program)
        .join(m.Revision, m.Revision.id == m.RevisionCall.revision_id)
        .join(m.Program, m.Program.id == m.Revision.program_id)
        .where(
            m.Program.machine_kind == program.machine_kind,
            m.Revision.status != OBSOLETE,
            or_(m.RevisionCall.number == n, m.RevisionCall.short_number == n),
        )
        .order_by(m.Program.number, m.Revision.seq, m.RevisionCall.line)
    ).all()
    current = _current_revisions(s, {p.id for _, _, p in rows})
    out = []
    for call, rev, prog in rows:
        if current.get(prog.id) != rev.id:
            continue
        c = Call(call.code, call.number, call.line, call.col, call.packed)
        if n not in c.candidates:
            continue
        if c.packed and c.number != n and _programs(s, [c.number], program.machine_kind):
            continue  # the 8-digit program itself exists: the call is to it
        out.append(dict(program_id=prog.id, number=prog.number, name=prog.name,
                        revision_id=rev.id, seq=rev.seq, status=rev.status, code=call.code,
                        line=call.line))  # fmt: skip
    return out


def _current_revisions(s: Session, program_ids: set[int]) -> dict[int, int]:
    """program id -> its released revision, else its newest draft."""
    out: dict[int, int] = {}
    if not program_ids:
        return out
    rows = s.execute(
        select(m.Revision.program_id, m.Revision.id, m.Revision.status)
        .where(m.Revision.program_id.in_(sorted(program_ids)), m.Revision.status != OBSOLETE)
        .order_by(m.Revision.program_id, m.Revision.seq)
    )
    released: dict[int, int] = {}
    for pid, rid, status in rows:
        out[pid] = rid  # the newest last
        if status == RELEASED:
            released[pid] = rid
    out.update(released)
    return out


def dependencies(s: Session, revision_id: int) -> list[Dependency]:
    """The released revisions a dispatch of `revision_id` brings along: every program it
    calls, transitively, deepest first (a subprogram before the program that calls it),
    each once. MissingDependency names the first call that reaches no released revision."""
    if s.scalar(select(m.RevisionCall.line).where(m.RevisionCall.revision_id == revision_id)
                .limit(1)) is None:  # fmt: skip
        return []  # most programs call none: one indexed query
    root = s.get(m.Revision, revision_id)
    if root is None:
        return []
    root_prog = s.get(m.Program, root.program_id)
    kind = root_prog.machine_kind
    order: list[Dependency] = []
    seen = {root_prog.number}

    def visit(rev: m.Revision, prog: m.Program) -> None:
        calls = _calls(s, rev.id)
        progs = _programs(s, (n for c in calls for n in c.candidates), kind)
        released = _released(s, (p.id for p in progs.values()))
        for c in calls:
            number = c.resolve(lambda n: n in progs and progs[n].id in released)
            if number is None:
                raise _missing(c, prog, rev, progs, kind)
            if number in seen:
                continue  # already brought (or on the way: a recursive call)
            seen.add(number)
            callee, crev = progs[number], released[progs[number].id]
            visit(crev, callee)
            order.append(Dependency(number, callee.id, crev.id, crev.sha256))

    visit(root, root_prog)
    return order


def _missing(
    c: Call, prog: m.Program, rev: m.Revision, progs: dict[int, m.Program], kind: str
) -> MissingDependency:
    number = next((n for n in c.candidates if n in progs), c.named())
    held = progs.get(number)
    why = (
        f"program {held.id} (O{number:04d}) has no released revision"
        if held is not None
        else f"the library has no O{number:04d} for {kind} machines"
    )
    return MissingDependency(
        f"O{prog.number:04d} (revision {rev.id}) line {c.line}: {c.code} P{c.number} calls "
        f"O{number:04d}, but {why}; release it before dispatching (nothing was sent)",
        missing=number,
        caller=prog.number,
        caller_revision_id=rev.id,
        line=c.line,
        col=c.col,
        code=c.code,
    )


class LibraryPrograms(Mapping[int, str]):
    """The library as the NC check's `programs` mapping: a called program's released
    revision, else its newest, read when the check reaches the call. Numbers in `stand_in`
    (calls the library cannot answer yet), and those a called program calls and the library
    lacks, read as an empty subprogram, so the check goes on past them."""

    def __init__(
        self, sessions: sessionmaker[Session], kind: str, *, stand_in: Iterable[int] = ()
    ) -> None:
        self._sessions, self._kind = sessions, kind
        self._stand_in = set(stand_in)
        self._held: dict[int, bool] = {}  # O number -> the library has it (asked once)

    def _has(self, number: int) -> bool:
        """One indexed query per number a call names (a library holds a million programs:
        they are not all listed for one upload)."""
        known = self._held.get(number)
        if known is None:
            with transaction(self._sessions) as s:
                known = self._held[number] = (
                    s.scalar(
                        select(m.Program.id).where(
                            m.Program.number == number, m.Program.machine_kind == self._kind
                        )
                    )
                    is not None
                )
        return known

    def __contains__(self, number: object) -> bool:
        return isinstance(number, int) and (number in self._stand_in or self._has(number))

    def __getitem__(self, number: int) -> str:
        if not self._has(number):
            if number in self._stand_in:
                return f"O{number}\nM99\n"
            raise KeyError(number)
        with transaction(self._sessions) as s:
            rev = s.scalar(
                select(m.Revision)
                .join(m.Program, m.Program.id == m.Revision.program_id)
                .where(
                    m.Program.number == number,
                    m.Program.machine_kind == self._kind,
                    m.Revision.status != OBSOLETE,
                )
                .order_by((m.Revision.status == RELEASED).desc(), m.Revision.seq.desc())
                .limit(1)
            )
            if rev is None:  # only obsolete revisions: nothing to call
                return f"O{number}\nM99\n"
            text = read_text(s, rev.sha256)
        # what it calls in turn and the library lacks reads as empty too (any order of uploads)
        self.stand_in_for(program_calls(text.splitlines()).calls)
        return text

    def __iter__(self) -> Iterator[int]:
        # the numbers asked about so far: the check only asks `in` and `[]`
        return iter(sorted({n for n, held in self._held.items() if held} | self._stand_in))

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def missing(self, calls: Iterable[Call]) -> list[Call]:
        """The calls the library cannot answer today."""
        return [c for c in calls if c.resolve(self._has) is None]

    def stand_in_for(self, calls: Iterable[Call]) -> LibraryPrograms:
        """Answer the calls the library lacks with an empty subprogram."""
        self._stand_in.update(c.named() for c in self.missing(calls))
        return self
