"""G31 skip function and the tool setter (docs/gcode.md, "G31 skip and the tool setter").

The interpreter's G31 against hand-computed skip positions (the tool setter met on the
programmed path, as `nc check` / `nc plan` decide it), the sensor geometry, the check's
warning, and the machine in lockstep: CiA 402 drives on the simulated CAN bus, the tool
setter switching on the encoder position, the macro reading the latched #5063.
"""

from __future__ import annotations

import pytest

from cnc.canon import SkipFeed, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.interp.state import ToolOffset
from cnc.params import MachineParams
from cnc.probe import ToolSetter

# a sensor at machine X-100 Y-50 whose contact plane is at machine Z -300
SETTER = ToolSetter(-100.0, -50.0, -300.0, 5.0)
MILL = MachineParams(tool_setter=SETTER)
# G54 = (-20, -10, -100): work = machine - G54
G54 = {1: (-20.0, -10.0, -100.0)}


def run(prog: str, params: MachineParams = MILL, **kw) -> tuple[Interpreter, list]:
    ip = Interpreter(params, work_offsets=G54, **kw)
    return ip, list(ip.run(prog))


def common(prog: str, params: MachineParams = MILL, **kw) -> dict[int, float]:
    ip, _ = run(prog, params, **kw)
    return dict(ip.vars.common)


# work X-80 Y-40 is machine X-100 Y-50: right over the sensor
OVER = "G90 G54 G0 X-80 Y-40 Z-50\n"


@pytest.mark.parametrize(
    ("prog", "expected"),
    [
        # trip: machine Z -300 is work Z -200; #5061/#5062 the X Y of the skip
        (OVER + "G31 Z-250 F100\n#100=#5061\n#101=#5062\n#102=#5063\n",
         {100: -80.0, 101: -40.0, 102: -200.0}),
        # no trip (the end point is above the sensor): the end point is the skip position
        (OVER + "G31 Z-150 F100\n#102=#5063\n", {102: -150.0}),
        # the next block starts at the skip position: G91 Z10 from work Z -200
        (OVER + "G31 Z-250 F100\nG91 G0 Z10\n#103=#5043\n#102=#5063\n",
         {103: -190.0, 102: -200.0}),
        # G31 under G91: an increment from where the tool stands
        (OVER + "G91 G31 Z-200 F100\n#102=#5063\n", {102: -200.0}),
        # G91 G53 G31 (the Kitamura macro's form): the same increment
        (OVER + "G91 G53 G31 P2 Z-200 F100\n#102=#5063\n#104=#5023\n",
         {102: -200.0, 104: -300.0}),
        # G90 G53 G31: the end point in machine coordinates (machine Z -280: no trip)
        (OVER + "G90 G53 G31 Z-280 F100\n#102=#5063\n#104=#5023\n",
         {102: -180.0, 104: -280.0}),
        # starting on the sensor: it switches at once, the skip position is the start
        ("G90 G54 G0 X-80 Y-40 Z-210\nG31 Z-250 F100\n#102=#5063\n", {102: -210.0}),
        # off to the side (X 10 mm off, radius 5): the path misses it
        ("G90 G54 G0 X-70 Y-40 Z-50\nG31 Z-250 F100\n#102=#5063\n", {102: -250.0}),
        # a slanted skip entering the disc from its side at X -95 (machine), Z -300 reached
        # at X -100 + 5 ... : from machine (-90, -50, -290) to (-100, -50, -310): the plane
        # is reached half-way at X -95, which is on the disc's edge
        ("G90 G54 G0 X-70 Y-40 Z-190\nG31 X-80 Z-210 F100\n#100=#5061\n#102=#5063\n",
         {100: -75.0, 102: -200.0}),
        # G1 G31: G31 moves, G1 stays the modal motion
        (OVER + "G1 G31 Z-250 F100\n#105=#4001\n", {105: 1.0}),
        # before any G31 #5063 reads the current position
        (OVER + "#102=#5063\n", {102: -50.0}),
    ],
)  # fmt: skip
def test_skip_positions(prog: str, expected: dict[int, float]) -> None:
    got = common(prog)
    assert {k: got.get(k) for k in expected} == pytest.approx(expected)


def test_the_tool_length_and_radius_decide_where_it_switches() -> None:
    # T7: 120 mm long, radius 20; its axis 22 mm off the sensor centre: the end's edge is
    # over the 5 mm disc; the gauge line stops at -300 + 120 = -180 (work -80)
    tools = {7: ToolOffset(length=120.0, radius=20.0)}
    prog = "T7 M6\nG90 G54 G0 X-58 Y-40 Z0\nG31 Z-150 F100\n#102=#5063\n"
    assert common(prog, tools=tools)[102] == pytest.approx(-80.0)
    # radius 10: 22 mm off does not reach the disc (10 + 5 < 22)
    tools = {7: ToolOffset(length=120.0, radius=10.0)}
    assert common(prog, tools=tools)[102] == pytest.approx(-150.0)


def test_g31_is_one_shot_and_the_command_carries_the_move() -> None:
    ip, cmds = run(OVER + "G31 P3 Z-250 F100\nZ-100\n")
    skip = [c for c in cmds if isinstance(c, SkipFeed)]
    assert skip == [
        SkipFeed(2, (-100.0, -50.0, -350.0), 100.0, True, 3, 0.0, 0.0, (-100.0, -50.0, -300.0))
    ]
    # the programmed end is the command's, the expected skip is where a planner stops
    assert skip[0].planned() == StraightFeed(2, (-100.0, -50.0, -300.0), 100.0, True)
    # the next block moves with the modal G0, from the skip position
    assert cmds[-1] == StraightTraverse(3, (-100.0, -50.0, -200.0), False)
    assert ip.skip_misses == []


def test_without_a_sensor_every_g31_runs_to_its_end_and_is_noted() -> None:
    ip, _ = run(OVER + "G31 Z-250 F100\n#102=#5063\nG31 Z-260\n", MachineParams())
    assert ip.vars.common[102] == -250.0
    assert [line for _, line in ip.skip_misses] == [2, 4]


@pytest.mark.parametrize(
    ("prog", "col", "says"),
    [
        ("G41 D1 G1 X10 Y0 F100\nG31 X20\n", 1, "PS0035 G31 with cutter compensation"),
        ("G31 P5 Z-10 F100\n", 5, "G31 P5: the multi-step skip is P1..P4"),
        ("G31 F100\n", 1, "G31 needs X, Y or Z"),
        ("G31 Z-10\n", 1, "feed move without F"),
        ("G31 G28 Z-10 F100\n", 5, "G28 and another G code"),
    ],
)
def test_g31_errors(prog: str, col: int, says: str) -> None:
    tools = {1: ToolOffset(radius=2.0)}
    with pytest.raises(NcError) as exc:
        run(prog, tools=tools)
    assert says in exc.value.message
    assert exc.value.col == col


@pytest.mark.parametrize(
    ("start", "end", "expected"),
    [
        ((-100.0, -50.0, -200.0), (-100.0, -50.0, -400.0), (-100.0, -50.0, -295.0)),
        ((-100.0, -50.0, -200.0), (-100.0, -50.0, -294.0), None),  # stops short
        ((-120.0, -50.0, -310.0), (-80.0, -50.0, -310.0), (-105.0, -50.0, -310.0)),  # side
        ((-120.0, -56.0, -310.0), (-80.0, -56.0, -310.0), None),  # passes beside it
        ((-100.0, -50.0, -400.0), (-100.0, -50.0, -200.0), (-100.0, -50.0, -400.0)),  # on it
        ((-90.0, -50.0, -290.0), (-110.0, -50.0, -310.0), (-95.0, -50.0, -295.0)),
    ],
)
def test_first_trip_on_hand_computed_paths(start, end, expected) -> None:
    # tool length 5: the tip is 5 below the gauge line, so the plane is at gauge Z -295
    got = SETTER.first_trip(start, end, 5.0)
    if expected is None:
        assert got is None
    else:
        assert got == pytest.approx(expected)
        assert SETTER.trips((got[0], got[1], got[2] - 5.0))


def test_nc_check_warns_when_a_g31_never_trips(tmp_path) -> None:
    from typer.testing import CliRunner

    from cnc.cli import nc_app

    path = tmp_path / "p.nc"
    path.write_text("G21 G90 G0 X-10 Y-10 Z-10\nG31 Z-20 F100\nM30\n")
    res = CliRunner().invoke(nc_app, ["check", str(path)])
    assert res.exit_code == 0
    assert (
        f"{path}:2:1: warning: G31 never tripped: no tool setter on this machine"
        " (probe.tool_setter); it ran to its end point"
    ) in res.stdout + res.stderr


def test_nc_plan_stops_a_g31_at_the_tool_setter(tmp_path) -> None:
    import json

    from typer.testing import CliRunner

    from cnc.cli import nc_app

    cfg = tmp_path / "m.yaml"
    cfg.write_text(
        "base: mill3\nmachine_data: null\n"
        "probe: {tool_setter: {x: -100.0, y: -50.0, z_trigger: -300.0}}\n"
    )
    path = tmp_path / "p.nc"
    path.write_text("G21 G90 G0 X-100 Y-50 Z-250\nG31 Z-350 F600\nM30\n")
    res = CliRunner().invoke(nc_app, ["plan", "--config", str(cfg), str(path)])
    assert res.exit_code == 0, res.stdout + res.stderr
    report = json.loads(res.stdout)
    assert report["final_work_position"]["Z"] == pytest.approx(-300.0)


PROBING = """%
O0031 (TOOL LENGTH ON THE TOOL SETTER)
G21 G90 G17
T1 M6
G53 G0 X-100 Y-50 Z-270
G31 Z-30 F300
#500=#5063
#501=#5023
G91 G0 Z10
#502=#5023
M30
%
"""


def test_machine_latches_the_encoder_position_where_the_tool_setter_switches() -> None:
    """Lockstep, CiA 402 drives on the simulated CAN bus, mill3's G54: tool 1 (30 mm long)
    skips down onto the sensor (contact plane at machine Z -320: the gauge line at -290,
    work Z 10); the PLC
    answers M6, the macro reads the latch. The latch is an encoder sample of the IPO cycle
    the sensor switched: at most one cycle's travel (300 mm/min x 2 ms = 0.01 mm) below the
    plane; the machine then stops a little further on (deceleration) and the next block
    starts from where it stopped."""
    from cnc.machine import Machine
    from tests.cnc.setups import machine_coordinates

    cfg = machine_coordinates(
        "mill3",
        probe={"tool_setter": {"x": -100.0, "y": -50.0, "z_trigger": -320.0}},
        machine_data={"tools": {1: {"length": 30.0}}},
    )
    m = Machine(cfg, "mill3")
    try:
        m.step(50)
        m.command("mode", mode="REF")
        m.command("home")
        assert m.run_until(lambda mm: all(mm.controller.referenced.values()), 30.0), m.alarms
        n = m.load_program(PROBING)
        m.command("mode", mode="AUTO")
        m.command("select_program", number=n)
        m.command("cycle_start")
        done = m.run_until(
            lambda mm: bool(mm.alarms) or mm.status.execution == "PROGRAM_COMPLETED", 60.0
        )
        assert done and not m.alarms, m.alarms
        kept = m.controller.machine_data.macro_variables
        latched, stopped, after = kept[500], kept[501], kept[502]
    finally:
        m.close()
    # mill3's G54 Z is -300: the skip position in work coordinates is machine Z + 300
    assert 10.0 - 0.0101 <= latched <= 10.0
    assert latched - 300.0 - 0.5 < stopped <= latched - 300.0  # overtravel, decelerating
    assert after == pytest.approx(stopped + 10.0, abs=1e-9)


def test_controller_without_a_signal_runs_the_skip_to_its_end_point(monkeypatch) -> None:
    """IdealAxes lagging 4 ms: the sensor sits away from the path, the G31 runs to its end,
    which becomes #5063, and the program goes on from there."""
    from cnc.machine_data import MachineData
    from tests.cnc.setups import machine_coordinates
    from tests.cnc.test_controller import Rig

    prog = "%\nO0032\nG21 G90\nG53 G0 X-100 Y-50 Z-270\nG31 Z-280 F600\n#500=#5063\n" \
        "G91 G0 Z5\n#501=#5023\nM30\n%\n"  # fmt: skip
    cfg = machine_coordinates(
        "mill3", probe={"tool_setter": {"x": -200.0, "y": -50.0, "z_trigger": -320.0}}
    )
    monkeypatch.setattr("tests.cnc.test_controller.machine_coordinates", lambda name: cfg)
    rig = Rig(programs={32: prog}, lag_s=0.004, machine_data=MachineData())
    rig.home()
    rig.run_program(32)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    kept = rig.ctl.machine_data.macro_variables
    assert (kept[500], kept[501]) == pytest.approx((-280.0, -275.0))
    assert not any("skip signal" in text for _, text in rig.ctl.events)
