"""`fmscell nc plan`: interpreter -> planner -> interpolator, one JSON object, CSV trace."""

from __future__ import annotations

import csv
import json
import math

import pytest
from typer.testing import CliRunner

import cnc.cli_plan  # noqa: F401  (registers the command on nc_app)
from cnc.canon import Dwell, PathMode, SetPathMode, StraightFeed, StraightTraverse
from cnc.cli import nc_app
from cnc.cli_plan import plan_run
from cnc.config import MACHINES_DIR
from cnc.params import MachineParams

PROGRAM = """%
O1000 (plan test)
G21 G90 G17 G54 G64 P0.02
G0 X-50 Y-50 Z-10
G1 X-100 F3000
G1 Y-100
G2 X-150 Y-100 I-25 J0
G1 X-150 Y-50
G4 X0.25
M30
%
"""

runner = CliRunner()


@pytest.fixture
def prog(tmp_path):
    p = tmp_path / "part.nc"
    p.write_text(PROGRAM)
    return p


def invoke(*args, setup=("--g54", "0,0,0")):
    # the programs here are in machine coordinates: G54 = 0 instead of the factory setup
    res = runner.invoke(nc_app, ["plan", *map(str, args), *setup])
    return res


def test_plan_prints_one_json_object_with_the_figures(prog):
    res = invoke(prog, "--json")
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)
    assert rep["moves"] == 5
    assert rep["final_position"] == {"X": -150.0, "Y": -50.0, "Z": -10.0}
    assert rep["final_work_position"] == {"X": -150.0, "Y": -50.0, "Z": -10.0}
    assert rep["path_length_mm"] == pytest.approx(50 + 50 + 25 * math.pi + 50, rel=1e-12)
    assert rep["rapid_length_mm"] == pytest.approx(math.sqrt(50**2 + 50**2 + 10**2), rel=1e-12)
    assert 0.0 < rep["max_path_deviation_mm"] <= 0.02 + 1e-9
    p = MachineParams()
    for ax in p.axes:
        assert rep["max_abs_velocity"][ax.name] <= ax.max_velocity / 60 * (1 + 1e-9)
        assert rep["max_abs_accel"][ax.name] <= ax.max_accel * (1 + 1e-9)
        assert rep["max_abs_jerk"][ax.name] <= ax.max_jerk * (1 + 1e-9)
        # the limit ratios are the maxima over the limits, per axis
        r = rep["limit_ratio"][ax.name]
        assert r["v"] == pytest.approx(rep["max_abs_velocity"][ax.name] / (ax.max_velocity / 60))
        assert r["a"] == pytest.approx(rep["max_abs_accel"][ax.name] / ax.max_accel)
        assert r["j"] == pytest.approx(rep["max_abs_jerk"][ax.name] / ax.max_jerk)
    worst = max(v for ax in rep["limit_ratio"].values() for v in ax.values())
    assert rep["worst_limit_ratio"] == worst
    assert 0.5 < worst <= 1.0 + 1e-9
    # the dwell is part of the cycle time
    assert rep["cycle_time_s"] > 0.25


def test_trace_csv_has_one_row_per_ipo_sample(prog, tmp_path):
    out = tmp_path / "trace.csv"
    res = invoke(prog, "--ipo-ms", "1", "--trace", out)
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)
    rows = list(csv.reader(out.open()))
    assert rows[0] == ["t", "X", "Y", "Z", "line"]
    assert len(rows) - 1 == round(rep["cycle_time_s"] / 0.001)
    assert [float(x) for x in rows[-1][1:4]] == [-150.0, -50.0, -10.0]
    ts = [float(r[0]) for r in rows[1:]]
    assert all(b > a for a, b in zip(ts, ts[1:], strict=False))


def test_trace_is_byte_identical_twice(prog, tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert invoke(prog, "--trace", a).exit_code == 0
    assert invoke(prog, "--trace", b).exit_code == 0
    assert a.read_bytes() == b.read_bytes()


def test_config_file_is_used(prog):
    res = invoke(prog, "--config", MACHINES_DIR / "mill3.yaml", "--json", setup=())
    assert res.exit_code == 0, res.output
    # the machine's own setup: G54 X-300 (cnc/machines/mill3.yaml)
    assert json.loads(res.output)["final_position"]["X"] == -450.0


def test_bad_program_gives_file_line_col(tmp_path):
    bad = tmp_path / "bad.nc"
    bad.write_text("G21 G90\nG1 X-10\n")  # feed move without F
    res = invoke(bad)
    assert res.exit_code == 1
    assert f"{bad}:2:" in res.output


def test_missing_file_is_a_clear_error(tmp_path):
    res = invoke(tmp_path / "nope.nc")
    assert res.exit_code == 1
    assert "cannot read program" in res.output


def test_plan_run_on_canonical_commands():
    cmds = [
        SetPathMode(1, PathMode.EXACT_STOP),
        StraightTraverse(2, (-10.0, 0.0, 0.0)),
        StraightFeed(3, (-10.0, -10.0, 0.0), 1200.0),
        Dwell(4, 0.1),
    ]
    seen = []
    rep = plan_run(MachineParams(), cmds, (0.0, 0.0, 0.0), on_sample=seen.append)
    assert rep["blocks"] == 4 and rep["moves"] == 2
    assert rep["path_length_mm"] == 10.0 and rep["rapid_length_mm"] == 10.0
    assert rep["max_path_deviation_mm"] < 1e-12
    assert len(seen) == round(rep["cycle_time_s"] / 0.002)
    # the dwell holds the machine for 0.1 s = 50 cycles at the end point
    assert sum(1 for s in seen if s.pose == (-10.0, -10.0, 0.0)) >= 50


def test_demo_runs_the_sample_program(capsys):
    from cnc.demo import run_demo

    assert run_demo() == 0
    out = capsys.readouterr().out
    assert "interpreter -> planner -> interpolator" in out
    assert "final machine position X-120.0000, Y-100.0000, Z-5.0000" in out


REPEATS = """%
O0001
G21 G90 G17 G64 P0.01
G0 X-20 Y-20 Z-5
M98 P200 L3
G0 Z0
M30
O200
G1 X-40 Y-20 F3000
G1 Y-40
G1 X-20
G1 Y-20
M99
%
"""


def test_deviation_is_measured_against_the_block_being_run(tmp_path):
    # the same square three times: a nearest-piece search could match a later pass
    p = tmp_path / "rep.nc"
    p.write_text(REPEATS)
    res = invoke(p, "--json")
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)
    assert rep["moves"] == 14
    assert 0.0 < rep["max_path_deviation_mm"] <= 0.01 + 1e-9
    assert rep["path_length_mm"] == pytest.approx(3 * 80.0, rel=1e-12)
    assert rep["final_position"] == {"X": -20.0, "Y": -20.0, "Z": 0.0}


def _corners(n: int, feed: float, tol: float) -> list:
    """A square spiral of n lines with G64 P`tol` blends, a dwell and a rapid between."""
    cmds: list = [SetPathMode(1, PathMode.CONTINUOUS, tol)]
    x = y = 0.0
    for i in range(n):
        step = 2.0 + 0.5 * i
        if i % 4 == 0:
            x -= step
        elif i % 4 == 1:
            y -= step
        elif i % 4 == 2:
            x += 0.7 * step
        else:
            y += 0.7 * step
        cmds.append(StraightFeed(i + 2, (x, y, -1.0 - 0.01 * i), feed))
        if i == n // 2:
            cmds.append(Dwell(i + 2, 0.05))
            cmds.append(StraightTraverse(i + 2, (x - 5.0, y, -1.0)))
    return cmds


@pytest.mark.parametrize(
    ("feed", "tol", "lookahead"), [(600.0, 0.01, 200), (3000.0, 0.05, 5), (9000.0, 0.002, 50)]
)
def test_the_summary_without_a_trace_equals_the_sampled_one(feed, tol, lookahead):
    """Without a trace `plan_run` steps natively (`Motion.run`) and takes the deviation in
    closed form from the blends; with one it samples in Python. Cycle time and maxima
    are the same to the bit (the same samples); the closed-form deviation is the exact
    largest one (at the blend's middle, where the distances to its two lines cross), so
    the samples' may fall short of it by what the distance drops over half a sample
    spacing from there: sin(theta/2) v T / 2 <= F T / 2 (the path speed never exceeds
    the programmed feed F at override 1)."""
    params = MachineParams(lookahead=lookahead)
    cmds = _corners(24, feed, tol)
    fast = plan_run(params, cmds, (0.0, 0.0, 0.0))
    seen = []
    slow = plan_run(params, cmds, (0.0, 0.0, 0.0), on_sample=seen.append)
    assert len(seen) == round(slow["cycle_time_s"] / 0.002)
    for key in ("cycle_time_s", "max_abs_velocity", "max_abs_accel", "max_abs_jerk"):
        assert fast[key] == slow[key], key
    assert fast["limit_ratio"] == slow["limit_ratio"]
    assert fast["final_position"] == slow["final_position"]
    assert "sampled_path_deviation_mm" not in fast
    sampled = slow["sampled_path_deviation_mm"]
    assert fast["max_path_deviation_mm"] == slow["max_path_deviation_mm"]
    assert 0.0 < sampled <= fast["max_path_deviation_mm"] + 1e-12
    assert fast["max_path_deviation_mm"] - sampled <= feed / 60.0 * 0.002 / 2 + 1e-12
    assert fast["max_path_deviation_mm"] <= tol + 1e-12
