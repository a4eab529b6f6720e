"""The `fmscell` command line. Each package contributes its own sub-command group."""

from __future__ import annotations

from pathlib import Path

import typer

from cam.cli import cam_app
from cnc.cli import nc_app
from cnc.cli_machine import machine as machine_command
from dnc.cli import dnc_app
from drives.cli import drives_app
from plc.cli import plc_app
from server.factory import factory as factory_command

app = typer.Typer(
    name="fmscell",
    help="fmscell: a flexible manufacturing cell (DNC host, CNC machines, CANopen drives, soft-PLC).",
    no_args_is_help=True,
    add_completion=False,
)
app.add_typer(nc_app, name="nc")
app.add_typer(plc_app, name="plc")
app.add_typer(drives_app, name="drives")
app.add_typer(dnc_app, name="dnc")
app.add_typer(cam_app, name="cam")


@app.command()
def run(
    config: Path | None = typer.Option(None, "--config", help="cell YAML (default: built-in cell)"),
    clock: str = typer.Option("realtime", "--clock", help="realtime | fast"),
    processes: bool = typer.Option(
        False, "--processes", help="machines as `fmscell machine` subprocesses"
    ),
    host: str = typer.Option(None, "--host", help="REST/dashboard bind address"),
    port: int = typer.Option(None, "--port", help="REST/dashboard TCP port"),
    insecure_open: bool = typer.Option(
        False, "--insecure-open", help="demo: no API key needed, every caller is an admin"
    ),
    faults: bool = typer.Option(False, "--faults", help="enable fault injection"),
    ideal_axes: bool = typer.Option(
        False, "--ideal-axes", help="ideal axes instead of CiA 402 drives (faster, no CAN)"
    ),
    database_url: str | None = typer.Option(
        None, "--database-url", help="SQLAlchemy URL (default FMSCELL_DATABASE_URL or SQLite)"
    ),
    attach: bool = typer.Option(
        False, "--attach", help="machines run elsewhere: connect to their configured faces"
    ),
) -> None:
    """Start the cell: DNC host, the configured machines and the REST API, until SIGINT or
    SIGTERM."""
    # deferred: the cell brings the web stack, SQLAlchemy and the machines, for this
    # sub-command only (start-up cost of every other `fmscell` command)
    from server.cell import run_cell

    raise typer.Exit(
        run_cell(
            config=config,
            clock=clock,
            processes=processes,
            host=host,
            port=port,
            insecure_open=insecure_open,
            faults=faults,
            ideal_axes=ideal_axes,
            database_url=database_url,
            attach=attach,
        )
    )


app.command("machine")(machine_command)
app.command("factory")(factory_command)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
