"""mill4 and mill5 end to end: programs with rotary axes on the complete simulated machines
(CiA 402 drives on CAN, PLC), the bus load at the IPO cycle, and the post's mill5 agreeing
with the NC's."""

from __future__ import annotations

import warnings

import pytest
import yaml

from cnc.cli_simulate import simulate
from cnc.config import MACHINES_DIR, builtin_machine, load_machine_config

MILL4_PROGRAM = """%
O0040 (MILL4 ROTARY)
G21 G90 G54 G17
T1 M06
S2000 M03
G00 X0 Y0 Z20 A0
G01 Z-2 F300
G01 X20 A90 F600
G91 A-45
G90 G01 A120 F3600
G00 Z20
M30
%
"""

# a short 5-axis CL path (seed 002's Table 1 orientations), tool tip in the workpiece frame
CL_5AXIS = """PARTNO ROTARY TEST
UNITS/MM
LOADTL/1
SPINDL/6000,CLW
MULTAX/ON
RAPID
GOTO/20,0,-100,0.6327447124,0.465569252,0.6187742456
FEDRAT/2000
GOTO/20,0,-155,0.6327447124,0.465569252,0.6187742456
GOTO/100,0,-150,0.628284235,0.461387437,0.62640867
FINI
"""
TOLERANCE = 0.01


def test_mill4_moves_the_a_drive_with_the_program():
    cfg = builtin_machine("mill4")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # bus load warnings belong to other tests
        got = simulate(MILL4_PROGRAM, cfg, "mill4", max_s=120.0)
    assert got["result"] == "completed", got
    # the A drive ends where the program left A, its following error a servo's, not a jump
    assert got["final_position"]["A"] == pytest.approx(120.0, abs=0.01)
    assert got["final_position"]["X"] == pytest.approx(-300.0 + 20.0, abs=0.01)
    assert 0.0 < got["max_following_error_mm"]["A"] < 0.5
    assert got["blocks"] >= 7


def _posted_mill5_program() -> str:
    from cam.chain import records_from_text
    from cam.post import PostOptions, load_machine, post

    _post, blocks = post(
        records_from_text(CL_5AXIS, "cl"),
        load_machine("mill5"),
        PostOptions(tolerance_mm=TOLERANCE),
    )
    return "\n".join(b.text for b in blocks) + "\n"


def test_a_posted_cl_program_runs_on_mill5_within_t_plus_the_servo_lag():
    text = _posted_mill5_program()
    assert " B" in text and " C" in text
    cfg = builtin_machine("mill5")
    got = simulate(text, cfg, "mill5", max_s=300.0)
    assert got["result"] == "completed", got
    tip = got["tool_tip"]
    # the interpolated joints' tip bows at most T from the CL line (the post bisected to
    # T at the midpoints; the bow peaks there); the drives add their lag
    assert 0.0 < tip["peak_deviation_mm"] <= TOLERANCE * 1.05
    lag = max(got["max_following_error_mm"].values())
    assert tip["actual_peak_deviation_mm"] <= TOLERANCE * 1.05 + 2.0 * lag + 0.01
    # the bus: five drives at the 1 ms IPO cycle on two lines, under 100 %
    assert 0.0 < got["bus_load"]["mean"] < 100.0


def test_five_drives_on_one_line_at_1_ms_are_refused_with_the_figures():
    from cnc.machine import Machine
    from drives.bus.loadplan import BusOverloadError

    doc = yaml.safe_load((MACHINES_DIR / "mill5.yaml").read_text(encoding="utf-8"))
    for entry in doc["drives"]["axes"].values():
        entry.pop("line", None)
    cfg = load_machine_config(doc)
    with pytest.raises(BusOverloadError, match=r"exceeds 100 %"):
        Machine(cfg, "mill5")


def test_mill5_agrees_with_the_posts_machine():
    from cam.machine5 import MILL5_FILE, load_mill5

    post = load_mill5(MILL5_FILE)
    nc = builtin_machine("mill5")
    assert nc.kind == post.kind == "mill5"
    k = nc.kinematics
    assert k is not None
    assert (k.d_mm, k.tool_length_mm, k.z_offset_mm) == (
        post.kinematics.d_mm,
        post.kinematics.tool_length_mm,
        post.kinematics.z_offset_mm,
    )
    for name in "XYZB":
        lim, axis = getattr(post.axes, name), nc.axes[name]
        assert (axis.min_mm, axis.max_mm) == (lim.min, lim.max), name
    assert post.axes.C.continuous and nc.axes["C"].continuous
