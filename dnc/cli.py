"""`fmscell dnc ...`: the DNC host's program library from the command line."""

from __future__ import annotations

from pathlib import Path

import typer

dnc_app = typer.Typer(help="DNC host: program library and transfers.", no_args_is_help=True)

DB_OPTION = typer.Option(
    None,
    "--database-url",
    envvar="FMSCELL_DATABASE_URL",
    help="SQLAlchemy URL; default sqlite:///fmscell.db in the working directory.",
)


def _library(database_url: str | None):
    from dnc.checker import nc_checker
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
    database_url: str | None = DB_OPTION,
) -> None:
    """Import .nc/.ngc/.tap/.txt programs; each file becomes a new program or revision."""
    from dnc.errors import DncError

    lib = _library(database_url)
    failed = 0
    for file, outcome in lib.import_path(path, machine_kind=kind, author=author, tags=tag):
        if isinstance(outcome, Exception):
            failed += 1
            message = outcome.message if isinstance(outcome, DncError) else str(outcome)
            typer.echo(f"{file}: refused: {message}", err=True)
            continue
        check = "check ok" if outcome.check_ok else f"{len(outcome.check_errors)} check error(s)"
        typer.echo(f"{file}: program {outcome.program_id} revision {outcome.seq} ({check})")
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
