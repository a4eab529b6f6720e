"""`fmscell nc simulate FILE`: a part program on a complete simulated machine, in lockstep."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from cnc.cli import nc_app
from cnc.cli_setup import SETUP_ERRORS, fail, names_units, units_warning
from cnc.errors import NcError
from cnc.program_memory import MemoryFull

SETTLE_S = 1.0  # after the end: let the axes settle onto the last setpoint (bounded)


def simulate(
    text: str,
    config,
    name: str,
    *,
    ideal: bool = False,
    faults=(),
    trace=None,
    candump=None,
    controller_factory=None,
    max_s: float = 3600.0,
    machine_data=None,
) -> dict:
    """Home, cycle start, run to the end or to an alarm; the result as plain data.

    Raises `MemoryFull` (drip-feed suggested) and `FaultSpecError` before anything runs.
    """
    from cnc.machine import Machine  # deferred: the machine is not loaded for `fmscell --help`

    m = Machine(
        config,
        name,
        ideal=ideal,
        faults=faults,
        trace=trace,
        candump=candump,
        controller_factory=controller_factory,
        machine_data=machine_data,
    )
    try:
        number = m.load_program(text)
        # PLC ready and AxisEnable, the controller enables the drives
        m.run_until(lambda mm: mm.axes.feedback().enabled or mm.alarms, 2.0)
        m.step(2)  # the controller takes the enabled drives in its next cycle
        if not m.alarms:
            m.command("mode", mode="REF")
            m.command("home")
            m.run_until(lambda mm: _homed(mm) or mm.alarms, 120.0)
        if m.alarms:
            return _result(m, "alarm", 0.0, 0)
        m.command("mode", mode="AUTO")
        m.command("select_program", number=number)
        m.command("cycle_start")
        t0 = m.t
        lines: list[int] = []

        def done(mm) -> bool:
            if not lines or lines[-1] != mm.status.line:
                lines.append(mm.status.line)
            return (
                bool(mm.alarms)
                or mm.status.execution in ("PROGRAM_COMPLETED", "READY")
                and mm.t > t0 + 0.05
            )

        m.run_until(done, max_s)
        cycle_time = m.t - t0
        if not m.alarms:
            m.run_until(lambda mm: _settled(mm) or bool(mm.alarms), SETTLE_S)
        blocks = len([x for x in lines if x])
        result = (
            "alarm"
            if m.alarms
            else (
                "completed" if m.status.execution in ("PROGRAM_COMPLETED", "READY") else "timeout"
            )
        )
        return _result(m, result, cycle_time, blocks)
    finally:
        m.close()


def _homed(m) -> bool:
    return all(m.controller.referenced.values())


def _settled(m) -> bool:
    fb = m.axes.feedback()
    return all(
        abs(fb.actual.get(a, 0.0) - m.last_targets.get(a, 0.0)) < 0.005 for a in m.axis_names
    )


def _result(m, result: str, cycle_time: float, blocks: int) -> dict:
    fb = m.axes.feedback()
    load = m.axes.bus_load
    line_of = {e.data["number"]: e.data.get("line") for e in m.events.of_kind("alarm") if e.data}
    return {
        "result": result,
        "alarms": [
            {
                "number": a.number,
                "text": a.text,
                "source": a.source,
                "axis": a.axis,
                "line": line_of.get(a.number, m.status.line),
            }
            for a in m.alarms
        ],
        "cycle_time_s": round(cycle_time, 6),
        "final_position": {a: round(fb.actual.get(a, 0.0), 4) for a in m.axis_names},
        "max_following_error_mm": {a: round(v, 4) for a, v in m.max_following_error.items()},
        "max_contour_error_mm": round(m.max_contour_error, 4),
        "bus_load": {"mean": round(load.mean * 100, 2), "peak": round(load.peak * 100, 2)}
        if load is not None
        else {"mean": 0.0, "peak": 0.0},
        "blocks": blocks,
        **_tool_tip(m),
    }


def _tool_tip(m) -> dict:
    """mill5: the program's peak tool-tip deviation from the programmed straight line, of
    the interpolated joints and of the drives' actual joints (the servo lag added)."""
    tip = m.status.tool_tip
    if tip is None:
        return {}
    return {
        "tool_tip": {
            "peak_deviation_mm": round(tip.peak, 6),
            "actual_peak_deviation_mm": round(tip.actual_peak, 6),
        }
    }


def _config(machine: str, config_path: Path | None):
    # deferred: the configuration is not loaded for `fmscell --help` (start-up cost)
    from cnc.config import builtin_machine, load_machine_config

    if config_path is not None:
        return load_machine_config(config_path, machine)
    return builtin_machine(machine)


@nc_app.command("simulate")
def simulate_cmd(
    file: Path = typer.Argument(..., help="part program file"),
    machine: str = typer.Option(
        "mill3", "--machine", help="mill3, lathe2, mill4, mill5 or a machine in --config"
    ),
    config: Path | None = typer.Option(None, "--config", help="cell or machine YAML"),
    as_json: bool = typer.Option(True, "--json/--no-json", help="print one JSON object"),
    trace: Path | None = typer.Option(None, "--trace", help="CSV: t, commanded/actual per axis"),
    candump: Path | None = typer.Option(None, "--candump", help="CAN frames, candump log format"),
    fault: list[str] = typer.Option([], "--fault", help="fault spec target:kind@time (repeat)"),
    ideal: bool = typer.Option(False, "--ideal", help="ideal axes instead of CANopen drives"),
    tools: Path | None = typer.Option(None, "--tools", help="tool table file (CSV or .tbl)"),
    offsets: Path | None = typer.Option(None, "--offsets", help="work offsets file (CSV)"),
    units: str | None = typer.Option(None, "--units", help="power-on unit, inch or mm"),
) -> None:
    """Run FILE on a complete simulated machine in lockstep: home, cycle start, to the end or
    to an alarm. Prints one JSON object (result, alarms, cycle_time_s, final_position, ...)."""
    # deferred: the controller and the drives' bus (python-can) are not loaded for the rest
    # of `fmscell` (start-up cost)
    from cnc.controller import CommandRefused
    from cnc.machine.faults import FaultSpecError, parse_fault_spec
    from drives.bus.loadplan import BusOverloadError

    try:
        cfg = _config(machine, config)
    except (NcError, ValueError, KeyError, OSError) as err:
        typer.echo(f"{config or machine}: {err}", err=True)
        raise typer.Exit(2) from None
    md = None
    if tools is not None or offsets is not None or units is not None:
        try:
            md = _setup_of(cfg, tools, offsets, units)
        except SETUP_ERRORS as err:
            raise fail(err) from None
    try:
        specs = [parse_fault_spec(f, tuple(cfg.axes)) for f in fault]
    except FaultSpecError as err:
        typer.echo(f"--fault: {err}", err=True)
        raise typer.Exit(2) from None
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        typer.echo(f"{file}: cannot read: {err}", err=True)
        raise typer.Exit(2) from None
    if not names_units(text.splitlines()):
        unit = md.power_on_units if md is not None else _power_on_units(cfg)
        typer.echo(units_warning(str(file), unit), err=True)
    try:
        with _open(trace) as tr, _open(candump) as cd:
            out = simulate(
                text, cfg, machine, ideal=ideal, faults=specs, trace=tr, candump=cd,
                machine_data=md,
            )  # fmt: skip
    except MemoryFull as err:
        typer.echo(f"{file}: {err}", err=True)
        raise typer.Exit(2) from None
    except CommandRefused as err:
        typer.echo(f"fmscell nc simulate: the machine refused: {err}", err=True)
        raise typer.Exit(1) from None
    except BusOverloadError as err:
        typer.echo(f"{config or machine}: {err}", err=True)
        raise typer.Exit(2) from None
    except Exception as err:  # never a traceback for the user: say what broke, exit 3
        typer.echo(f"fmscell nc simulate: internal error: {type(err).__name__}: {err}", err=True)
        raise typer.Exit(3) from None
    except ImportError as err:
        typer.echo(f"fmscell nc simulate: {err}", err=True)
        raise typer.Exit(3) from None
    if as_json:
        typer.echo(json.dumps(out, sort_keys=True))
    else:
        for k, v in out.items():
            typer.echo(f"{k}: {v}")
    raise typer.Exit(0 if out["result"] == "completed" else 1)


def _setup_of(cfg, tools, offsets, units):
    """The machine data of a shipped machine with the command line's files taken in."""
    from cnc.machine_data import MachineData, apply_files  # deferred: as in cli_setup

    md = cfg.machine_data.initial() if cfg.machine_data is not None else MachineData()
    md = apply_files(md, tools, offsets)
    if units is not None:
        if units not in ("mm", "inch"):
            raise typer.BadParameter(f"must be inch or mm, not {units!r}", param_hint="--units")
        md.set_parameters(power_on_units=units)
    return md


def _power_on_units(cfg) -> str:
    return cfg.machine_data.power_on_units if cfg.machine_data is not None else "mm"


class _open:
    """A text file for writing, or nothing."""

    def __init__(self, path: Path | None) -> None:
        self.path, self.f = path, None

    def __enter__(self):
        if self.path is not None:
            self.f = open(self.path, "w", encoding="ascii", newline="\n")  # noqa: SIM115
        return self.f

    def __exit__(self, *exc) -> None:
        if self.f is not None:
            self.f.close()
