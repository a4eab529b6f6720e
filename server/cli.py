"""The `fmscell` command line. Each package contributes its own sub-command group."""

from __future__ import annotations

import typer

from cnc.cli import nc_app
from dnc.cli import dnc_app
from drives.cli import drives_app
from plc.cli import plc_app

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


@app.command()
def run() -> None:
    """Start the default cell.

    The cell server (host, machines, REST API) is not built yet; until it is, this runs the
    NC kernel demo: a sample part program through interpreter, planner and interpolator.
    """
    from cnc.demo import run_demo

    raise typer.Exit(run_demo())


def main() -> None:
    app()


if __name__ == "__main__":
    main()
