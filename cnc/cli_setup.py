"""The machine setup `nc check`, `nc plan` and `nc simulate` run a program with.

A program runs on a machine (the shipped mill3 / lathe2 by `--kind`, or `--config`) with
that machine's setup from its YAML `machine_data` section: work offsets (G54 at the table
centre or the chuck face), tool offsets and the power-on unit. `--tools FILE` replaces the
tool table, `--offsets FILE` the work offsets it names, `--g54 X,Y,Z` sets G54 and
`--units inch|mm` the power-on unit (docs/machine_data.md, "Files").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import typer

from cnc.errors import NcError
from cnc.gcode.lexer import parse_line
from cnc.params import DecimalStyle

KIND_MACHINE = {"mill": "mill3", "lathe": "lathe2"}
NO_LIMIT_MM = 1e9


@dataclass
class Setup:
    config: Any  # cnc.config.MachineConfig
    params: Any  # cnc.params.MachineParams
    machine_data: Any  # cnc.machine_data.MachineData


def machine_setup(
    *,
    kind: str = "mill",
    config: Path | None = None,
    name: str | None = None,
    tools: Path | None = None,
    offsets: Path | None = None,
    units: str | None = None,
    g54: str = "",
    decimal: str | None = None,
    soft_limits: bool = True,
    gcode_system: str | None = None,
) -> Setup:
    """The setup from the command line's options; raises NcError (file:line:col) or
    typer.BadParameter for a bad option."""
    # deferred: the configuration (pydantic models, the PLC's M-code table) and the
    # machine-data store are not loaded for `fmscell --help` (start-up cost)
    from cnc.config import SHIPPED_MACHINES, builtin_machine, load_machine_config
    from cnc.machine_data import MachineData, apply_files

    if config is not None and str(config) in SHIPPED_MACHINES and not config.exists():
        cfg = builtin_machine(str(config))  # `--config mill4`: a shipped machine by name
    elif config is not None:
        cfg = load_machine_config(config, name)
    else:
        if kind not in KIND_MACHINE:
            raise typer.BadParameter(f"must be mill or lathe, not {kind!r}", param_hint="--kind")
        cfg = builtin_machine(KIND_MACHINE[kind])
    params = cfg.params
    if decimal is not None:
        try:
            params = replace(params, decimal_style=DecimalStyle(decimal))
        except ValueError:
            raise typer.BadParameter(
                f"must be calculator or least_increment, not {decimal!r}", param_hint="--decimal"
            ) from None
    if gcode_system is not None:
        if params.kind != "lathe" or gcode_system not in ("A", "B", "C"):
            raise typer.BadParameter(
                f"a lathe's Fanuc G-code system is A, B or C, not {gcode_system!r}"
                + ("" if params.kind == "lathe" else " (and the machine is not a lathe)"),
                param_hint="--gcode-system",
            )
        params = replace(params, lathe_gcode_system=gcode_system)
    if not soft_limits:
        params = replace(
            params,
            axes=tuple(replace(a, min_mm=-NO_LIMIT_MM, max_mm=NO_LIMIT_MM) for a in params.axes),
        )
    section = cfg.machine_data
    md = section.initial() if section is not None else MachineData()
    md = apply_files(md, tools, offsets)
    if g54:
        try:
            xyz = tuple(float(v) for v in g54.split(","))
            if len(xyz) != 3:
                raise ValueError
        except ValueError:
            raise typer.BadParameter(
                f"must be 'X,Y,Z' in mm, not {g54!r}", param_hint="--g54"
            ) from None
        md.set_work_offset(1, xyz)
    if units is not None:
        if units not in ("mm", "inch"):
            raise typer.BadParameter(f"must be inch or mm, not {units!r}", param_hint="--units")
        md.set_parameters(power_on_units=units)
    return Setup(cfg, params, md)


def units_warning(file: str, units: str) -> str:
    """The warning for a program that never says G20 or G21."""
    other = "inch" if units == "mm" else "mm"
    return (
        f"{file}: warning: no G20/G21 in the program: read in {units}, the power-on unit"
        f" (--units {other} if it is written in {other})"
    )


def names_units(lines) -> bool:
    """Whether a program text says G20 or G21 anywhere (lexed, comments ignored)."""
    for n, line in enumerate(lines, 1):
        if "20" not in line and "21" not in line:
            continue
        try:
            blk = parse_line(line, n)
        except NcError:
            continue
        if blk is not None and any(g in (200, 210) for g in blk.g):
            return True
    return False


def fail(err: Exception, file: Path | str | None = None) -> typer.Exit:
    """Print a setup error as one line (or one per bad row) and give the exit to raise."""
    if isinstance(err, typer.BadParameter):
        typer.echo(f"{err.param_hint}: {err.message}", err=True)
    else:
        typer.echo(str(err), err=True)
    return typer.Exit(2)


SETUP_ERRORS = (NcError, typer.BadParameter, ValueError, OSError)
