"""`fmscell dnc ...`: the DNC host's program library from the command line."""

from __future__ import annotations

from pathlib import Path

import typer

from cnc.errors import NcError
from dnc.checker import nc_checker
from dnc.errors import DncError
from dnc.tape import MAX_PROGRAM_NUMBER
from dnc.transfer import TransferError

dnc_app = typer.Typer(help="DNC host: program library and transfers.", no_args_is_help=True)

DB_OPTION = typer.Option(
    None,
    "--database-url",
    envvar="FMSCELL_DATABASE_URL",
    help="SQLAlchemy URL; default sqlite:///fmscell.db in the working directory.",
)


SECRET_OPTION = typer.Option(
    None,
    "--secret",
    envvar="FMSCELL_DNC_SECRET",
    help="The machine's DNC port secret (ports.secret); better given in FMSCELL_DNC_SECRET,"
    " which other users' `ps` does not show.",
)


def _library(database_url: str | None):
    # deferred: SQLAlchemy and the library's models are not loaded for the rest of `fmscell`
    from dnc.db import make_engine, migrate, session_factory
    from dnc.library import Library

    engine = make_engine(database_url)
    migrate(engine)
    return Library(session_factory(engine), checker=nc_checker)


@dnc_app.command("import")
def import_(
    path: Path = typer.Argument(..., exists=True, help="A program file or a directory of them."),
    kind: str = typer.Option("mill", help="Machine kind the programs are for (mill, lathe)."),
    tag: list[str] = typer.Option([], help="Tag to put on newly created programs (repeatable)."),
    author: str = typer.Option("import", help="Recorded as the revisions' author."),
    post_kind: list[str] = typer.Option(
        [],
        "--post-kind",
        help="APT/CL files: a machine kind they are posted for at dispatch (repeatable;"
        " default: the kind MACHIN/ names, else every kind registered).",
    ),
    database_url: str | None = DB_OPTION,
) -> None:
    """Import .nc/.ngc/.tap/.txt programs, and .apt (APT) and .cl/.cls (CL data) sources
    posted for each machine at dispatch; each file becomes a new program or revision."""
    lib = _library(database_url)
    failed = 0
    outcomes = lib.import_path(
        path, machine_kind=kind, author=author, tags=tag, post_kinds=post_kind
    )
    for file, outcome in outcomes:
        if isinstance(outcome, Exception):
            failed += 1
            message = outcome.message if isinstance(outcome, DncError) else str(outcome)
            typer.echo(f"{file}: refused: {message}", err=True)
            continue
        check = "check ok" if outcome.check_ok else f"{len(outcome.check_errors)} check error(s)"
        if outcome.kind != "gcode":
            check += f"; {outcome.kind}, posted for {', '.join(outcome.post_kinds)}"
        typer.echo(f"{file}: program {outcome.program_id} revision {outcome.seq} ({check})")
        if outcome.kind != "gcode":  # which kind's trial post failed, and where
            for err in outcome.check_errors[:5]:
                typer.echo(f"{file}:{err['line']}:{err['col']}: {err['message']}", err=True)
    raise typer.Exit(1 if failed else 0)


@dnc_app.command("list")
def list_(
    query: str | None = typer.Option(None, "--query", "-q", help="Name or O number."),
    tag: str | None = typer.Option(None, help="Only programs with this tag."),
    text: str | None = typer.Option(None, help="Only programs whose text contains this."),
    limit: int = typer.Option(50, min=1, max=500),
    database_url: str | None = DB_OPTION,
) -> None:
    """List programs with their released and latest revisions."""
    lib = _library(database_url)
    page = lib.search(query=query, tag=tag, text=text, limit=limit)
    for p in page.items:
        released = f"rev id {p.released_revision_id}" if p.released_revision_id else "none"
        tags = f" [{', '.join(p.tags)}]" if p.tags else ""
        typer.echo(f"O{p.number:04d}  {p.machine_kind:<6} {p.name}{tags}  released: {released}")
    if page.next_cursor:
        typer.echo("... more (narrow the search or raise --limit)")


def _program_number(text: str) -> int:
    digits = text.upper().removeprefix("O")
    if not digits.isdigit():
        raise typer.BadParameter(f"{text!r} is not a program number (O1234 or 1234)")
    if not 1 <= int(digits) <= MAX_PROGRAM_NUMBER:
        raise typer.BadParameter(f"{text!r} is outside O1..O{MAX_PROGRAM_NUMBER}")
    return int(digits)


@dnc_app.command("machine")
def machine(
    name: str = typer.Argument(..., help="Machine name, e.g. mill1."),
    kind: str = typer.Option(..., help="mill or lathe."),
    dnc: str = typer.Option(..., help="DNC port address host:port."),
    parity: bool = typer.Option(False, help="ISO 7-bit even parity on the DNC line."),
    memory: int = typer.Option(0, help="Program memory in bytes (for planning)."),
    database_url: str | None = DB_OPTION,
) -> None:
    """Register (or update) a machine in the host's registry."""
    lib = _library(database_url)
    lib.register_machine(
        name, kind, dnc_address=dnc, memory_bytes=memory, dnc_profile={"parity": parity}
    )
    typer.echo(f"machine {name} ({kind}) at {dnc}")


@dnc_app.command("send")
def send(
    program: str = typer.Argument(..., help="Program number, O1234 or 1234."),
    machine: str = typer.Option(..., "--machine", "-m", help="Registered machine name."),
    drip: bool = typer.Option(False, help="Drip-feed (BTR) instead of loading into memory."),
    database_url: str | None = DB_OPTION,
    secret: str | None = SECRET_OPTION,
) -> None:
    """Send the released revision of PROGRAM to a machine, verified by reading it back."""
    import uuid

    # deferred: SQLAlchemy, as in _library
    from dnc.db import make_engine, migrate, session_factory
    from dnc.dispatch import Dispatches
    from dnc.transfer_worker import RetryPolicy, TransferWorker, _default_client

    engine = make_engine(database_url)
    migrate(engine)
    sessions = session_factory(engine)
    lib = _library(database_url)
    try:
        kind = lib.machine(machine)["kind"]
        rev = lib.released_revision(_program_number(program), kind)
        info, _ = Dispatches(sessions).request(
            key=f"cli-{uuid.uuid4()}",
            revision_id=rev.id,
            machine=machine,
            mode="drip_feed" if drip else "memory",
            requested_by="cli",
        )
    except DncError as exc:
        typer.echo(f"refused: {exc.message}", err=True)
        raise typer.Exit(1) from None

    def client(host: str, port: int, profile: dict):
        return _default_client(host, port, {**profile, "secret": secret})

    state = TransferWorker(sessions, client_factory=client, retry=RetryPolicy(max_attempts=1)).run(
        info.id
    )
    done = Dispatches(sessions).get(info.id)
    if state != "done":
        typer.echo(f"dispatch {done.id} {state}: {done.error}", err=True)
        raise typer.Exit(1)
    check = "verified" if done.verified else "not verifiable (drip-feed)"
    deps = lib.dependencies(rev.id)
    brought = f" with {', '.join(f'O{d.number:04d}' for d in deps)}" if deps else ""
    typer.echo(
        f"dispatch {done.id}: revision {rev.id}{brought} sent to {machine}, {done.bytes_sent} "
        f"bytes, {check}"
    )


@dnc_app.command("calls")
def calls(
    program: str = typer.Argument(..., help="Program number, O1234 or 1234."),
    kind: str = typer.Option("mill", help="Machine kind of the program (mill, lathe)."),
    database_url: str | None = DB_OPTION,
) -> None:
    """The programs PROGRAM calls (M98 P, G65 P, G66 P) and the programs that call it.

    Exit 1 when a program it calls, directly or through another, has no released revision
    (a dispatch would be refused)."""
    from dnc.dependencies import MissingDependency  # deferred: SQLAlchemy, as in _library

    lib = _library(database_url)
    number = _program_number(program)
    page = lib.search(number=number, machine_kind=kind, limit=1)
    if not page.items:
        typer.echo(f"no O{number:04d} for {kind} machines", err=True)
        raise typer.Exit(1)
    prog = page.items[0]
    current = prog.released_revision_id or prog.latest_revision_id
    which = "released" if prog.released_revision_id else "newest, not released"
    typer.echo(f"O{number:04d} {prog.name} (revision id {current}, {which})")
    for c in lib.calls(current) if current is not None else []:
        where = (
            f"released revision id {c['released_revision_id']}"
            if c["released_revision_id"]
            else ("not released" if c["program_id"] else "not in the library")
        )
        typer.echo(f"  line {c['line']}: {c['code']} calls O{c['number']:04d} ({where})")
    for c in lib.called_by(prog.id):
        typer.echo(f"  called by O{c['number']:04d} {c['name']} line {c['line']} ({c['code']}, "
                   f"revision id {c['revision_id']}, {c['status']})")  # fmt: skip
    if current is None:
        return
    try:
        lib.dependencies(current)
    except MissingDependency as exc:
        typer.echo(f"not dispatchable: {exc.message}", err=True)
        raise typer.Exit(1) from None


@dnc_app.command("receive")
def receive(
    program: str = typer.Argument(..., help="Program number to punch from the machine."),
    machine: str = typer.Option(..., "--machine", "-m"),
    database_url: str | None = DB_OPTION,
    secret: str | None = SECRET_OPTION,
) -> None:
    """Upload a program from a machine; it is stored as a candidate (draft) revision."""
    from dnc.machine_link import upload_from_machine  # deferred: SQLAlchemy, as in _library

    lib = _library(database_url)
    try:
        rev = upload_from_machine(lib, machine, _program_number(program), secret=secret)
    except (DncError, TransferError) as exc:
        typer.echo(f"refused: {exc.message}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"program {rev.program_id} revision {rev.seq} ({rev.status}) from {machine}")


@dnc_app.command("tools")
def tools(
    machine: str = typer.Option(..., "--machine", "-m", help="Registered machine name."),
    send_file: Path | None = typer.Option(
        None, "--send", help="tool table to send: CSV, LinuxCNC .tbl or JSON (the table)"
    ),
    database_url: str | None = DB_OPTION,
    secret: str | None = SECRET_OPTION,
) -> None:
    """Print a machine's tool offset table (JSON), or send one to it first (--send)."""
    _machine_data(machine, "tools", send_file, database_url, secret)


@dnc_app.command("offsets")
def offsets(
    machine: str = typer.Option(..., "--machine", "-m", help="Registered machine name."),
    send_file: Path | None = typer.Option(
        None, "--send", help="work offsets to send: CSV offset,x,y,z or JSON"
    ),
    database_url: str | None = DB_OPTION,
    secret: str | None = SECRET_OPTION,
) -> None:
    """Print a machine's work offsets and G92 shift (JSON), or send offsets first (--send)."""
    _machine_data(machine, "offsets", send_file, database_url, secret)


def _machine_data(
    machine: str, what: str, send_file: Path | None, database_url, secret: str | None
) -> None:
    """The host's tool data to and from a machine over its DNC port (TOOLS / OFFSETS)."""
    import json

    from dnc.machine_link import client_for  # deferred: SQLAlchemy, as in _library

    doc = None
    if send_file is not None:
        try:
            doc = _data_file(what, send_file)
        except (NcError, OSError, ValueError) as exc:
            typer.echo(str(exc), err=True)
            raise typer.Exit(2) from None
    lib = _library(database_url)
    try:
        with client_for(lib, machine, secret=secret) as client:
            data = client.machine_data(what, doc)
    except (DncError, TransferError) as exc:
        typer.echo(f"refused: {exc.message}", err=True)
        raise typer.Exit(1) from None
    if doc is not None:
        lib.note_transfer(machine, f"machine.{what}_written", actor="cli", file=str(send_file))
    typer.echo(json.dumps(data, indent=1))


def _data_file(what: str, path: Path) -> object:
    import json

    # deferred: the machine-data store is not loaded for the rest of `fmscell`
    from cnc.machine_data import MachineData, load_offsets, load_tools

    if path.suffix.lower() == ".json":
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}:{exc.lineno}:{exc.colno}: not JSON: {exc.msg}") from None
    if what == "tools":
        return MachineData(load_tools(path)).tools_dict()
    ofs = load_offsets(path)
    g92 = ofs.pop("G92", None)
    doc: dict = {"work_offsets": {k: list(v) for k, v in ofs.items()}}
    if g92 is not None:
        doc["g92"] = list(g92)
    return doc
