"""The machine end to end in lockstep: the controller, CiA 402 drives over the simulated CAN
bus (axis group, virtual drives with their plants), the PLC with the machine-tool program."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from cnc.machine import Machine
from tests.cnc.setups import machine_coordinates

SQUARE = """%
O0010 (SQUARE WITH A TOOL CHANGE)
N10 G21 G90 G17
N20 T2 M6
N30 G0 X-100 Y-100 Z-10
N40 G1 X-150 F3000
N50 Y-150
N60 X-100
N70 Y-100
N80 G0 Z-5
N90 M30
%
"""

LONG = """%
O0020 (LONG FEED MOVES, NO SPINDLE)
N10 G21 G90 G17
N20 G1 X-300 Y-200 F3000
N30 X-50 Y-50
N40 M30
%
"""


def build(**kw) -> Machine:
    return Machine(machine_coordinates("mill3"), "mill3", **kw)


def homed(m: Machine) -> bool:
    return all(m.controller.referenced.values())


def home(m: Machine) -> None:
    m.step(50)  # the PLC gives AxisEnable, the controller enables the drives
    m.command("mode", mode="REF")
    m.command("home")
    assert m.run_until(homed, 30.0), m.alarms


def start(m: Machine, text: str) -> None:
    n = m.load_program(text)
    m.command("mode", mode="AUTO")
    m.command("select_program", number=n)
    m.command("cycle_start")


def finished(m: Machine) -> bool:
    return bool(m.alarms) or m.status.execution == "PROGRAM_COMPLETED"


@pytest.fixture
def machine():
    m = build()
    yield m
    m.close()


def test_homing_through_cia402_sets_the_reference_point_at_the_dog(machine):
    home(machine)
    fb = machine.axes.feedback()
    for axis in "XYZ":
        # home_mm = 0 at the dog's edge; the creep brakes a fraction of a millimetre on
        assert -0.5 < fb.actual[axis] <= 0.0
    assert machine.axes.group.state("X") == "OPERATION ENABLED"


def test_program_with_m6_completes_on_canopen_drives(machine):
    home(machine)
    start(machine, SQUARE)
    assert machine.run_until(finished, 30.0)
    assert machine.alarms == ()
    assert machine.status.execution == "PROGRAM_COMPLETED"
    # M6 went through the PLC: strobe, the changer sequence, finish
    assert machine.io.nc.get("ToolInSpindle") == 2
    assert machine.io.state.tool_in_spindle == 2
    machine.step(500)  # settle onto the last setpoint
    fb = machine.axes.feedback()
    assert fb.actual["X"] == pytest.approx(-100.0, abs=0.002)
    assert fb.actual["Y"] == pytest.approx(-100.0, abs=0.002)
    assert fb.actual["Z"] == pytest.approx(-5.0, abs=0.002)
    assert 0 < machine.max_following_error["X"] < 40.0
    assert machine.axes.bus_load.mean > 0.1


def test_door_opened_mid_cycle_gives_feed_hold_and_cycle_start_resumes(machine):
    home(machine)
    start(machine, LONG)
    machine.step(250)  # 0.5 s into the first move
    assert machine.status.execution == "ACTIVE"
    assert machine.open_door()  # no spindle: the door is not locked
    assert machine.run_until(lambda m: m.status.execution == "FEED_HOLD", 0.05)
    assert machine.io.nc.get("FeedHold")
    assert 1030 in machine.plc.alarms
    machine.step(500)  # the path decelerates along the path and stays
    held = dict(machine.axes.feedback().actual)
    machine.step(50)
    assert machine.axes.feedback().actual == pytest.approx(held, abs=0.002)
    machine.close_door()
    machine.step(5)
    machine.press("PanelCycleStart")
    assert machine.run_until(lambda m: m.status.execution == "ACTIVE", 0.1)
    machine.step(250)
    moved = machine.axes.feedback().actual
    assert abs(moved["X"] - held["X"]) > 5.0  # feeding again along the same path


def test_estop_quick_stops_raises_an_alarm_and_needs_homing_again(machine):
    home(machine)
    start(machine, LONG)
    machine.step(300)
    machine.press_estop()
    assert machine.run_until(lambda m: m.alarms, 0.05)
    assert machine.status.emergency_stop == "TRIGGERED"
    assert 1001 in machine.plc.alarms
    machine.step(500)  # quick stop ramps at max_accel: < 0.2 s from 50 mm/s
    a = dict(machine.axes.feedback().actual)
    machine.step(10)
    assert machine.axes.feedback().actual == pytest.approx(a, abs=1e-3)
    assert machine.axes.group.state("X") in ("QUICK STOP ACTIVE", "SWITCH ON DISABLED")
    fb = machine.axes.feedback()
    assert not any(fb.homed.values()) and not fb.enabled
    assert any(e.kind == "alarm" for e in machine.events.events)


@pytest.mark.parametrize(
    ("spec", "axis", "code", "bound_s"),
    [
        ("drive:X:encoder", "X", 0x7305, 0.01),
        ("drive:X:overcurrent", "X", 0x2310, 0.01),
        ("drive:Y:undervoltage", "Y", 0x3130, 0.05),
        ("drive:Z:overtemperature", "Z", 0x4310, 0.01),
        ("drive:Z:power_cycle", "Z", 0x0000, 0.01),
        # the master misses the axis's TPDO1 for 5 SYNC cycles (10 ms), + a cycle; the
        # heartbeat (3 x 100 ms) would tell later
        ("bus:bus_off:X", "X", 0x8100, 0.012),
        ("bus:drop:Y:count=0", "Y", 0x8100, 0.012),
        ("bus:drop_rpdo:Z:count=0", "Z", 0x8250, 0.052),  # the drive's RPDO deadline
        ("drive:X:chopper_failure", "X", 0x7111, 0.102),  # the brake check's period
    ],
)
def test_each_drive_fault_reaches_the_nc_within_its_bound(spec, axis, code, bound_s):
    m = build(faults=[f"{spec}@0.1s"])
    try:
        m.run_until(lambda mm: mm.t >= 0.1, 1.0)
        t0 = m.t
        assert m.run_until(lambda mm: mm.axes.active_faults, bound_s + 0.004)
        assert m.t - t0 <= bound_s + 0.004
        faults = m.axes.active_faults
        assert (axis, code) in [(a, c) for a, c, _ in faults]
        m.step(2)
        assert any(a.axis == axis for a in m.alarms)
        assert m.events.of_kind("fault_injected")[0].text == f"{spec}@0.1s"
    finally:
        m.close()


def test_jammed_slide_trips_the_nc_following_error_supervision_first(machine):
    home(machine)
    start(machine, LONG)
    machine.step(100)
    machine.inject("drive:Y:following_error")  # the table jams (drives.faults "blocked")
    t0 = machine.t
    assert machine.run_until(lambda m: m.alarms, 0.2)
    alarm = machine.alarms[0]
    # the NC's limit (1..5 mm, scaled with the axis speed) is far below the drive's 60 mm
    # window (0x6065): the NC quick-stops the axes before the drive faults
    assert (alarm.number, alarm.source, alarm.axis) == (3010, "NC", "Y")
    assert machine.t - t0 < 0.2
    machine.step(200)
    assert machine.status.execution == "STOPPED"
    assert not machine.axes.feedback().enabled


@pytest.mark.parametrize(
    ("spec", "axis", "number", "source"),
    [
        ("drive:X:encoder", "X", 3040, "DRIVE"),
        ("bus:bus_off:Y", "Y", 3041, "BUS"),
    ],
)
def test_drive_and_bus_faults_become_controller_alarms(spec, axis, number, source):
    m = build(faults=[f"{spec}@0.2s"])
    try:
        assert m.run_until(lambda mm: mm.alarms, 1.0)
        a = m.alarms[0]
        assert (a.number, a.source, a.axis) == (number, source, axis)
        assert m.events.of_kind("alarm")[0].data["number"] == number
    finally:
        m.close()


SHORT = """%
O0030 (LINES AND AN ARC)
N10 G21 G90 G17
N20 G1 X-20 Y-10 Z-5 F6000
N30 G2 X-40 Y-10 I-10 J0
N40 G0 X-10 Y-30
N50 M30
%
"""


def _scenario() -> tuple[str, str]:
    trace, candump = io.StringIO(), io.StringIO()
    m = build(trace=trace, candump=candump, faults=["plc:air_pressure_loss@3.0s"])  # mid-program
    try:
        home(m)
        start(m, SHORT)
        m.run_until(finished, 30.0)
        m.step(100)
    finally:
        m.close()
    return trace.getvalue(), candump.getvalue()


def test_lockstep_runs_are_byte_identical():
    a = _scenario()
    b = _scenario()
    assert a[0].splitlines()[0] == "t,X_cmd,Y_cmd,Z_cmd,X_act,Y_act,Z_act,line"
    assert len(a[0].splitlines()) > 500 and len(a[1].splitlines()) > 5_000
    assert a[0] == b[0]
    assert a[1] == b[1]


def test_seed_chapter_10_cam_program_with_spindle_and_coolant_on_canopen_drives(machine):
    """000_nc_book.md ch. 10, example 2 (eccentric cam), transcribed in programs/."""
    text = (Path(__file__).parent / "programs" / "cam_ch10.nc").read_text()
    home(machine)
    start(machine, text)
    seen = {"rpm": 0.0, "coolant": False}

    def watch(m: Machine) -> bool:
        seen["rpm"] = max(seen["rpm"], m.io.state.spindle_rpm)
        seen["coolant"] |= bool(m.io.output("CoolantPump"))
        return finished(m)

    assert machine.run_until(watch, 60.0)
    assert machine.alarms == ()
    assert seen["rpm"] == pytest.approx(400.0, abs=10.0)  # S400 M3 through the PLC
    assert seen["coolant"]  # M8
    machine.step(500)
    fb = machine.axes.feedback()
    # G54 X-300 Y-200 Z-300; the cam ends at X19.9 Z0, then G0 Y50
    for axis, want in {"X": -280.1, "Y": -150.0, "Z": -300.0}.items():
        assert fb.actual[axis] == pytest.approx(want, abs=0.005)
    assert machine.max_contour_error < 0.05


def test_lathe_composes_two_canopen_axes_and_homes_them():
    m = Machine(machine_coordinates("lathe2"), "lathe2")
    try:
        assert m.axis_names == ("X", "Z")
        assert sorted(m.axes.drives) == ["X", "Z"]
        home(m)
        assert all(-0.5 < v <= 0.0 for v in m.axes.feedback().actual.values())
        assert m.axes.hub.channel == "lathe2"
    finally:
        m.close()


def test_power_on_homes_in_the_sequence_and_ends_in_auto():
    m = build(ideal=True)
    try:
        m.power_on()
        assert homed(m) and m.controller.mode == "AUTO"
        texts = [t for _, t in m.controller.events]
        assert "homing Z then X Y" in texts and "homed Z X Y" in texts, texts
    finally:
        m.close()


@pytest.mark.parametrize(
    "kwargs", [None, {}, {"speed": 10.0}, {"speed": 1000.0, "idle_speed": 4.0}]
)
def test_plc_watchdog_takes_the_scan_threads_cpu_time_in_every_clock(kwargs):
    """Lockstep, real time and sped up alike: CPU time, so a descheduled thread is no overrun;
    and the status shows the last scan's time (machine time would read 0)."""
    import time

    from cnc.machine import RealtimeRunner

    m = build(ideal=True)
    try:
        if kwargs is not None:
            RealtimeRunner(m, **kwargs)
        assert m.plc.clock_ns is time.thread_time_ns
        m.step(50)  # 0.1 s: several 10 ms scans
        assert 0.0 < m.full_status().plc_scan_time_ms < 100.0
    finally:
        m.close()


def test_home_all_and_program_select_from_the_remote_panel_on_canopen_drives():
    """The remote panel's markers through the PLC to the NC, in lockstep, with the CiA 402
    homing runs blocking inside a cycle: the PLC catches up after each group and takes the
    NC's answer without a handshake timeout."""
    m = build()
    rt = m.plc
    try:
        m.step(50)
        rt.write_once("RemModeReq", 4)
        assert m.run_until(lambda m: m.controller.mode == "REF", 1.0)
        rt.write_once("RemHomeAll", True)
        assert m.run_until(lambda m: rt.read("HomeAccepted") or rt.read("HomeRefused"), 2.0)
        assert rt.read("HomeAccepted"), rt.read("HomeRefuseCode")
        rt.write_once("RemHomeAll", False)
        assert m.run_until(lambda m: rt.read("AllReferenced") and not rt.read("HomingActive"), 30)
        assert rt.read("ReferencedAxes") == 0b111
        texts = [t for _, t in m.controller.events]
        assert "homing Z then X Y" in texts and "homed Z X Y" in texts, texts
        fb = m.axes.feedback()
        # at the reference point (home_mm = 0) within the creep's stopping distance
        assert all(abs(fb.actual[a]) < 0.05 for a in "XYZ"), fb.actual
        rt.write_once("RemModeReq", 1)
        n = m.load_program(SHORT)
        rt.write_once("RemProgNumber", n)
        rt.write_once("RemProgSelect", True)
        assert m.run_until(lambda m: rt.read("ProgSelected"), 1.0)
        assert m.controller.mode == "AUTO" and rt.read("ActiveProgram") == n
        assert m.alarms == () and rt.alarms == {}
    finally:
        m.close()


@pytest.mark.parametrize(
    ("env", "arg", "expected"),
    [({}, None, 0), ({"FMSCELL_MACHINE_RT_PRIORITY": "30"}, None, 30), ({}, 12, 12)],
)
def test_realtime_runner_takes_its_fifo_priority_from_the_argument_or_the_environment(
    monkeypatch, env, arg, expected
):
    from cnc.machine import RealtimeRunner

    monkeypatch.delenv("FMSCELL_MACHINE_RT_PRIORITY", raising=False)
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    m = build(ideal=True)
    try:
        assert RealtimeRunner(m, rt_priority=arg).rt_priority == expected
    finally:
        m.close()


@pytest.mark.parametrize("bad", ["-1", "100", "high"])
def test_a_malformed_machine_rt_priority_is_refused_naming_the_variable(monkeypatch, bad):
    from cnc.machine.runner import rt_priority_from_env

    with pytest.raises(ValueError, match="FMSCELL_MACHINE_RT_PRIORITY"):
        rt_priority_from_env({"FMSCELL_MACHINE_RT_PRIORITY": bad})


def test_the_realtime_runner_reports_a_refused_fifo_and_runs_on(monkeypatch):
    """Without the privilege the runner says so in its summary and still paces."""
    import cnc.machine.runner as runner_mod
    from cnc.machine import RealtimeRunner

    refused = "SCHED_OTHER (SCHED_FIFO 20 refused: Operation not permitted)"
    monkeypatch.setattr(runner_mod, "request_fifo", lambda priority: refused)
    m = build(ideal=True)
    try:
        runner = RealtimeRunner(m, rt_priority=20)
        summary = runner.run(duration_s=0.05)
        assert summary["scheduling"] == refused and summary["cycles"] > 0
    finally:
        m.close()


@pytest.mark.parametrize("kwargs", [{"speed": 10.0}, {"speed": 1000.0, "idle_speed": 4.0}])
def test_the_fast_clock_takes_no_fifo_and_leaves_the_collector_alone(monkeypatch, kwargs):
    """A runner that does not sleep must not hold a CPU at SCHED_FIFO, nor freeze the
    process's garbage collector waiting for a slack that never comes."""
    import gc

    import cnc.machine.runner as runner_mod
    from cnc.machine import RealtimeRunner

    asked = []
    monkeypatch.setattr(runner_mod, "request_fifo", lambda priority: asked.append(priority))
    m = build(ideal=True)
    try:
        threshold = gc.get_threshold()
        summary = RealtimeRunner(m, rt_priority=20, **kwargs).run(duration_s=0.02)
        assert asked == [] and "not applied" in summary["scheduling"]
        assert gc.get_threshold() == threshold and summary["cycles"] > 0
    finally:
        m.close()


def test_an_idle_machine_paced_at_real_time_collects_the_old_generation(monkeypatch):
    """The pacing collects only young generations in a cycle's slack; an idle machine
    also gets full collections, so a long-running machine process keeps no cyclic garbage."""
    import cnc.machine.runner as runner_mod
    from cnc.machine import RealtimeRunner

    monkeypatch.setattr(runner_mod, "OLD_GENERATION_EVERY_S", 0.0)
    m = build(ideal=True)
    try:
        assert m.status.execution not in runner_mod.BUSY
        summary = RealtimeRunner(m).run(duration_s=0.02)
        assert summary["old_generation_collections"] > 0
    finally:
        m.close()


def test_the_realtime_runner_collects_before_fifo_and_gives_fifo_back(monkeypatch):
    """The setup's collection runs at the ordinary priority (at FIFO it would hold the CPU
    from the other machines' cycles), and the thread leaves run() at the priority it came
    with, so the summary and whatever follows do not run at FIFO."""
    import os
    import threading

    import cnc.machine.runner as runner_mod
    from cnc.machine import RealtimeRunner
    from drives.realtime import RealtimeProcess, request_fifo

    at_promotion = []
    users = RealtimeProcess._users  # another test's drives may still hold it in this worker

    def promote(priority: int) -> str:
        at_promotion.append((RealtimeProcess._users > users, os.sched_getscheduler(0)))
        return request_fifo(priority)

    monkeypatch.setattr(runner_mod, "request_fifo", promote)
    m = build(ideal=True)
    out: dict = {}

    def run() -> None:
        out["summary"] = RealtimeRunner(m, rt_priority=20).run(duration_s=0.02)
        out["after"] = os.sched_getscheduler(0)

    try:
        thread = threading.Thread(target=run)
        thread.start()
        thread.join(30)
        assert at_promotion == [(True, os.SCHED_OTHER)]  # collected and frozen, not yet FIFO
        assert out["summary"]["cycles"] > 0 and RealtimeProcess._users == users
        if not out["summary"]["scheduling"].startswith("SCHED_FIFO"):
            pytest.skip(f"no realtime privilege here: {out['summary']['scheduling']}")
        assert out["after"] == os.SCHED_OTHER
    finally:
        m.close()


@pytest.mark.parametrize("speed", [1.0, 10.0])
def test_prepare_holds_the_realtime_settings_only_for_a_paced_run(speed):
    """prepare() collects and freezes ahead of run(), once however often it is called; a
    run that is not paced (the clock sped up meanwhile) lets them go, as a paced run does
    when it ends."""
    import gc

    from cnc.machine import RealtimeRunner
    from drives.realtime import RealtimeProcess

    users = RealtimeProcess._users  # another test's drives may still hold it in this worker
    m = build(ideal=True)
    try:
        runner = RealtimeRunner(m)
        runner.prepare()
        runner.prepare()
        assert RealtimeProcess._users == users + 1 and gc.get_freeze_count() > 0
        runner.speed = speed
        assert runner.run(duration_s=0.02)["cycles"] > 0
        assert RealtimeProcess._users == users
        fast = RealtimeRunner(m, speed=10.0)
        fast.prepare()  # nothing to prepare for a sped-up clock
        assert RealtimeProcess._users == users
    finally:
        m.close()
