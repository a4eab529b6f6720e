"""Posting at dispatch: APT source and CL data become the G-code of the machine they go to.

A revision is of kind `gcode` (the NC program itself), `apt` (an APT part program) or `cl`
(CL data from a CAM system). A source revision is checked on upload: it must process (APT)
or read (CL) without error, else it is refused with file, line, column and why; then it is
trial-posted for every machine kind it is meant for, and a kind whose post fails makes a
check error (the revision cannot be released), as a failed NC check does for G-code.

The kinds a source is meant for: the upload's `post_kinds`, else the `MACHIN/` statement
when its name is a machine kind (`MACHIN/MILL,1` -> mill), else every kind of the machines
registered in the cell.

At dispatch the source is posted for the machine's kind with the machine's configuration
(the post is chosen by `cam.post.POSTS[kind]`, the travel checked against the machine's axes
and work offsets), and the posted text is stored as a derived revision in the same
transaction as the dispatch that sends it. The same source posted to the same text again
(another machine of the kind, a re-dispatch) finds the derived revision with that sha256.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from pathlib import PurePath
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from cam.chain import APT_SUFFIXES, CL_SUFFIXES, records_from_text
from cam.errors import CamError
from cam.machine5 import Mill5Config, from_nc_config
from cam.post import CAM_KINDS, POSTS, Machine, PostOptions, load_machine, post
from cnc.config import SHIPPED_MACHINES, builtin_machine
from cnc.interp import check
from dnc import models as m
from dnc.content import read_text, split_text, store
from dnc.errors import DncError, InvalidUpload, NotFound, WorkflowError
from dnc.events import record
from dnc.tape import TapeHeader, count_lines, sha256_of

GCODE, APT, CL = "gcode", "apt", "cl"
REVISION_KINDS = (GCODE, APT, CL)
SOURCE_KINDS = (APT, CL)
MAX_CHECK_ERRORS = 100

MachineConfigs = Callable[[str, str], Any]
"""(machine name, machine kind) -> the machine's configuration (a `cnc.config.MachineConfig`,
or for the CAM-described kinds a `cam.machine5.Mill5Config`), None when the host has none:
then the kind's shipped machine stands in for it."""


class PostRefused(DncError):
    """A source the post-processor cannot turn into a program for this machine: the CL/APT
    line and why (5-axis data to a 3-axis machine, travel beyond a limit, ...)."""

    kind = "post-refused"


@dataclass(frozen=True, slots=True)
class Posted:
    """A source posted for one machine (nothing stored)."""

    text: str
    sha256: str
    machine: str
    machine_kind: str
    post_name: str
    post_version: str
    tolerance_mm: float | None
    warnings: tuple[str, ...]


def kind_of_upload(kind: str | None, filename: str | None) -> str:
    """The revision kind of an upload: the `kind` given, else by the file's suffix (`.apt`
    APT, `.cl` `.cls` `.aptsource` `.cldata` `.clf` CL data), else G-code."""
    if kind:
        if kind not in REVISION_KINDS:
            raise InvalidUpload(
                f"kind must be one of {', '.join(REVISION_KINDS)}, got {kind!r}", pointer="#/kind"
            )
        return kind
    suffix = PurePath(filename or "").suffix.lower()
    if suffix in APT_SUFFIXES:
        return APT
    if suffix in CL_SUFFIXES:
        return CL
    return GCODE


_PARTNO = re.compile(r"^\s*PARTNO\b[ \t,]*(?P<text>.*?)\s*$", re.IGNORECASE | re.MULTILINE)
_DIGITS_END = re.compile(r"(\d{1,8})$")


def partno_header(head: str) -> TapeHeader:
    """An APT/CL file's number and title, from its PARTNO text (`PARTNO PLATE 2001`: O2001,
    "PLATE 2001"), as the post numbers the program it writes."""
    found = _PARTNO.search(head)
    if found is None:
        return TapeHeader(None, "")
    title = found.group("text")
    digits = _DIGITS_END.search(title)
    number = int(digits.group(1)) if digits and int(digits.group(1)) > 0 else None
    return TapeHeader(number, title)


def read_source(text: str, kind: str, file: str) -> list:
    """The CL records of a source; malformed input is refused with file, line, column."""
    try:
        return list(records_from_text(text, kind, file))
    except CamError as e:
        what = "APT program" if kind == APT else "CL data"
        raise InvalidUpload(
            f"{e.file}:{e.line}:{e.col}: {e.message} (malformed {what})",
            file=e.file,
            line=e.line,
            column=e.col,
            pointer="#/text",
        ) from None


def machin_kinds(records: Iterable) -> list[str]:
    """The machine kinds `MACHIN/name` statements name (names that are no machine kind,
    `MACHIN/FANUC,6` as CAM systems write it, say nothing about the kind)."""
    kinds = []
    for rec in records:
        if rec.word == "MACHIN" and rec.words:
            name = rec.words[0].lower()
            if name in POSTS and name not in kinds:
                kinds.append(name)
    return kinds


def check_source(
    text: str, kind: str, file: str, post_kinds: Iterable[str] | None, cell_kinds: list[str]
) -> tuple[list[str], list[dict[str, Any]]]:
    """(the kinds the source is meant for, check errors of its trial posts)."""
    records = read_source(text, kind, file)
    kinds = _clean_kinds(post_kinds) if post_kinds else []
    for k in kinds:
        if k not in POSTS:
            raise InvalidUpload(
                f"post_kinds: no post-processor for machine kind {k!r} "
                f"(known: {', '.join(sorted(POSTS))})",
                pointer="#/post_kinds",
            )
    kinds = kinds or machin_kinds(records) or sorted(set(cell_kinds))
    errors: list[dict[str, Any]] = []
    for k in kinds:
        try:
            _post(records, _stand_in(k), None, file)
        except PostRefused as e:
            errors.append(
                {
                    "line": e.detail.get("line", 0),
                    "col": e.detail.get("column", 0),
                    "message": f"post for {k}: {e.detail.get('reason', e.message)}",
                    "machine_kind": k,
                }
            )
    return kinds, errors[:MAX_CHECK_ERRORS]


def post_for_machine(
    text: str,
    kind: str,
    *,
    file: str,
    machine: str,
    machine_kind: str,
    config: Any,
    program_number: int,
) -> Posted:
    """Post a source for one machine and check the result as the machine will run it.

    A kind whose post has its own machine description (mill5, `cam.post.CAM_KINDS`) given
    the NC's configuration of the machine: the post's description is made from it
    (`cam.machine5.from_nc_config`: the machine's kinematics and travel), and the NC
    kernel checks the posted program with it."""
    nc_config = None
    if machine_kind in CAM_KINDS and config is not None and not isinstance(config, Mill5Config):
        nc_config = config
        try:
            config = from_nc_config(config)
        except CamError as e:
            raise PostRefused(
                f"{machine}: {e.message} (posting for {machine}, a {machine_kind})",
                machine=machine,
                machine_kind=machine_kind,
            ) from None
    mach = Machine(machine, machine_kind, config) if config is not None else None
    mach = mach or dataclasses.replace(_stand_in(machine_kind), name=machine)
    records = read_source(text, kind, file)
    return _post(records, mach, program_number, file, travel=True, nc_config=nc_config)


def _post(
    records: list, mach, program_number: int | None, file: str, *, travel=False, nc_config=None
) -> Posted:
    try:
        p, stream = post(iter(records), mach, PostOptions(program_number=program_number), file)
        blocks = list(stream)
    except CamError as e:
        raise _refused(mach, e.file, e.line, e.col, e.message) from None
    text = "".join(b.text + "\n" for b in blocks)
    nc_config = nc_config or _nc_machine(mach)
    if nc_config is not None:
        _nc_check(text, blocks, mach, nc_config, file, travel)
    return Posted(
        text=text,
        sha256=sha256_of(text),
        machine=mach.name,
        machine_kind=mach.kind,
        post_name=p.name,
        post_version=p.version,
        tolerance_mm=getattr(p, "tol_mm", None),
        warnings=tuple(str(w) for w in p.summary.warnings),
    )


def _nc_machine(mach):
    """The NC kernel's configuration to check a post for `mach` with: the machine's own
    for the NC-described kinds (mill, lathe), the kind's shipped NC machine for a kind the
    post describes itself (mill5: cnc/machines/mill5.yaml), None when the NC has none."""
    if mach.kind in ("mill", "lathe"):
        return mach.config
    return builtin_machine(mach.kind) if mach.kind in SHIPPED_MACHINES else None


def _nc_check(text: str, blocks: list, mach, cfg, file: str, travel: bool) -> None:
    """The posted program through the NC kernel's check for this machine (`cfg`, its NC
    configuration): with its axis travel and work offsets at dispatch (`travel`), syntax
    and modal rules only for a trial post (the kind's machines may differ in travel and
    offsets). The first error points back at the CL/APT line that made the block."""
    params = cfg.params
    data = cfg.machine_data.initial() if travel and cfg.machine_data is not None else None
    if not travel:
        big = 1e9
        params = dataclasses.replace(
            params,
            axes=tuple(dataclasses.replace(a, min_mm=-big, max_mm=big) for a in params.axes),
        )
    errors = check(text.splitlines(), params, file="posted", machine_data=data)
    if errors:
        e = errors[0]
        line, reason = 0, e.message
        if 0 < e.line <= len(blocks):
            b = blocks[e.line - 1]
            line, reason = b.cl_line, f"posted block {e.line} ({b.text}): {e.message}"
        raise _refused(mach, file, line, 0, reason)


def _refused(mach, file: str, line: int, col: int, reason: str) -> PostRefused:
    return PostRefused(
        f"{file}:{line}:{col}: {reason} (posting for {mach.name}, a {mach.kind})",
        file=file,
        line=line,
        column=col,
        reason=reason,
        machine=mach.name,
        machine_kind=mach.kind,
    )


def _stand_in(kind: str):
    """The kind's shipped machine (`cam.post.load_machine`): mill -> mill3, lathe -> lathe2,
    mill5 -> cam/machines/mill5.yaml."""
    shipped = {"mill": "mill3", "lathe": "lathe2", "mill5": "mill5"}
    if kind not in POSTS or kind not in shipped:
        known = ", ".join(sorted(POSTS))
        raise PostRefused(
            f"no post-processor with a machine for kind {kind!r} (known: {known})",
            machine_kind=kind,
        )
    return load_machine(shipped[kind])


def _clean_kinds(kinds: Iterable[str]) -> list[str]:
    out: list[str] = []
    for k in kinds:
        k = k.strip().lower()
        if k and k not in out:
            out.append(k)
    return out


def default_machine_configs(name: str, kind: str) -> Any:
    """Without a cell: no machine's own configuration (the kind's shipped one stands in)."""
    return None


# ----------------------------------------------------------------------- in a transaction


def posted_for(
    s: Session,
    revision_id: int,
    machine: str,
    configs: MachineConfigs = default_machine_configs,
) -> tuple[m.Revision, m.Machine, Posted | None]:
    """(revision, machine, its post) for a dispatch of the revision to the machine; the post
    is None for a G-code revision. Refuses a source not meant for the machine's kind."""
    rev = s.get(m.Revision, revision_id)
    if rev is None:
        raise NotFound(f"no revision with id {revision_id}")
    mach = s.scalar(select(m.Machine).where(m.Machine.name == machine))
    if mach is None:
        raise NotFound(f"unknown machine {machine!r}")
    if rev.kind not in SOURCE_KINDS:
        return rev, mach, None
    prog = s.get(m.Program, rev.program_id)
    text = read_text(s, rev.sha256)
    meant = not rev.post_kinds or mach.kind in rev.post_kinds
    not_meant = (
        f"revision {rev.id} is meant for {', '.join(rev.post_kinds)} machines; "
        f"{mach.name} is a {mach.kind}"
    )
    try:
        # posted even when not meant for the kind: the post's own reason (5-axis data to a
        # 3-axis mill, line 9) says more than the kinds do
        posted = post_for_machine(
            text,
            rev.kind,
            file=f"revision {rev.id} ({rev.kind})",
            machine=mach.name,
            machine_kind=mach.kind,
            config=configs(mach.name, mach.kind),
            program_number=prog.number,
        )
    except PostRefused as e:
        if not meant:
            e.message = f"{e.message}; {not_meant}"
            e.args = (e.message,)
        raise
    if not meant:
        raise WorkflowError(not_meant, machine=mach.name, machine_kind=mach.kind)
    return rev, mach, posted


def store_derived(
    s: Session, rev: m.Revision, posted: Posted, *, actor: str, now: datetime
) -> m.DerivedRevision:
    """The derived revision holding `posted`: the one with its sha256 if the source was
    posted to the same text for the kind before, else a new one (with its audit entry)."""
    same = select(m.DerivedRevision).where(
        m.DerivedRevision.source_revision_id == rev.id,
        m.DerivedRevision.machine_kind == posted.machine_kind,
        m.DerivedRevision.sha256 == posted.sha256,
    )
    found = s.scalar(same)
    if found is not None:
        return found
    store(s, posted.sha256, len(posted.text), split_text(posted.text))
    derived = m.DerivedRevision(
        source_revision_id=rev.id,
        machine_kind=posted.machine_kind,
        post_name=posted.post_name,
        post_version=posted.post_version,
        tolerance_mm=posted.tolerance_mm,
        sha256=posted.sha256,
        size=len(posted.text),
        lines=count_lines(posted.text),
        machine=posted.machine,
        created_at=now,
    )
    s.add(derived)
    # a concurrent dispatch of the same source to the same kind may store the same text
    # first: the unique key refuses the second (IntegrityError), and its caller retries
    s.flush()
    record(
        s,
        now=now,
        actor=actor,
        action="revision.posted",
        entity="revision",
        entity_id=rev.id,
        derived_id=derived.id,
        machine=posted.machine,
        machine_kind=posted.machine_kind,
        post=f"{posted.post_name} {posted.post_version}",
        tolerance_mm=posted.tolerance_mm,
        sha256=posted.sha256,
    )
    return derived


def derived_info(d: m.DerivedRevision) -> dict[str, Any]:
    return dict(
        id=d.id,
        source_revision_id=d.source_revision_id,
        machine_kind=d.machine_kind,
        machine=d.machine,
        post_name=d.post_name,
        post_version=d.post_version,
        tolerance_mm=d.tolerance_mm,
        sha256=d.sha256,
        size=d.size,
        lines=d.lines,
        created_at=d.created_at,
    )
