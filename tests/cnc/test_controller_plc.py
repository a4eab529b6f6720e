"""Controller core against the real machine-tool PLC program (plc.machine_io.machine_plc),
scanned every 5 IPO cycles (10 ms at 2 ms) in lockstep with IdealAxes."""

from __future__ import annotations

import pytest

from cnc.controller import CommandRefused
from tests.cnc.test_controller import Rig

TOOL_CHANGE = """%
O5000
G90 G0 X-50 Y-50 Z-20
T7
G1 X-60 F1000
M6
S1500 M3
M8
G1 X-80 F1000
M9
M5
M30
%
"""

LONG = """%
O6000
G90 G0 X-10 Y-10 Z-10
S1000 M3
G1 X-300 F1500
M30
%
"""


def _rig() -> Rig:
    rig = Rig(plc="real", programs={5000: TOOL_CHANGE, 6000: LONG})
    rig.home()
    return rig


def test_overrides_and_ready_come_from_the_plc():
    rig = _rig()
    assert rig.plc_in["PlcReady"] and rig.plc_in["AxisEnable"]
    assert rig.outputs.status.feed_override == 100.0
    assert rig.outputs.status.rapid_override == 100.0


def test_m6_through_the_real_plc_program():
    rig = _rig()
    io = rig.plc.io
    assert io.state.tool_in_spindle != 7
    rig.run_program(5000, 60)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert rig.ctl.alarms == ()
    assert io.state.tool_in_spindle == 7
    assert rig.plc_in["ToolInSpindle"] == 7
    assert [s for s in rig.plc.seen if s[0] == "T"] == [("T", 7)]
    ms = [c for k, c in rig.plc.seen if k == "M"]
    assert ms == [6, 3, 8, 9, 5, 30]
    assert ("S", 1500) in rig.plc.seen
    assert io.state.crashes == [] if hasattr(io.state, "crashes") else True
    assert rig.ctl.part_count == 1
    assert rig.pos("X") == pytest.approx(-80.0)


def test_door_opened_mid_cycle_gives_feed_hold_and_cycle_start_resumes():
    rig = _rig()
    io = rig.plc.io
    rig.cmd("select_program", number=6000)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1400, 10)
    io.inject("door_open")
    rig.step(10)
    assert rig.plc_in["FeedHold"] is True
    assert rig.ex == "FEED_HOLD"
    assert any(a.number == 1030 and a.source == "PLC" for a in rig.ctl.alarms)
    rig.until(lambda: rig.outputs.status.path_feed_rate == 0.0, 2)
    x = rig.pos("X")
    rig.step(100)
    assert rig.pos("X") == x
    # the NC refuses the operator's start while the PLC holds
    with pytest.raises(CommandRefused, match="feed hold from the PLC"):
        rig.cmd("cycle_start")
    io.clear("door_open")
    io.close_door()
    rig.step(10)
    io.press("PanelCycleStart")
    rig.step(10)
    io.release("PanelCycleStart")
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED", 30)
    assert rig.pos("X") == pytest.approx(-300.0)
    assert rig.ctl.part_count == 1


def test_estop_from_the_plc_quick_stops_and_requires_homing():
    rig = _rig()
    io = rig.plc.io
    rig.cmd("select_program", number=6000)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1400, 10)
    io.press_estop()
    rig.step(10)
    assert "quick_stop" in rig.axes.commands
    assert rig.ex == "STOPPED"
    nums = {a.number for a in rig.ctl.alarms}
    assert {3001, 1001} <= nums
    assert rig.outputs.status.emergency_stop == "TRIGGERED"
    assert not any(rig.ctl.referenced.values())
    assert not rig.axes.enabled
    io.release_estop()
    rig.step(10)
    io.press("PanelReset")
    rig.step(10)
    io.release("PanelReset")
    rig.step(20)
    # no FAULT left; the warnings say the reference is gone until homing
    assert [(a.number, a.severity) for a in rig.ctl.alarms] == [(3031, "WARNING")] * 3
    assert rig.axes.enabled  # AxisEnable back: the NC enabled the drives again
    rig.cmd("select_program", number=6000)
    with pytest.raises(CommandRefused, match="not homed"):
        rig.cmd("cycle_start")
    rig.home()
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED", 30)


def test_panel_cycle_start_in_jog_is_refused_by_the_plc():
    rig = _rig()
    rig.cmd("mode", mode="JOG")
    rig.step(10)
    io = rig.plc.io
    io.press("PanelCycleStart")
    rig.step(10)
    io.release("PanelCycleStart")
    rig.step(5)
    assert rig.ex == "READY"
    assert rig.plc.rt.image.mx[8] is True or rig.plc.rt.image.mx[8] == 1  # CycleStartRefused


@pytest.mark.parametrize(
    "machine,path,number,work_offsets,functions,final",
    [
        (
            "mill3",
            "tests/cnc/programs/pocket_mill.nc",
            100,
            None,
            [("T", 1), ("M", 6), ("S", 2000), ("M", 3), ("M", 8), ("M", 9), ("M", 30)],
            {"X": -330.0, "Y": -260.0, "Z": 0.0},
        ),
        (
            "lathe2",
            "tests/cnc/programs/lathe_shaft.nc",
            200,
            {1: (-150.0, 0.0, -300.0)},
            [("T", 1), ("M", 6), ("S", 191), ("M", 3), ("S", 800), ("M", 3), ("M", 5), ("M", 30)],
            {"X": -110.0, "Z": -250.0},
        ),
    ],
)
def test_sample_programs_run_end_to_end_through_the_real_plc(
    machine, path, number, work_offsets, functions, final
):
    with open(path) as fh:
        text = fh.read()
    rig = Rig(machine, plc="real", programs={number: text}, work_offsets=work_offsets)
    rig.home()
    rig.run_program(number, 120)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert rig.ctl.alarms == ()
    assert rig.plc.seen == functions
    assert rig.ctl.part_count == 1
    assert {a: round(v, 6) for a, v in rig.axes.actual.items()} == pytest.approx(final)
    assert rig.ctl.cutting_time > 0.0 and rig.ctl.spindle_time > 0.0


def test_panel_feed_hold_and_cycle_start_buttons():
    rig = _rig()
    io = rig.plc.io
    rig.cmd("select_program", number=6000)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1400, 10)
    io.press("PanelFeedHold")
    rig.step(10)
    io.release("PanelFeedHold")
    assert rig.ex == "FEED_HOLD"
    rig.until(lambda: rig.outputs.status.path_feed_rate == 0.0, 2)
    rig.step(50)
    assert rig.ex == "FEED_HOLD"
    io.press("PanelCycleStart")
    rig.step(10)
    io.release("PanelCycleStart")
    assert rig.ex == "ACTIVE"
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED", 30)
    assert rig.pos("X") == pytest.approx(-300.0)


def test_nc_reset_clears_the_plc_latched_alarm():
    rig = _rig()
    io = rig.plc.io
    io.inject("air_pressure_loss")
    rig.step(10)
    assert any(a.number == 1040 for a in rig.ctl.alarms)
    io.clear("air_pressure_loss")
    rig.step(10)
    assert any(a.number == 1040 for a in rig.ctl.alarms)  # latched in the PLC
    rig.cmd("reset")  # NcResetting clears the PLC's latched alarms
    rig.step(10)
    assert rig.ctl.alarms == ()
    assert rig.outputs.plc["NcResetting"] is False


def test_a_plc_that_stops_mid_cut_is_named_as_the_cause_and_clears_when_it_runs_again():
    """A PLC in FAULT (here its watchdog) switches its outputs off, axis enable with them: the
    cut stops with 3002 and the NC raises 3003 saying the PLC is not running (not only 'axis
    drives disabled'); 3003 goes when the PLC runs again."""
    from plc.runtime import ALARM_WATCHDOG

    rig = _rig()
    rig.cmd("select_program", number=6000)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1400, 10)
    assert not any(a.number == 3003 for a in rig.ctl.alarms)
    rig.plc.rt._fault(ALARM_WATCHDOG, "scan took 250 ms", rig.k)
    rig.until(lambda: rig.ex == "STOPPED", 2)
    numbers = {a.number: a for a in rig.ctl.alarms}
    assert 3003 in numbers and numbers[3003].source == "PLC", rig.ctl.alarms
    assert "PLC not running" in numbers[3003].text
    assert 3002 in numbers  # the drives went off during motion: the consequence
    rig.plc.rt.reset_fault()
    rig.plc.rt.run()
    rig.step(20)
    assert not any(a.number == 3003 for a in rig.ctl.alarms)
