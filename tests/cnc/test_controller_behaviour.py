"""Controller core with IdealAxes and the fake PLC: refusals, stops, switches, MDI, jog,
E-stop, following error, drip-feed, ACC, determinism."""

from __future__ import annotations

import pytest

from cnc.controller import CommandRefused, ControllerSettings, CuttingModel
from cnc.faces.drip import DripBuffer
from tests.cnc.test_controller import SQUARE, Rig

LONG = """%
O2000
G90 G0 X-10 Y-10 Z-10
G1 X-300 F3000
G1 Y-200
G0 Z-5
M30
%
"""

STOPS = """%
O3000
G90 G0 X-10 Y-10 Z-10
G1 X-20 F2000
M0
G1 X-30
M1
/G1 Y-50
G1 X-40
M30
%
"""


def _homed(**kw) -> Rig:
    rig = Rig(programs={1000: SQUARE, 2000: LONG, 3000: STOPS}, **kw)
    rig.home()
    return rig


# ---- refusal table ------------------------------------------------------------------------


def _running(rig: Rig) -> None:
    rig.cmd("select_program", number=2000)
    rig.cmd("cycle_start")
    rig.step(20)


REFUSALS = [
    # (setup, command, args, expected reason)
    ("idle", "cycle_start", {}, "no program selected"),
    ("idle", "select_program", {"number": 1234}, "program O1234 not in memory"),
    ("idle", "mode", {"mode": "TEACH"}, "mode 'TEACH' unknown"),
    ("idle", "feed_override", {"pct": 250}, "feed override 250 % outside 0..200 %"),
    ("idle", "rapid_override", {"pct": 120}, "rapid override 120 % outside 0..100 %"),
    ("idle", "spindle_override", {"pct": 40}, "spindle override 40 % outside 50..120 %"),
    ("idle", "jog", {"axis": "X", "direction": 1}, "jog refused: mode is AUTO, not JOG"),
    ("idle", "home", {}, "homing refused: mode is AUTO, not REF"),
    ("idle", "feed_hold", {}, "feed hold refused: nothing is moving"),
    ("idle", "mdi", {"text": "G0 X-1"}, "MDI refused: mode is AUTO, not MDI"),
    ("idle", "acc", {"on": True, "limit_pct": 0}, "ACC limit 0 % outside 1..200 %"),
    ("idle", "frobnicate", {}, "unknown command 'frobnicate'"),
    ("running", "mode", {"mode": "JOG"}, "mode change refused while ACTIVE"),
    ("running", "select_program", {"number": 1000}, "program select refused while ACTIVE"),
    ("running", "cycle_start", {}, "cycle start refused: program already ACTIVE"),
    ("running", "dry_run", {"on": True}, "dry run switch refused while ACTIVE"),
    ("mdi", "cycle_start", {}, "MDI has no program"),
    ("mdi", "mdi", {"text": "G0 X50"}, "beyond the soft limit"),
    ("mdi", "mdi", {"text": "G1 X-5"}, "feed move without F"),
    ("jog", "jog", {"axis": "Q", "direction": 1}, "no axis 'Q'"),
    ("jog", "jog", {"axis": "X", "direction": 1, "increment": 1000}, "beyond the soft limit"),
    ("jog", "jog", {"axis": "X", "direction": 1, "feed": 99999}, "outside 0..30000"),
]


@pytest.mark.parametrize("setup,name,args,reason", REFUSALS)
def test_refusal_table(setup, name, args, reason):
    rig = _homed()
    if setup == "running":
        _running(rig)
    elif setup in ("mdi", "jog"):
        rig.cmd("mode", mode=setup.upper())
    with pytest.raises(CommandRefused) as exc:
        rig.cmd(name, **args)
    assert reason in exc.value.reason
    assert any(reason in text for _, text in rig.ctl.events)


def test_program_start_refusals_name_the_cause():
    rig = Rig(programs={2000: LONG})
    rig.step(10)
    rig.cmd("select_program", number=2000)
    with pytest.raises(CommandRefused, match=r"machine not homed \(X, Y, Z\)"):
        rig.cmd("cycle_start")
    rig.home()
    rig.plc.out["DoorClosed"] = False
    rig.step(5)
    with pytest.raises(CommandRefused, match="door open"):
        rig.cmd("cycle_start")
    rig.plc.out["DoorClosed"] = True
    rig.plc.out.update(PlcAlarm=True, PlcAlarmNumber=1041)
    rig.step(5)
    with pytest.raises(CommandRefused, match="alarm 1041"):
        rig.cmd("cycle_start")
    assert rig.ctl.alarms[0].source == "PLC"
    rig.plc.out.update(PlcAlarm=False, PlcAlarmNumber=0)
    rig.step(5)
    assert rig.ctl.alarms == ()  # a PLC alarm goes with its cause
    rig.cmd("cycle_start")


# ---- stops and switches -------------------------------------------------------------------


def test_feed_hold_and_resume_end_at_the_programmed_point():
    rig = _homed()
    _running(rig)
    rig.until(lambda: rig.outputs.status.path_feed_rate > 2900)
    rig.cmd("feed_hold")
    assert rig.ex == "FEED_HOLD"
    rig.until(lambda: rig.outputs.status.path_feed_rate == 0.0, 2)
    x = rig.pos("X")
    rig.step(200)
    assert rig.pos("X") == x and rig.ex == "FEED_HOLD"
    assert rig.outputs.plc["NcInCycle"] is True
    rig.cmd("cycle_start")
    assert rig.ex == "ACTIVE"
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")
    assert (rig.pos("X"), rig.pos("Y"), rig.pos("Z")) == pytest.approx((-300, -200, -5))


def test_plc_feed_hold_level_holds_and_cycle_start_edge_resumes():
    rig = _homed()
    _running(rig)
    rig.plc.out["FeedHold"] = True
    rig.step(10)
    assert rig.ex == "FEED_HOLD"
    with pytest.raises(CommandRefused, match="feed hold from the PLC"):
        rig.cmd("cycle_start")
    rig.plc.out["FeedHold"] = False
    rig.step(10)
    assert rig.ex == "FEED_HOLD"  # the level dropping does not restart the machine
    rig.plc.out["CycleStart"] = True
    rig.step(5)
    rig.plc.out["CycleStart"] = False
    assert rig.ex == "ACTIVE"
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")


def test_single_block_stops_at_each_block_end():
    rig = _homed()
    rig.cmd("single_block", on=True)
    rig.cmd("select_program", number=2000)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "INTERRUPTED", 5)
    assert (rig.pos("X"), rig.pos("Y"), rig.pos("Z")) == pytest.approx((-10, -10, -10))
    rig.step(100)
    assert rig.ex == "INTERRUPTED" and rig.pos("X") == pytest.approx(-10)
    rig.cmd("cycle_start")
    rig.step()
    rig.until(lambda: rig.ex == "INTERRUPTED", 10)
    assert rig.pos("X") == pytest.approx(-300) and rig.pos("Y") == pytest.approx(-10)
    rig.cmd("single_block", on=False)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED", 10)


@pytest.mark.parametrize(
    "optional_stop,block_skip,stops,final_y",
    [
        (False, False, ["PROGRAM_STOPPED"], -50.0),
        (True, False, ["PROGRAM_STOPPED", "OPTIONAL_STOP"], -50.0),
        (True, True, ["PROGRAM_STOPPED", "OPTIONAL_STOP"], -10.0),
        (False, True, ["PROGRAM_STOPPED"], -10.0),
    ],
)
def test_program_stop_optional_stop_and_block_skip(optional_stop, block_skip, stops, final_y):
    rig = _homed()
    rig.cmd("optional_stop", on=optional_stop)
    rig.cmd("block_skip", on=block_skip)
    rig.cmd("select_program", number=3000)
    rig.cmd("cycle_start")
    seen = []
    for _ in range(len(stops)):
        rig.until(lambda: rig.ex in ("PROGRAM_STOPPED", "OPTIONAL_STOP", "PROGRAM_COMPLETED"))
        seen.append(rig.ex)
        rig.step(50)
        assert rig.ex == seen[-1]  # stays stopped until cycle start
        rig.cmd("cycle_start")
        rig.step()
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")
    assert seen == stops
    assert rig.pos("Y") == pytest.approx(final_y)
    assert rig.pos("X") == pytest.approx(-40)


def test_dry_run_uses_the_dry_run_feed_and_counts_no_part():
    rig = _homed(settings=ControllerSettings(dry_run_feed=6000.0))
    rig.cmd("dry_run", on=True)
    rig.cmd("select_program", number=2000)
    rig.cmd("cycle_start")
    peak = 0.0
    while rig.ex != "PROGRAM_COMPLETED":
        rig.step()
        if rig.outputs.status.line == 4:  # G1 X-300 F3000
            peak = max(peak, rig.outputs.status.path_feed_rate)
    assert peak == pytest.approx(6000.0, rel=1e-6)
    assert rig.ctl.part_count == 0


def test_feed_override_scales_the_path_feed():
    rig = _homed()
    rig.cmd("feed_override", pct=50)
    _running(rig)
    rig.until(lambda: rig.pos("X") < -150)
    assert rig.outputs.status.path_feed_rate == pytest.approx(1500.0, rel=1e-6)
    assert rig.outputs.status.feed_override == 50.0


def test_reset_aborts_the_program_after_braking():
    rig = _homed()
    _running(rig)
    rig.until(lambda: rig.outputs.status.path_feed_rate > 2900)
    rig.cmd("reset")
    rig.step()
    assert rig.outputs.plc["NcResetting"] is True  # the PLC drops its handshakes
    assert rig.outputs.plc["NcInCycle"] is True  # braking first
    assert rig.ex == "STOPPED"
    rig.until(lambda: rig.ex == "READY", 2)
    rig.step()
    assert rig.outputs.plc["NcInCycle"] is False
    x = rig.pos("X")
    rig.step(50)
    assert rig.pos("X") == x
    assert rig.outputs.plc["NcResetting"] is False


# ---- MDI and jog --------------------------------------------------------------------------


def test_mdi_executes_typed_blocks():
    rig = _homed()
    rig.cmd("mode", mode="MDI")
    rig.cmd("mdi", text="G90 G0 X-25 Y-35\nG1 Z-12 F500")
    rig.step()
    assert rig.ex == "ACTIVE" and rig.outputs.status.program == "MDI"
    rig.until(lambda: rig.ex == "READY", 10)
    assert (rig.pos("X"), rig.pos("Y"), rig.pos("Z")) == pytest.approx((-25, -35, -12))
    assert rig.ctl.part_count == 0
    with pytest.raises(CommandRefused, match="mode change refused while ACTIVE"):
        rig.cmd("mdi", text="G91 G1 X-5 F100")
        rig.step()
        rig.cmd("mode", mode="AUTO")
    rig.until(lambda: rig.ex == "READY", 10)
    assert rig.pos("X") == pytest.approx(-30)


def test_jog_increment_continuous_and_soft_limit():
    rig = _homed()
    rig.cmd("mode", mode="JOG")
    rig.cmd("jog", axis="X", direction=-1, increment=10.0)
    rig.until(lambda: not rig.ctl._jog, 5)
    assert rig.pos("X") == pytest.approx(-10.0)
    rig.cmd("jog", axis="Y", direction=-1, feed=6000.0)
    rig.step(200)
    y = rig.pos("Y")
    assert -400 < y < -10
    rig.cmd("jog", axis="Y", direction=0)
    rig.until(lambda: not rig.ctl._jog, 5)
    stopped = rig.pos("Y")
    rig.step(50)
    assert rig.pos("Y") == stopped
    # continuous jog stops at the soft limit
    rig.cmd("jog", axis="Z", direction=-1, feed=24000.0)
    rig.until(lambda: not rig.ctl._jog, 10)
    assert rig.pos("Z") == pytest.approx(-450.0)
    with pytest.raises(CommandRefused, match="at its soft limit"):
        rig.cmd("jog", axis="Z", direction=-1)


# ---- E-stop, following error, drive faults ------------------------------------------------


def test_estop_quick_stops_raises_alarm_and_requires_homing():
    rig = _homed()
    _running(rig)
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1000)
    rig.plc.out["EStopActive"] = True
    rig.plc.out["AxisEnable"] = False
    rig.step(5)
    assert "quick_stop" in rig.axes.commands
    assert rig.ex == "STOPPED"
    st = rig.outputs.status
    assert st.emergency_stop == "TRIGGERED"
    lost = [(3031, "X"), (3031, "Y"), (3031, "Z")]  # warnings: home the machine
    assert [a.number for a in st.alarms if a.severity == "FAULT"] == [3001]
    assert [(a.number, a.axis) for a in st.alarms if a.severity == "WARNING"] == lost
    assert st.unreferenced == ("X", "Y", "Z")
    assert not any(rig.ctl.referenced.values())
    # reset while the E-stop is still active keeps the alarm
    rig.cmd("reset")
    assert [a.number for a in rig.ctl.alarms if a.severity == "FAULT"] == [3001]
    rig.plc.out["EStopActive"] = False
    rig.plc.out["AxisEnable"] = True
    rig.step(5)
    rig.cmd("reset")
    # RESET clears the E-stop alarm, not the lost reference: the machine says so
    assert [(a.number, a.axis) for a in rig.ctl.alarms] == lost
    assert all(a.severity == "WARNING" for a in rig.ctl.alarms)
    rig.step(10)
    rig.cmd("select_program", number=2000)
    with pytest.raises(CommandRefused, match=r"machine not homed \(X, Y, Z\)"):
        rig.cmd("cycle_start")
    rig.step(1)  # the status of the next cycle carries the reason
    assert "not homed" in rig.outputs.status.cycle_start_refused
    rig.home()
    assert rig.ctl.alarms == () and rig.outputs.status.unreferenced == ()
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")


def test_following_error_alarm_names_the_axis_and_stops():
    rig = _homed()
    _running(rig)
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1000)
    rig.axes.disturb("Y", 1.5)  # above the 1 mm floor at the low Y speed
    rig.step(3)
    alarms = rig.ctl.alarms
    assert [(a.number, a.axis) for a in alarms] == [(3010, "Y")]
    assert "following error on Y: 1.500 mm" in alarms[0].text
    assert rig.ex == "STOPPED"
    assert "quick_stop" in rig.axes.commands
    rig.axes.disturb("Y", 0.0)
    rig.cmd("reset")
    assert rig.ctl.alarms == ()
    rig.step(5)
    assert rig.axes.commands[-2:] == ["fault_reset", "enable"]
    assert rig.axes.enabled


def test_following_error_limit_scales_with_speed():
    rig = _homed(settings=ControllerSettings(ferror_min_mm=0.5, ferror_max_mm=5.0))
    _running(rig)
    rig.until(lambda: rig.outputs.status.path_feed_rate > 2900)  # X at 50 mm/s of 500
    rig.axes.disturb("X", 0.45)  # limit 0.5 mm (5 mm x 0.1)
    rig.step(3)
    assert rig.ctl.alarms == ()
    rig.axes.disturb("X", 0.6)
    rig.step(3)
    assert [a.number for a in rig.ctl.alarms] == [3010]


def test_drive_fault_raises_a_drive_alarm_with_axis_and_loses_reference_on_encoder():
    rig = _homed()
    _running(rig)
    rig.axes.inject_fault("X", 0x7305, "encoder signal lost", lose_reference=True)
    rig.step(2)
    a = rig.ctl.alarms[0]
    assert (a.number, a.source, a.axis) == (3040, "DRIVE", "X")
    assert "0x7305" in a.text
    assert rig.ex == "STOPPED"
    assert rig.ctl.referenced["X"] is False and rig.ctl.referenced["Y"] is True
    rig.axes.inject_fault("Y", 0x8130, "heartbeat lost")
    rig.step(2)
    assert any(x.source == "BUS" and x.axis == "Y" for x in rig.ctl.alarms)


# ---- drip-feed ----------------------------------------------------------------------------


def test_drip_feed_runs_from_the_buffer_and_waits_for_data():
    rig = _homed()
    buf = rig.ctl.drip_input()
    assert isinstance(buf, DripBuffer)
    assert rig.ctl.drip_input() is None  # one drip at a time
    buf.put("%")
    buf.put("G90 G0 X-10 Y-10 Z-10")
    buf.put("(a comment line gives no command)")
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "INTERRUPTED", 5)  # waiting for data
    assert rig.pos("X") == pytest.approx(-10)
    assert rig.outputs.plc["NcInCycle"] is True
    n = 200
    for i in range(n):
        while buf.fill > buf.high:
            rig.step()
        buf.put(f"G1 X{-10 - (i + 1) * 0.5:.3f} F6000")
    buf.put("M30")
    buf.end()
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED", 30)
    assert rig.pos("X") == pytest.approx(-10 - n * 0.5)
    assert rig.ctl.part_count == 1
    assert buf.max_fill <= buf.capacity
    lines = {s.line for s in rig.trace if s.program == "DRIP"}
    assert max(lines) == n + 4  # tape lines: %, G0, comment, n moves, M30


def test_drip_feed_reports_program_errors_with_the_tape_line():
    rig = _homed()
    buf = rig.ctl.drip_input()
    buf.put("G90 G0 X-10 Y-10 Z-10")
    rig.cmd("cycle_start")
    rig.step(50)
    buf.put("G1 X-20 F1000")
    buf.put("G1 X50")
    buf.end()
    rig.until(lambda: rig.ex == "STOPPED", 10)
    a = rig.ctl.alarms[0]
    assert a.number == 3020 and "DRIP:3:" in a.text and "soft limit" in a.text


def test_policy_refuses_replacing_the_running_program():
    rig = _homed()
    _running(rig)
    assert "O2000 is running" in rig.ctl.policy("READ", 2000)
    assert rig.ctl.policy("READ", 1000) is None
    assert rig.ctl.policy("PUNCH", 2000) is None
    assert "DRIP needs AUTO" in rig.ctl.policy("DRIP", None)


# ---- adaptive control ---------------------------------------------------------------------

HEAVY = """%
O4000
G90 G0 X-10 Y-10 Z-10
S1000 M3
G0 Z-108
G1 X-200 F2000
G0 Z-10
M30
%
"""


@pytest.mark.parametrize("acc_on", [False, True])
def test_acc_lowers_the_feed_override_under_a_heavy_cut(acc_on):
    model = CuttingModel(stock_top_mm=-100.0, width_mm=10.0, teeth=4, rated_power_kw=7.5)
    rig = Rig(programs={4000: HEAVY}, cutting_model=model)
    rig.home()
    if acc_on:
        rig.cmd("acc", on=True, limit_pct=60.0)
    rig.cmd("select_program", number=4000)
    rig.cmd("cycle_start")
    loads, states, overrides = [], set(), []
    while rig.ex != "PROGRAM_COMPLETED":
        rig.step()
        st = rig.outputs.status
        states.add(st.adaptive_control)
        if -190 < rig.pos("X") < -110 and st.path_feed_rate > 0:
            loads.append(st.spindle_load)
            overrides.append(st.feed_override)
        assert rig.k < 200000
    if acc_on:
        assert "LIMITING" in states
        assert max(loads[len(loads) // 2 :]) <= 60.0 * 1.05
        assert min(overrides) < 100.0
    else:
        assert states == {"OFF"}
        assert min(loads) > 70.0  # the unchecked cut loads the spindle beyond the limit
        assert set(overrides) == {100.0}


def test_cutting_model_load_grows_with_feed_depth_and_material():
    m = CuttingModel(stock_top_mm=0.0)
    base = m.load(1000.0, 2000.0, -2.0)
    assert m.load(2000.0, 2000.0, -2.0) > base
    assert m.load(1000.0, 2000.0, -4.0) == pytest.approx(
        m.idle_load_pct + 2 * (base - m.idle_load_pct)
    )
    hard = CuttingModel(stock_top_mm=0.0, material_factor=2.0)
    assert hard.load(1000.0, 2000.0, -2.0) - hard.idle_load_pct == pytest.approx(
        2 * (base - m.idle_load_pct)
    )
    assert m.load(1000.0, 2000.0, 1.0) == m.idle_load_pct  # above the stock: no cut
    assert m.load(1000.0, 0.0, -2.0) == 0.0


# ---- determinism --------------------------------------------------------------------------


def test_same_inputs_give_identical_status_sequences():
    def run():
        rig = _homed(lag_s=0.005)
        rig.cmd("select_program", number=1000)
        rig.cmd("cycle_start")
        rig.step(300)
        rig.cmd("feed_hold")
        rig.step(100)
        rig.cmd("cycle_start")
        rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")
        return rig.trace

    a, b = run(), run()
    assert len(a) == len(b) and a == b


# ---- the PLC path: mode requests, reset, overrides ----------------------------------------


def test_plc_mode_request_reset_and_overrides_take_the_same_path():
    rig = _homed()
    rig.plc.out["ModeSelect"] = 3
    rig.step(5)
    assert rig.ctl.mode == "JOG" and rig.outputs.plc["NcMode"] == 3
    assert rig.outputs.status.controller_mode == "MANUAL"
    rig.plc.out["ModeSelect"] = 1
    rig.step(5)
    assert rig.ctl.mode == "AUTO"
    rig.plc.out.update(FeedOverride=150, RapidOverride=180)
    _running(rig)
    assert rig.outputs.status.feed_override == 150.0
    assert rig.outputs.status.rapid_override == 100.0  # the NC's rapid override ends at 100
    rig.plc.out["ModeSelect"] = 2
    rig.step(5)
    assert rig.ctl.mode == "AUTO"
    assert any("PLC: mode change refused while ACTIVE" in t for _, t in rig.ctl.events)
    rig.plc.out["NcReset"] = True
    rig.step(5)
    rig.plc.out["NcReset"] = False
    rig.until(lambda: rig.ex == "READY", 2)
    assert any("reset (PLC)" in t for _, t in rig.ctl.events)


LATHE = """%
O7000
G18 G98 G0 X-100 Z-20
G1 X-80 Z-60 F300
G0 X-200 Z-10
M30
%
"""


def test_lathe_runs_x_z_with_x_as_diameter():
    rig = Rig("lathe2", programs={7000: LATHE})
    rig.home()
    assert rig.ctl.home_order == ("X", "Z")
    rig.run_program(7000)
    assert rig.ex == "PROGRAM_COMPLETED"
    assert set(rig.outputs.targets) == {"X", "Z"}
    assert (rig.pos("X"), rig.pos("Z")) == pytest.approx((-100.0, -10.0))  # radius
    trace_x = [s.axes["X"].commanded for s in rig.trace if s.line == 4]
    assert max(trace_x) == pytest.approx(-40.0, abs=1e-6)  # X-80 diameter = -40 mm radius


def test_reset_ends_a_drip_feed_and_tells_the_sender():
    rig = _homed()
    buf = rig.ctl.drip_input()
    buf.put("G90 G0 X-10 Y-10 Z-10")
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "INTERRUPTED", 5)
    rig.cmd("reset")
    rig.step()
    assert rig.ex == "READY"
    assert buf.aborted == "program ready at the machine"
    armed = rig.ctl.drip_input()
    rig.cmd("reset")
    assert armed.aborted == "reset at the machine"


# ---- subprograms, homing failures, spindle-at-speed interlock ------------------------------

MAIN_WITH_SUB = """%
O8000
G90 G0 X-10 Y-10 Z-10
M98 P8001 L2
M30
%
"""
SUB = """O8001
G91 G1 X-5 F3000
G90
M99
"""


def test_subprogram_from_memory_runs_with_repeats():
    rig = Rig(programs={8000: MAIN_WITH_SUB, 8001: SUB})
    rig.home()
    rig.run_program(8000)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert rig.pos("X") == pytest.approx(-20.0)


def test_homing_that_never_starts_raises_an_alarm():
    rig = Rig()
    rig.step(10)
    real_apply = rig.axes.apply

    def ignore_home(out, dt):  # an axis layer that drops the home request
        if out.axis_command == "home":
            out = type(out)(out.targets, "none", (), out.plc, out.status)
        real_apply(out, dt)

    rig.axes.apply = ignore_home
    rig.cmd("mode", mode="REF")
    rig.cmd("home")
    rig.until(lambda: rig.ctl.alarms, 3)
    assert rig.ctl.alarms[0].number == 3030
    assert "did not start homing" in rig.ctl.alarms[0].text
    rig.cmd("reset")
    assert rig.ctl.alarms == ()
    rig.axes.apply = real_apply
    rig.cmd("home", axes=["X"])
    rig.step()
    assert rig.outputs.home_axes == ("X",)
    rig.until(lambda: rig.ctl.referenced["X"], 3)
    assert not rig.ctl.referenced["Y"]


def test_estop_during_homing_aborts_it():
    rig = Rig()
    rig.step(10)
    rig.cmd("mode", mode="REF")
    rig.cmd("home")
    rig.step(30)  # Z homed, X under way
    rig.plc.out.update(EStopActive=True, AxisEnable=False)
    rig.step(6)  # the next PLC scan, then the cycle that reads it
    assert not any(rig.ctl.referenced.values())
    with pytest.raises(CommandRefused, match="emergency stop active"):
        rig.cmd("home")


def test_feed_waits_for_spindle_at_speed_but_rapids_do_not():
    rig = _homed()
    rig.cmd("select_program", number=1000)  # S2000 M3, then G1 moves
    rig.cmd("cycle_start")
    rig.until(lambda: rig.outputs.status.line == 7 and rig.outputs.status.path_feed_rate > 0)
    rig.plc.out["SpindleAtSpeed"] = False  # the spindle sags (a door stop, a stall)
    rig.step(100)
    assert rig.outputs.status.path_feed_rate == 0.0
    assert rig.ex == "ACTIVE"
    x = rig.pos("X")
    rig.step(50)
    assert rig.pos("X") == x
    rig.plc.out["SpindleAtSpeed"] = True
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")


@pytest.mark.parametrize(
    "name,args",
    [
        ("select_program", {"number": "abc"}),
        ("jog", {"axis": "X", "direction": "up"}),
        ("feed_override", {"pct": "fast"}),
        ("mode", {}),
        ("cycle_start", {"now": True}),
    ],
)
def test_malformed_commands_are_refused_not_crashes(name, args):
    rig = _homed()
    rig.cmd("mode", mode="JOG") if name == "jog" else None
    with pytest.raises(CommandRefused):
        rig.cmd(name, **args)
    rig.step(5)
    assert rig.ex == "READY"


def test_after_a_following_error_reset_the_program_runs_again_without_homing():
    rig = _homed()
    _running(rig)
    rig.until(lambda: rig.outputs.status.path_feed_rate > 1000)
    rig.axes.disturb("X", 6.0)
    rig.step(3)
    assert rig.ex == "STOPPED"
    rig.axes.disturb("X", 0.0)
    rig.cmd("reset")
    rig.step(5)
    assert all(rig.ctl.referenced.values())
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")
