"""`fmscell nc plan FILE`: interpreter -> planner -> interpolator on ideal axes.

Prints one JSON object with the run's figures (docs/motion.md lists the keys). The core
is `plan_run`, which takes canonical commands and needs no interpreter, so the machine
and the tests can use it too.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import typer

from cnc.canon import MOTION_TYPES, Dwell, SkipFeed, StraightTraverse
from cnc.cli import nc_app, skip_warnings
from cnc.cli_setup import SETUP_ERRORS, fail, machine_setup, units_warning
from cnc.errors import NcError
from cnc.interp import Interpreter

AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}
INCH_MM = 25.4


class _Deviation:
    """Distance of each sample from the programmed (unblended) path.

    Motion blocks are numbered in push order as the planner numbers them, so a sample
    of block k is compared with the programmed moves k-1, k and k+1 (a G64 blend belongs
    to block k and deviates from k and k+1). Moves behind are dropped: memory stays
    bounded by the look-ahead.
    """

    def __init__(self) -> None:
        self.pieces: dict[int, object] = {}
        self.count = 0
        self.low = 1
        self.worst = 0.0

    def add(self, piece) -> None:
        self.count += 1
        self.pieces[self.count] = piece

    def sample(self, pose, block: int) -> None:
        # deferred: the planner (compiled) is not loaded for the rest of `fmscell`
        from cnc.planner.geometry import distance_to_piece

        if block <= 0:
            return
        best = math.inf
        for k in (block - 1, block, block + 1):
            g = self.pieces.get(k)
            if g is not None:
                d = distance_to_piece(pose, g)
                if d < best:
                    best = d
        if best != math.inf and best > self.worst:
            self.worst = best
        while self.low < block - 1:
            self.pieces.pop(self.low, None)
            self.low += 1


def _skips_planned(commands: Iterable) -> Iterator:
    """Without a machine no skip signal comes: a G31 runs to where the interpreter expects
    the tool setter to switch (canon.SkipFeed.planned), as it assumed for the blocks after."""
    for cmd in commands:
        yield cmd.planned() if type(cmd) is SkipFeed else cmd


def plan_run(
    params,
    commands: Iterable,
    start: tuple[float, ...],
    ipo: float | None = None,
    on_sample: Callable | None = None,
    max_cycles: int = 50_000_000,
) -> dict:
    """Run canonical commands through Motion on ideal axes; return the plan figures.

    Dwell sync points hold for their time; every other sync point is acknowledged at
    once (ideal PLC). `on_sample(sample)` sees every IPO sample.
    """
    # deferred: the planner and interpolator (compiled) are not loaded for the rest of
    # `fmscell` (start-up cost)
    from cnc.interpolator import Motion
    from cnc.interpolator.motion import Peaks
    from cnc.planner.geometry import Line, arc_from_canon

    motion = Motion(params, start=start, ipo_cycle_s=ipo)
    t = motion.ipo
    names = [a.name for a in params.axes if a.name in AXIS_INDEX]
    idx = [AXIS_INDEX[n] for n in names]
    dev = _Deviation()  # sampled deviation: only with a trace (on_sample)
    blocks = moves = 0
    last_line = None
    feed_len = rapid_len = 0.0
    pos = tuple(start[:3])  # the X Y Z path (rotary axes: docs/motion.md)
    it = iter(_skips_planned(commands))
    pending = next(it, None)
    fed_all = pending is None
    if fed_all:
        motion.end_of_program()
    cycles = 0
    dwell_left = 0
    last = None

    def take(cmd) -> None:
        nonlocal blocks, moves, last_line, feed_len, rapid_len, pos
        if cmd.line != last_line:
            blocks += 1
            last_line = cmd.line
        if isinstance(cmd, MOTION_TYPES):
            moves += 1
            end = tuple(float(x) for x in cmd.end[:3])
            if end != pos or getattr(cmd, "center", None) is not None:
                if hasattr(cmd, "center"):
                    piece = arc_from_canon(
                        pos, end, cmd.center[:3], cmd.plane.value, cmd.clockwise, cmd.turns
                    )
                else:
                    piece = Line(pos, end)
                if piece.length > 1e-12:  # the planner drops shorter moves too
                    if on_sample is not None:
                        dev.add(piece)
                    if isinstance(cmd, StraightTraverse):
                        rapid_len += piece.length
                    else:
                        feed_len += piece.length
            pos = end

    peaks = Peaks((start[0], start[1], start[2]), t)
    while True:
        while pending is not None and motion.push(pending):
            take(pending)
            pending = next(it, None)
        if pending is None and not fed_all:
            motion.end_of_program()
            fed_all = True
        if dwell_left > 0:
            dwell_left -= 1
            if dwell_left == 0:
                motion.acknowledge()
        if on_sample is None and dwell_left == 0:
            # no trace asked: the interpolator steps on by itself (compiled: no Python
            # per cycle) until a sync point, room for the next block, or idle
            s = motion.run(max_cycles + 1 - cycles, peaks, pending is not None)
            cycles += motion.run_cycles
        else:
            s = motion.step()
            cycles += 1
            peaks.add(s.pose[:3])
            if on_sample is not None:
                dev.sample(s.pose, motion.block)
                on_sample(s)
        if cycles > max_cycles:
            raise NcError(f"plan did not finish within {max_cycles} IPO cycles")
        last = s
        if s.sync is not None:
            if isinstance(s.sync, Dwell) and s.sync.seconds > 0:
                dwell_left = max(1, math.ceil(s.sync.seconds / t - 1e-9))
            else:
                motion.acknowledge()
        if fed_all and motion.idle and dwell_left == 0:
            break
    vmax, amax, jmax = list(peaks.vmax), list(peaks.amax), list(peaks.jmax)

    def per_axis(vals) -> dict[str, float]:
        return {nm: vals[i] for nm, i in zip(names, idx, strict=True)}

    ratios = limit_ratios(params, vmax, amax, jmax, names, idx)
    return {
        "blocks": blocks,
        "moves": moves,
        "cycle_time_s": cycles * t,
        "ipo_cycle_s": t,
        "path_length_mm": feed_len,
        "rapid_length_mm": rapid_len,
        "final_position": per_axis(last.pose if last else start),
        "max_abs_velocity": per_axis(vmax),
        "max_abs_accel": per_axis(amax),
        "max_abs_jerk": per_axis(jmax),
        # exact, from the blends (the only departure from the programmed path); with a
        # trace also as measured on the samples
        "max_path_deviation_mm": motion.path.max_blend_deviation,
        **({"sampled_path_deviation_mm": dev.worst} if on_sample is not None else {}),
        "limit_ratio": ratios,
        "worst_limit_ratio": max((r for ax in ratios.values() for r in ax.values()), default=0.0),
        "replans": motion.replans,
        "units": {"velocity": "mm/s", "accel": "mm/s^2", "jerk": "mm/s^3"},
    }


def limit_ratios(params, vmax, amax, jmax, names, idx) -> dict[str, dict[str, float]]:
    """Per axis, each maximum over the axis's limit: {"X": {"v": .., "a": .., "j": ..}}.

    The planner's claim (docs/motion.md, Limits) is that every ratio is <= 1 up to float
    rounding; a run that shows more has found a planner bug.
    """
    out: dict[str, dict[str, float]] = {}
    for nm, i in zip(names, idx, strict=True):
        ax = params.axis(nm)
        out[nm] = {
            "v": vmax[i] / (ax.max_velocity / 60.0) if ax.max_velocity > 0 else math.inf,
            "a": amax[i] / ax.max_accel if ax.max_accel > 0 else math.inf,
            "j": jmax[i] / ax.max_jerk if ax.max_jerk > 0 else math.inf,
        }
    return out


@nc_app.command("plan")
def plan_cmd(
    file: Path = typer.Argument(..., help="part program"),
    config: Path | None = typer.Option(None, "--config", help="machine YAML (overrides --kind)"),
    kind: str = typer.Option("mill", "--kind", help="shipped machine: mill (mill3) or lathe"),
    tools: Path | None = typer.Option(None, "--tools", help="tool table file (CSV or .tbl)"),
    offsets: Path | None = typer.Option(None, "--offsets", help="work offsets file (CSV)"),
    g54: str = typer.Option("", "--g54", help="G54 'X,Y,Z' in mm (default: the machine's)"),
    units: str | None = typer.Option(None, "--units", help="power-on unit, inch or mm"),
    soft_limits: bool = typer.Option(
        True, "--soft-limits/--no-soft-limits", help="check moves against the axis travel"
    ),
    ipo_ms: float = typer.Option(None, "--ipo-ms", help="IPO cycle in ms (default: machine's)"),
    trace: Path | None = typer.Option(None, "--trace", help="write one CSV row per IPO sample"),
    as_json: bool = typer.Option(False, "--json", help="compact one-line JSON"),
) -> None:
    """Plan and interpolate FILE on ideal axes; print one JSON object with the figures."""
    try:
        setup = machine_setup(
            kind=kind, config=config, tools=tools, offsets=offsets, units=units, g54=g54,
            soft_limits=soft_limits,
        )  # fmt: skip
    except SETUP_ERRORS as err:
        raise fail(err) from None
    params = setup.params
    try:
        try:
            # streamed line by line: memory does not grow with the program's size
            fh = open(file, encoding="latin-1", newline=None)  # noqa: SIM115 - closed below
        except OSError as e:
            raise NcError(f"cannot read program: {e.strerror}", file=str(file)) from e
        interp = Interpreter(params, file=str(file), machine_data=setup.machine_data)
        # X Y Z, then the rotary axes at their reference angle (where the interpreter
        # starts them too)
        start = tuple(interp.state.machine_position) + tuple(a.home_mm for a in params.rotary_axes)
        names = [a.name for a in params.axes if a.name in AXIS_INDEX]
        out = trace.open("w", encoding="ascii", newline="") if trace else None
        try:
            on_sample = None
            if out is not None:
                out.write("t," + ",".join(names) + ",line\n")
                cols = [AXIS_INDEX[nm] for nm in names]

                def on_sample(s):
                    out.write(
                        f"{s.t!r}," + ",".join(repr(s.pose[i]) for i in cols) + f",{s.line}\n"
                    )

            ipo = None if ipo_ms is None else ipo_ms / 1000.0
            report = plan_run(params, interp.run(fh), start, ipo, on_sample)
        finally:
            fh.close()
            if out is not None:
                out.close()
        st = interp.state
        scale = INCH_MM if st.units == "inch" else 1.0
        report["final_work_position"] = {
            nm: st.work_position[AXIS_INDEX[nm]] * scale for nm in names
        }
    except NcError as e:
        if not e.file or e.file == "<program>":
            e.file = str(file)
        print(str(e), file=sys.stderr)
        raise typer.Exit(1) from None
    for w in skip_warnings(interp, params):
        print(w, file=sys.stderr)
    if not interp.units_programmed:
        print(units_warning(str(file), setup.machine_data.power_on_units), file=sys.stderr)
    if as_json:
        print(json.dumps(report, separators=(",", ":")))
    else:
        print(json.dumps(report, indent=2))
