"""`fmscell nc ...`: the NC kernel's command line."""

from __future__ import annotations

from pathlib import Path

import typer

nc_app = typer.Typer(
    help="NC kernel: check, plan and simulate part programs.", no_args_is_help=True
)


@nc_app.command("check")
def check_cmd(
    file: Path = typer.Argument(..., help="part program file (ISO 6983 / Fanuc)"),
    kind: str = typer.Option("mill", help="machine kind: mill or lathe"),
    config: Path | None = typer.Option(
        None, "--config", help="machine YAML (cnc.config); overrides --kind and --decimal"
    ),
    decimal: str = typer.Option(
        "calculator", help="numbers without a decimal point: calculator or least_increment"
    ),
    block_delete: bool = typer.Option(False, "--block-delete", help="skip '/' blocks"),
    g54: str = typer.Option(
        "", "--g54", help="G54 work offset 'X,Y,Z' in mm, machine coordinates (default 0,0,0)"
    ),
    soft_limits: bool = typer.Option(
        True, "--soft-limits/--no-soft-limits", help="check moves against the axis travel"
    ),
    library: Path | None = typer.Option(
        None,
        "--library",
        help="folder of programs that M98 P / G65 P / G66 P call, found by their O number",
    ),
) -> None:
    """Check a part program: exit 0 when valid, else one `FILE:LINE:COL: message` per error.

    A program whose last block is M99 is checked as a subprogram (its M99 ends it).
    """
    from cnc.interp import check
    from cnc.params import DecimalStyle, MachineParams

    if kind not in ("mill", "lathe"):
        typer.echo(f"--kind must be mill or lathe, not {kind!r}", err=True)
        raise typer.Exit(2)
    try:
        style = DecimalStyle(decimal)
    except ValueError:
        typer.echo(f"--decimal must be calculator or least_increment, not {decimal!r}", err=True)
        raise typer.Exit(2) from None
    params = MachineParams(kind=kind, decimal_style=style)
    if config is not None:
        from cnc.config import load_machine_params
        from cnc.errors import NcError

        try:
            params = load_machine_params(config)
        except NcError as err:
            typer.echo(str(err), err=True)
            raise typer.Exit(2) from None
    elif kind == "lathe":
        from cnc.params import AxisParams

        x, _, z = params.axes
        params = MachineParams(
            kind="lathe",
            axes=(AxisParams("X", -5.0, 300.0, x.max_velocity, x.max_accel, x.max_jerk),
                  AxisParams("Z", -600.0, 300.0, z.max_velocity, z.max_accel, z.max_jerk)),
            decimal_style=style,
        )  # fmt: skip
    offsets = None
    if g54:
        try:
            xyz = tuple(float(v) for v in g54.split(","))
            assert len(xyz) == 3
        except (ValueError, AssertionError):
            typer.echo(f"--g54 must be 'X,Y,Z' in mm, not {g54!r}", err=True)
            raise typer.Exit(2) from None
        offsets = {1: xyz}
    if not soft_limits:
        from dataclasses import replace

        big = 1e9
        params = replace(
            params, axes=tuple(replace(a, min_mm=-big, max_mm=big) for a in params.axes)
        )
    programs = None
    if library is not None:
        from cnc.gcode.source import library_programs

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
    with fh:
        errors = check(
            fh,
            params,
            file=str(file),
            block_delete=block_delete,
            work_offsets=offsets,
            programs=programs,
        )
    for e in errors:
        typer.echo(str(e))
    raise typer.Exit(1 if errors else 0)


# `nc plan` lives in cnc.cli_plan and registers itself on nc_app when imported.
from cnc import cli_plan as _cli_plan  # noqa: E402,F401

# `nc simulate` lives in cnc.cli_simulate and registers itself on nc_app when imported.
from cnc import cli_simulate as _cli_simulate  # noqa: E402,F401
