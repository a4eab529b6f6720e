"""`fmscell nc ...`: the NC kernel's command line."""

from __future__ import annotations

from pathlib import Path

import typer

from cnc.cli_setup import SETUP_ERRORS, fail, machine_setup, units_warning
from cnc.gcode.source import library_programs
from cnc.interp import Interpreter

nc_app = typer.Typer(
    help="NC kernel: check, plan and simulate part programs.", no_args_is_help=True
)


@nc_app.command("check")
def check_cmd(
    file: Path = typer.Argument(..., help="part program file (ISO 6983 / Fanuc)"),
    kind: str = typer.Option("mill", help="machine kind: mill (mill3) or lathe (lathe2)"),
    config: Path | None = typer.Option(
        None,
        "--config",
        help="machine YAML (cnc.config) or a shipped machine (mill3, lathe2, mill4, mill5);"
        " overrides --kind",
    ),
    decimal: str | None = typer.Option(
        None,
        help="numbers without a decimal point: calculator or least_increment"
        " (default: the machine's)",
    ),
    block_delete: bool = typer.Option(False, "--block-delete", help="skip '/' blocks"),
    g54: str = typer.Option(
        "",
        "--g54",
        help="G54 work offset 'X,Y,Z' in mm, machine coordinates (default: the machine's setup)",
    ),
    tools: Path | None = typer.Option(None, "--tools", help="tool table file (CSV or .tbl)"),
    offsets: Path | None = typer.Option(None, "--offsets", help="work offsets file (CSV)"),
    units: str | None = typer.Option(
        None, "--units", help="power-on unit, inch or mm (default: the machine's)"
    ),
    soft_limits: bool = typer.Option(
        True, "--soft-limits/--no-soft-limits", help="check moves against the axis travel"
    ),
    library: Path | None = typer.Option(
        None,
        "--library",
        help="folder of programs that M98 P / G65 P / G66 P call, found by their O number",
    ),
    gcode_system: str | None = typer.Option(
        None, "--gcode-system", help="lathe G-code system A, B or C (default: the machine's)"
    ),
) -> None:
    """Check a part program: exit 0 when valid, else one `FILE:LINE:COL: message` per error.

    A program whose last block is M99 is checked as a subprogram (its M99 ends it, and
    feed moves before its first F take the caller's feed).
    """
    try:
        setup = machine_setup(
            kind=kind, config=config, tools=tools, offsets=offsets, units=units, g54=g54,
            decimal=decimal, soft_limits=soft_limits, gcode_system=gcode_system,
        )  # fmt: skip
    except SETUP_ERRORS as err:
        raise fail(err) from None
    programs = None
    if library is not None:
        if not library.is_dir():
            typer.echo(f"--library {library}: not a folder", err=True)
            raise typer.Exit(2)
        programs, warnings = library_programs(str(library))
        for w in warnings:
            typer.echo(w, err=True)
    try:
        fh = open(file, encoding="latin-1", newline=None)  # noqa: SIM115 - closed below
    except OSError as err:
        typer.echo(f"{file}:0:0: cannot read: {err.strerror}", err=True)
        raise typer.Exit(1) from None
    interp = Interpreter(
        setup.params,
        file=str(file),
        block_delete=block_delete,
        machine_data=setup.machine_data,
        max_blocks=CHECK_MAX_BLOCKS,
        programs=programs,
        subprogram=None,  # decided by the program's last block (M99: a subprogram)
    )
    with fh:
        errors = interp.check_all(fh)
    for e in errors:
        typer.echo(str(e))
    if interp.caller_feed_line is not None:
        typer.echo(
            f"{file}:{interp.caller_feed_line}:1: warning: checked as a subprogram: feed moves "
            "before its first F take the caller's feed",
            err=True,
        )
    if not interp.units_programmed:
        typer.echo(units_warning(str(file), setup.machine_data.power_on_units), err=True)
    raise typer.Exit(1 if errors else 0)


CHECK_MAX_BLOCKS = 5_000_000


# `nc plan` lives in cnc.cli_plan and registers itself on nc_app when imported.
from cnc import cli_plan as _cli_plan  # noqa: E402,F401

# `nc simulate` lives in cnc.cli_simulate and registers itself on nc_app when imported.
from cnc import cli_simulate as _cli_simulate  # noqa: E402,F401
