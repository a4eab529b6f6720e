"""`fmscell nc ...`: the NC kernel's command line."""

from __future__ import annotations

import re
from pathlib import Path

import typer

from cnc.cli_setup import SETUP_ERRORS, fail, machine_setup, units_warning
from cnc.gcode.source import library_programs
from cnc.interp import Interpreter
from cnc.interp.macro import ARGUMENTS

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
    subprogram: bool | None = typer.Option(
        None,
        "--subprogram/--main-program",
        help="check as a subprogram (its M99 returns to a caller) or as a main program"
        " (default: a subprogram when its last block is M99)",
    ),
    g65: str | None = typer.Option(
        None,
        "--g65",
        help="check a macro as `G65 P... ARGS` runs it: 'A.125 C.625 V10100.' sets #1 #3 #22"
        " (argument specification I); implies --subprogram",
    ),
) -> None:
    """Check a part program: exit 0 when valid, else one `FILE:LINE:COL: message` per error.

    A program whose last block is M99 is checked as a subprogram (its M99 ends it, and
    feed moves before its first F take the caller's feed).
    """
    args: dict[int, float] = {}
    if g65 is not None:
        try:
            args = g65_arguments(g65)
        except ValueError as err:
            typer.echo(f"--g65 {g65!r}: {err}", err=True)
            raise typer.Exit(2) from None
        subprogram = True

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
        # the kept variables a setter preset (machine_data.macro_variables in the YAML)
        macro_variables=setup.machine_data.macro_variables,
        max_blocks=CHECK_MAX_BLOCKS,
        programs=programs,
        subprogram=subprogram,  # None: decided by the program's last block (M99: a subprogram)
    )
    interp.vars.loc.update(args)  # the locals a G65 call would set
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
    for w in skip_warnings(interp, setup.params):
        typer.echo(w, err=True)
    for f, line in interp.upward_holes:
        typer.echo(
            f"{f}:{line}:1: warning: canned cycle with the hole bottom above R: it feeds "
            "upward from R (a Fanuc runs it; a sign slip?)",
            err=True,
        )
    if not interp.units_programmed:
        typer.echo(units_warning(str(file), setup.machine_data.power_on_units), err=True)
    raise typer.Exit(1 if errors else 0)


def skip_warnings(interp, params) -> list[str]:
    """One warning per G31 line that ran to its end point without a skip signal."""
    why = (
        "no tool setter on this machine (probe.tool_setter)"
        if params.tool_setter is None
        else "the tool does not meet the tool setter on its path"
    )
    seen = dict.fromkeys(interp.skip_misses)
    return [
        f"{f}:{line}:1: warning: G31 never tripped: {why}; it ran to its end point"
        for f, line in seen
    ]


CHECK_MAX_BLOCKS = 5_000_000
_ARGUMENT = re.compile(r"\s*([A-Z])\s*([-+]?(?:\d+\.?\d*|\.\d+))\s*", re.IGNORECASE)


def g65_arguments(text: str) -> dict[int, float]:
    """The local variables `G65 P... <text>` sets (argument specification I: A -> #1,
    B -> #2, ..., Z -> #26); a letter G65 cannot pass (G L N O P) or a repeated one is an
    error, as on the control."""
    out: dict[int, float] = {}
    pos = 0
    while pos < len(text):
        m = _ARGUMENT.match(text, pos)
        if m is None or m.end() == pos:
            raise ValueError(f"column {pos + 1}: expected an address and a number (A.125)")
        letter = m.group(1).upper()
        if letter not in ARGUMENTS:
            raise ValueError(f"column {pos + 1}: {letter} is not a G65 argument address")
        if ARGUMENTS[letter] in out:
            raise ValueError(f"column {pos + 1}: {letter} given twice")
        out[ARGUMENTS[letter]] = float(m.group(2))
        pos = m.end()
    return out


# `nc plan` lives in cnc.cli_plan and registers itself on nc_app when imported.
from cnc import cli_plan as _cli_plan  # noqa: E402,F401

# `nc simulate` lives in cnc.cli_simulate and registers itself on nc_app when imported.
from cnc import cli_simulate as _cli_simulate  # noqa: E402,F401
