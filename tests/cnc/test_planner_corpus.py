"""Real part programs never make the planner break an axis limit (issue 13, item 5).

Every corpus program (../shared/reference/corpus/gcode, read where it lies, never
copied) that the interpreter reads is planned on the shipped mill (or, when the mill
refuses it, the shipped lathe) with soft limits far away, so that only the planner is
under test; inch programs are read as inch (G20 in the program). The per-axis discrete
velocity, acceleration and jerk of every IPO sample (docs/motion.md, Limits) are
measured here, not taken from `nc plan`'s own summary, at look-ahead 200 (the shipped
depth) and 5 (where the window boundary bites most).

Bounded for the suite's time as plain Python: the first MOVES motion blocks of each
program and at most CYCLES IPO cycles of them (the corpus's long CAM programs reach
their dense short-block stretches within that). Tolerance: 1e-9 relative plus the float
rounding floor of the k-th difference of poses of size |p|, as in the property tests.
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
from pathlib import Path

import pytest

from cnc.canon import MOTION_TYPES
from cnc.cli_plan import plan_run
from cnc.config import load_machine_params
from cnc.errors import NcError
from tests.reference import GCODE_CORPUS, MISSING

ROOT = Path(__file__).resolve().parents[2]
MOVES = 400
CYCLES = 25_000
REL = 1e-9
EPS = sys.float_info.epsilon
MIN_PLANNED = 10  # the corpus holds more than this many programs the kernel reads


class _Enough(Exception):
    """Raised from the sample callback after CYCLES samples."""


def _wide(name: str, lookahead: int):
    params = load_machine_params(ROOT / "cnc" / "machines" / f"{name}.yaml")
    axes = tuple(dataclasses.replace(a, min_mm=-1e5, max_mm=1e5) for a in params.axes)
    return dataclasses.replace(params, axes=axes, lookahead=lookahead, second_reference_mm=None)


def _first_moves(cmds, n):
    k = 0
    for c in cmds:
        if isinstance(c, MOTION_TYPES):
            k += 1
            if k > n:
                return
        yield c


class _Peaks:
    """Worst |v|, |a|, |j| over limit per axis, from the samples (discrete definition)."""

    def __init__(self, params, start) -> None:
        self.t = params.ipo_cycle_s
        self.lim = [
            (a.max_velocity / 60.0, a.max_accel, a.max_jerk) for a in params.axes if a.name in "XYZ"
        ]
        self.idx = ["XYZ".index(a.name) for a in params.axes if a.name in "XYZ"]
        self.p = list(start)
        self.v = [0.0] * 3
        self.a = [0.0] * 3
        self.worst = 0.0
        self.where = None
        self.n = 0
        self.scale = max(abs(x) for x in start)

    def __call__(self, s) -> None:
        t = self.t
        for k, i in enumerate(self.idx):
            x = s.pose[i]
            v = (x - self.p[i]) / t
            a = (v - self.v[i]) / t
            j = (a - self.a[i]) / t
            self.p[i], self.v[i], self.a[i] = x, v, a
            if abs(x) > self.scale:
                self.scale = abs(x)
            floor = self.scale * EPS
            lv, la, lj = self.lim[k]
            for q, (val, lim, fl) in enumerate(
                ((v, lv, 2 * floor / t), (a, la, 4 * floor / t**2), (j, lj, 8 * floor / t**3))
            ):
                r = (abs(val) - fl) / lim
                if r > self.worst:
                    self.worst = r
                    self.where = ("XYZ"[i], "vaj"[q], s.line, s.t)
        self.n += 1
        if self.n >= CYCLES:
            raise _Enough


def _plan(path: Path, lookahead: int):
    """(_Peaks, machine) of the program, or None when the kernel does not read it."""
    from cnc.interp import Interpreter

    for machine in ("mill3", "lathe2"):
        params = _wide(machine, lookahead)
        try:
            interp = Interpreter(params, file=str(path))
            start = tuple(interp.state.machine_position)
            peaks = _Peaks(params, start)
            # CYCLES samples checked: enough (_Enough ends the run)
            with open(path, encoding="latin-1") as fh, contextlib.suppress(_Enough):
                plan_run(params, _first_moves(interp.run(fh), MOVES), start, None, peaks)
        except NcError:
            continue
        return peaks, machine
    return None


@pytest.mark.skipif(not GCODE_CORPUS.is_dir(), reason=MISSING)
@pytest.mark.parametrize("lookahead", [200, 5])
def test_no_corpus_program_makes_the_planner_break_a_limit(lookahead):
    planned = []
    worst = (0.0, None, None)
    for path in sorted(GCODE_CORPUS.glob("*.nc")):
        got = _plan(path, lookahead)
        if got is None:
            continue
        peaks, machine = got
        planned.append(path.name)
        if peaks.worst > worst[0]:
            worst = (peaks.worst, path.name, peaks.where)
    assert len(planned) >= MIN_PLANNED, planned
    assert worst[0] <= 1.0 + REL, f"worst limit ratio {worst} (look-ahead {lookahead})"


@pytest.mark.skipif(not GCODE_CORPUS.is_dir(), reason=MISSING)
@pytest.mark.parametrize(
    "name", ["cline-exclamation.nc", "enier-mill-hp2.nc", "kiely-mill-text.nc"]
)
def test_the_summary_without_a_trace_equals_the_sampled_one_on_real_programs(name):
    """`nc plan` without a trace (Motion.run, closed-form deviation) and with one (every
    sample through Python) report the same cycle time and maxima, to the bit; the
    sampled deviation is at most the closed-form one (see tests/cnc/test_plan_cli.py)."""
    from cnc.interp import Interpreter

    path = GCODE_CORPUS / name
    params = _wide("mill3", 200)
    reps = []
    for on_sample in (None, lambda s: None):
        interp = Interpreter(params, file=str(path))
        start = tuple(interp.state.machine_position)
        with open(path, encoding="latin-1") as fh:
            reps.append(plan_run(params, interp.run(fh), start, None, on_sample))
    fast, slow = reps
    for key in ("cycle_time_s", "max_abs_velocity", "max_abs_accel", "max_abs_jerk"):
        assert fast[key] == slow[key], key
    assert fast["worst_limit_ratio"] == slow["worst_limit_ratio"] <= 1.0 + REL
    assert slow["sampled_path_deviation_mm"] <= fast["max_path_deviation_mm"] + 1e-12
