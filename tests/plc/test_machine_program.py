"""Machine-tool PLC program scenarios, in lockstep: the Runtime is scanned every 10 ms of
virtual time and the simulated machine (MachineIO) follows the same time, so every finish
and every timeout lands on an exact scan."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from plc.machine_io import MachineParams, machine_plc
from plc.signals import MODE_AUTO, MODE_JOG, MODE_MDI, PLC_TO_FIELD, signals

PERIOD = 10
P = MachineParams()
ACTUATORS = [s.name for s in signals(PLC_TO_FIELD) if s.name != "AlarmLamp"]
ARM_MS = sum(ms for _, ms in P.arm_ms)


def arrival_ms(rpm_from: int, rpm_to: int) -> int:
    """Ramp time until the drive reports speed arrival, rounded up to whole scans."""
    tolerance = max(P.at_speed_tolerance_rpm, abs(rpm_to) * 0.02)
    ms = (abs(rpm_to - rpm_from) - tolerance) * 1000 / P.spindle_accel_rpm_per_s
    return math.ceil(ms / PERIOD) * PERIOD


class Plc:
    """The program, its plant and the NC side, stepped together."""

    def __init__(self, params: MachineParams | None = None) -> None:
        self.rt, self.io = machine_plc(params=params)
        # virtual time only: a scan the busy test host preempts must not trip the watchdog
        self.rt.clock_ns = lambda: 0
        self.nc = self.io.nc
        self.now = 0  # time of the next scan
        self.last = None  # time of the last scan

    def scan(self) -> None:
        self.rt.scan(self.now)
        self.last = self.now
        self.now += PERIOD

    def run(self, ms: int) -> None:
        for _ in range(ms // PERIOD):
            self.scan()

    def until(self, pred: Callable[[], bool], limit_ms: int) -> int:
        """Scan until `pred()` holds after a scan; the time of that scan."""
        end = self.now + limit_ms
        while self.now <= end:
            self.scan()
            if pred():
                return self.last
        raise AssertionError(f"condition not reached within {limit_ms} ms")

    def read(self, name: str):
        return self.rt.read(name)

    def ready(self, mode: int = MODE_AUTO) -> None:
        self.nc.set("NcReady", True)
        self.nc.set("NcMode", mode)
        self.run(P.drive_ready_ms + 100)
        assert self.rt.alarms == {}

    def strobe(self, code: str, value: int) -> int:
        """Set a code and raise its strobe; returns the time of the scan that sees it."""
        self.nc.set(code[0] + "Code", value)
        self.nc.set(code[0] + "Strobe", True)
        return self.now

    def function(self, kind: str, value: int, limit_ms: int = 15000) -> int:
        """One complete M/S/T handshake; returns strobe -> finish time in ms."""
        t0 = self.strobe(kind, value)
        fin = kind + "Finish"
        t1 = self.until(lambda: self.nc.get(fin), limit_ms)
        self.nc.set(kind + "Strobe", False)
        self.scan()
        assert not self.nc.get(fin), "finish must drop with the strobe"
        return t1 - t0

    def spindle_on(self, rpm: int = 3000) -> None:
        self.nc.set("SCode", rpm)
        self.function("M", 3)


@pytest.fixture
def plc() -> Plc:
    p = Plc()
    p.ready()
    return p


def test_power_on_state(plc):
    out = plc.nc.outputs()
    assert out["PlcReady"] and out["AxisEnable"] and not out["EStopActive"]
    assert out["FeedOverride"] == out["RapidOverride"] == out["SpindleOverride"] == 100
    assert out["PlcAlarmNumber"] == 0 and not out["PlcAlarm"]
    assert plc.io.output("SpindleEnable") and plc.io.input("SpindleDriveReady")


def test_plc_ready_is_off_in_the_first_scan():
    p = Plc()
    p.scan()
    assert not p.nc.get("PlcReady")
    p.scan()
    assert p.nc.get("PlcReady")


def test_m3_finishes_exactly_when_the_spindle_is_at_speed(plc):
    plc.nc.set("SCode", 3000)
    t0 = plc.strobe("M", 3)
    t_fwd = plc.until(lambda: plc.io.output("SpindleFwd"), 1000)
    # the door locks first; the spindle runs once the bolt is engaged
    assert t_fwd - t0 == P.door_lock_ms
    assert plc.io.output("DoorLock")
    t_fin = plc.until(lambda: plc.nc.get("MFinish"), 2000)
    assert t_fin - t_fwd == arrival_ms(0, 3000)
    assert plc.nc.get("SpindleAtSpeed")
    plc.run(100)
    assert plc.nc.get("MFinish"), "finish is held until the NC drops the strobe"
    plc.nc.set("MStrobe", False)
    plc.scan()
    assert not plc.nc.get("MFinish")
    assert plc.io.output("SpindleSpeedRef") == 3000


def test_m4_m5_and_m19(plc):
    plc.spindle_on(2000)
    assert plc.function("M", 4) == arrival_ms(2000, -2000)
    assert plc.io.output("SpindleRev") and not plc.io.output("SpindleFwd")
    assert plc.function("M", 5) == 200  # below the 10 rpm zero-speed threshold
    assert plc.io.input("SpindleZeroSpeed")
    # the door unlocked at standstill: orientation waits for the bolt again
    assert plc.function("M", 19) == P.door_lock_ms + P.orient_ms
    assert plc.io.input("SpindleOriented") and plc.io.output("SpindleOrient")
    plc.spindle_on(1000)
    assert not plc.io.output("SpindleOrient")


@pytest.mark.parametrize(
    ("code", "expected_ms"),
    [(8, P.coolant_pressure_ms), (7, 50), (9, 50), (0, 50), (1, 50)],
)
def test_coolant_and_program_stop_codes(plc, code, expected_ms):
    assert plc.function("M", code) == expected_ms
    if code == 8:
        assert plc.io.output("CoolantPump") and plc.io.input("CoolantPressureOk")
    if code == 7:
        assert plc.io.output("CoolantMist")


def test_m13_and_m14_spindle_with_coolant(plc):
    plc.nc.set("SCode", 1000)
    # the door lock (100 ms) and the ramp (to within 20 rpm: 98 ms) run after one another;
    # the coolant pressure (400 ms) is the longer branch
    assert plc.function("M", 13) == P.coolant_pressure_ms
    assert plc.io.output("SpindleFwd") and plc.io.output("CoolantPump")
    assert plc.function("M", 14) == arrival_ms(1000, -1000)
    assert plc.io.output("SpindleRev") and plc.io.output("CoolantPump")


def test_m9_and_m30_switch_the_coolant_off(plc):
    plc.function("M", 8)
    plc.function("M", 7)
    plc.function("M", 9)
    assert not plc.io.output("CoolantPump") and not plc.io.output("CoolantMist")
    plc.function("M", 8)
    plc.spindle_on(1000)
    plc.function("M", 30)
    assert not plc.io.output("CoolantPump") and not plc.io.output("SpindleFwd")


def test_speed_reference_applies_the_override_and_the_limits(plc):
    plc.spindle_on(3333)
    plc.rt.write_once("RemSpindleOvr", 90)
    plc.run(20)
    assert plc.io.output("SpindleSpeedRef") == 2999  # 3333 x 0.9, truncated
    plc.rt.write_once("RemSpindleOvr", 150)
    plc.nc.set("SCode", 10000)
    plc.run(20)
    assert plc.io.output("SpindleSpeedRef") == 12000  # machine limit
    plc.rt.write_once("RemSpindleOvr", 500)
    plc.rt.write_once("RemFeedOvr", -5)
    plc.rt.write_once("RemRapidOvr", 250)
    plc.run(20)
    assert plc.nc.get("SpindleOverride") == 200
    assert plc.nc.get("FeedOverride") == 0
    assert plc.nc.get("RapidOverride") == 200


def test_s_function_finishes_at_the_new_speed(plc):
    assert plc.function("S", 2000) == 50  # spindle off: nothing to wait for
    plc.spindle_on(2000)
    assert plc.function("S", 5000) == arrival_ms(2000, 5000)


# --- M6 -------------------------------------------------------------------------------------


def test_m6_sequence_end_to_end_with_exact_timing(plc):
    # T7 pre-positions the carousel from pocket 1: 6 pockets
    assert plc.function("T", 7) == 6 * P.pocket_index_ms
    assert plc.io.state.carousel_pocket == 7 and plc.nc.get("PreparedTool") == 7
    steps, arm_cmds = [], []
    t0 = plc.strobe("M", 6)

    def watch() -> bool:
        step = plc.read("ToolStep")
        if not steps or steps[-1][0] != step:
            steps.append((step, plc.last - t0))
        cmd = [n for n in ("ArmToGrip", "ArmToExtract", "ArmToSwap", "ArmToInsert", "ArmToHome")
               if plc.io.output(n)]  # fmt: skip
        if cmd and (not arm_cmds or arm_cmds[-1] != cmd[0]):
            arm_cmds.append(cmd[0])
        return plc.nc.get("MFinish")

    t_fin = plc.until(watch, 10000)
    # the spindle stands still and the door is unlocked: lock, orient, then the arm (the
    # carousel is at the pocket already, so step 20 passes in the scan that sees orientation)
    grip, extract, swap, insert, home = (ms for _, ms in P.arm_ms)
    o = P.door_lock_ms + P.orient_ms
    assert steps == [
        (10, 0),
        (30, o),
        (40, o + grip),
        (50, o + grip + extract),
        (60, o + grip + extract + swap),
        (70, o + grip + extract + swap + insert),
        (90, o + ARM_MS),
    ]
    assert t_fin - t0 == o + ARM_MS
    assert arm_cmds == ["ArmToGrip", "ArmToExtract", "ArmToSwap", "ArmToInsert", "ArmToHome"]
    assert plc.nc.get("ToolInSpindle") == 7 and plc.io.state.tool_in_spindle == 7
    assert plc.io.state.pockets[6] == 0  # the spindle was empty
    assert plc.io.state.crashes == []
    assert plc.io.output("DoorLock"), "the door stays locked during a tool change"
    plc.nc.set("MStrobe", False)
    plc.scan()
    assert plc.read("ToolStep") == 0 and not plc.nc.get("MFinish")
    assert plc.rt.alarms == {}


def test_m6_from_a_turning_spindle_returns_the_old_tool(plc):
    plc.function("T", 7)
    plc.function("M", 6)
    plc.spindle_on(2000)
    # T3 from pocket 7: 4 pockets back, while the spindle keeps cutting
    assert plc.function("T", 3) == 4 * P.pocket_index_ms
    assert plc.io.output("SpindleFwd")
    t0 = plc.strobe("M", 6)
    t_zero = plc.until(lambda: plc.io.input("SpindleZeroSpeed"), 1000)
    t_orient = plc.until(lambda: plc.io.input("SpindleOriented"), 1000)
    t_fin = plc.until(lambda: plc.nc.get("MFinish"), 5000)
    assert t_zero - t0 == 200  # 2000 rpm down to below 10 rpm at 10000 rpm/s
    # the door is still locked (the spindle turned); orientation counts from the plant step
    # that reached zero speed, one scan before the scan that sees it
    assert t_orient - t_zero == P.orient_ms - PERIOD
    assert t_fin - t_orient == ARM_MS
    assert plc.io.state.tool_in_spindle == 3 and plc.nc.get("ToolInSpindle") == 3
    assert plc.io.state.pockets[2] == 7, "tool 7 went into pocket 3"
    assert not plc.io.output("SpindleFwd"), "M6 leaves the spindle stopped"
    assert plc.io.state.crashes == []


def test_m6_with_the_tool_already_in_the_spindle_finishes_at_once(plc):
    plc.function("T", 4)
    plc.function("M", 6)
    plc.function("T", 4)
    assert plc.function("M", 6) == 50  # only the settle delay
    assert plc.io.state.tool_in_spindle == 4


def test_t_and_m6_in_one_block(plc):
    """A "T11 M06" block: both strobes in the same scan. The T is taken first; the carousel turns
    while the spindle orients, and the arm waits for it."""
    plc.nc.set("TCode", 11)
    plc.nc.set("TStrobe", True)
    t0 = plc.strobe("M", 6)
    t_t = plc.until(lambda: plc.nc.get("TFinish"), 5000)
    plc.nc.set("TStrobe", False)
    t_m = plc.until(lambda: plc.nc.get("MFinish"), 5000)
    assert t_t - t0 == 10 * P.pocket_index_ms
    assert t_m - t0 == 10 * P.pocket_index_ms + ARM_MS
    assert plc.io.state.tool_in_spindle == 11 and plc.io.state.crashes == []


# --- timeouts ------------------------------------------------------------------------------

TIMEOUTS = [
    # fault, M code, alarm, ms from the strobe's scan to the alarm's scan
    ("spindle_stall", 3, 1003, P.door_lock_ms + 10000),
    ("orient_fail", 19, 1004, 5000),
    ("coolant_pump_fail", 8, 1006, 3000),
    ("door_lock_fail", 3, 1031, 1000),
]


@pytest.mark.parametrize(("fault", "code", "alarm", "after_ms"), TIMEOUTS)
def test_m_function_timeout_raises_its_alarm(plc, fault, code, alarm, after_ms):
    plc.io.inject(fault)
    plc.nc.set("SCode", 3000)
    t0 = plc.strobe("M", code)
    t_alarm = plc.until(lambda: alarm in plc.rt.alarms, after_ms + 1000)
    assert t_alarm - t0 == after_ms
    assert not plc.nc.get("MFinish")
    assert plc.nc.get("PlcAlarm") and plc.nc.get("PlcAlarmNumber") == alarm
    assert plc.rt.alarms[alarm].text
    # reset with the fault still there: the alarm is cleared, the request dropped
    plc.io.clear(fault)
    plc.nc.set("MStrobe", False)
    plc.io.press("PanelReset")
    plc.scan()
    assert plc.nc.get("NcReset")
    plc.io.release("PanelReset")
    plc.scan()
    assert alarm not in plc.rt.alarms and not plc.nc.get("PlcAlarm")
    assert not plc.io.output("SpindleFwd") and not plc.io.output("CoolantPump")


def test_generic_m_finish_timeout_after_30_s(plc):
    plc.io.inject("orient_fail")
    t0 = plc.strobe("M", 19)
    t_alarm = plc.until(lambda: 1020 in plc.rt.alarms, 31000)
    assert t_alarm - t0 == 30000
    assert set(plc.rt.alarms) == {1004, 1020}
    assert plc.nc.get("PlcAlarmNumber") == 1004  # lowest number first


def test_unknown_m_code_raises_an_alarm_and_is_never_finished(plc):
    plc.strobe("M", 55)
    plc.run(100)
    assert 1021 in plc.rt.alarms and not plc.nc.get("MFinish")


def test_tool_change_orient_timeout(plc):
    plc.function("T", 9)
    plc.io.inject("orient_fail")
    t0 = plc.strobe("M", 6)
    assert plc.until(lambda: 1010 in plc.rt.alarms, 6000) - t0 == 5000
    assert not plc.nc.get("MFinish") and plc.nc.get("PlcAlarmNumber") == 1010


def test_tool_change_arm_timeout(plc):
    plc.function("T", 9)
    plc.io.inject("arm_jam")
    t0 = plc.strobe("M", 6)
    t_grip = plc.until(lambda: plc.io.output("ArmToGrip"), 1000)
    assert t_grip - t0 == P.door_lock_ms + P.orient_ms
    assert plc.until(lambda: 1012 in plc.rt.alarms, 3000) - t_grip == 2000
    assert not plc.nc.get("MFinish")


def test_tool_change_carousel_timeout(plc):
    plc.io.inject("carousel_jam")
    plc.nc.set("TCode", 9)
    plc.nc.set("TStrobe", True)
    t0 = plc.strobe("M", 6)
    assert plc.until(lambda: 1017 in plc.rt.alarms, 6000) - t0 == 5000  # T not finished
    # step 20 began when the spindle was oriented
    t_alarm = plc.until(lambda: 1011 in plc.rt.alarms, 6000)
    assert t_alarm - t0 == P.door_lock_ms + P.orient_ms + 5000
    assert not plc.nc.get("MFinish") and not plc.nc.get("TFinish")


def test_t_function_with_a_bad_tool_number(plc):
    plc.strobe("T", 21)
    plc.run(50)
    assert 1018 in plc.rt.alarms and not plc.nc.get("TFinish")


def test_t_function_timeout(plc):
    plc.io.inject("carousel_jam")
    t0 = plc.strobe("T", 5)
    t_alarm = plc.until(lambda: 1017 in plc.rt.alarms, 6000)
    assert t_alarm - t0 == 5000


# --- door, E-stop, air, lubrication ---------------------------------------------------------


def test_door_opened_mid_cycle_feed_hold_and_spindle_stop_in_the_same_scan(plc):
    plc.spindle_on(3000)
    plc.function("M", 8)
    plc.nc.set("NcInCycle", True)
    plc.run(50)
    assert not plc.io.open_door(), "the lock holds the door while the spindle turns"
    assert plc.io.output("SpindleFwd") and not plc.nc.get("FeedHold")
    plc.io.inject("door_open")  # the lock is defeated
    plc.scan()
    assert plc.nc.get("FeedHold")
    assert not plc.io.output("SpindleFwd") and not plc.io.output("CoolantPump")
    assert 1030 in plc.rt.alarms and not plc.nc.get("DoorClosed")
    assert plc.io.output("SpindleSpeedRef") == 3000  # the request stays for the restart
    # cycle start is refused while the door is open
    plc.io.press("PanelCycleStart")
    plc.scan()
    assert not plc.nc.get("CycleStart") and plc.read("CycleStartRefused")
    plc.io.release("PanelCycleStart")
    plc.io.clear("door_open")
    plc.scan()
    t_closed = plc.last
    assert 1030 not in plc.rt.alarms and plc.nc.get("FeedHold")
    assert plc.io.output("DoorLock"), "the closed door locks at once: the spindle is requested"
    plc.io.press("PanelCycleStart")
    plc.scan()
    t_start = plc.last
    assert plc.nc.get("CycleStart") and not plc.nc.get("FeedHold")
    assert plc.io.output("CoolantPump"), "coolant resumes with the start"
    plc.io.release("PanelCycleStart")
    # the spindle restarts once the door is locked again; the NC waits for SpindleAtSpeed
    t = plc.until(lambda: plc.io.output("SpindleFwd"), 1000)
    assert t - t_closed == P.door_lock_ms and t > t_start


def test_door_opened_in_jog_stops_the_spindle_without_feed_hold():
    p = Plc()
    p.ready(MODE_JOG)
    p.spindle_on(1000)
    p.io.inject("door_open")
    p.scan()
    assert not p.io.output("SpindleFwd") and not p.nc.get("FeedHold")
    assert 1030 not in p.rt.alarms


def test_door_unlocks_once_the_spindle_has_stopped(plc):
    plc.spindle_on(1000)
    plc.function("M", 5)
    plc.scan()
    assert not plc.io.output("DoorLock")
    plc.scan()
    assert plc.io.open_door()
    plc.scan()
    assert not plc.nc.get("DoorClosed")


def test_estop_drops_every_output_in_the_same_scan_and_needs_a_closed_chain(plc):
    plc.spindle_on(3000)
    plc.function("M", 8)
    plc.function("T", 5)
    assert any(plc.io.output(n) for n in ACTUATORS)
    plc.io.press_estop()
    plc.scan()
    assert [n for n in ACTUATORS if plc.io.output(n)] == []
    assert plc.nc.get("EStopActive") and not plc.nc.get("AxisEnable")
    assert plc.nc.get("FeedHold") and 1001 in plc.rt.alarms
    assert plc.io.output("AlarmLamp")
    # reset with the chain still open: refused
    plc.io.press("PanelReset")
    plc.run(50)
    plc.io.release("PanelReset")
    plc.scan()
    assert plc.nc.get("EStopActive") and 1001 in plc.rt.alarms
    plc.io.release_estop()
    plc.run(50)
    assert plc.nc.get("EStopActive"), "a closed chain alone does not reset"
    plc.io.press("PanelReset")
    plc.scan()
    plc.io.release("PanelReset")
    plc.scan()
    assert not plc.nc.get("EStopActive") and plc.nc.get("AxisEnable")
    assert 1001 not in plc.rt.alarms
    plc.run(500)
    assert not plc.io.output("SpindleFwd") and not plc.io.output("CoolantPump"), (
        "nothing restarts by itself after an E-stop"
    )


def test_estop_chain_fault_and_nc_reset(plc):
    plc.io.inject("estop_chain")
    plc.scan()
    assert plc.nc.get("EStopActive")
    plc.io.clear("estop_chain")
    plc.nc.set("NcResetting", True)
    plc.scan()
    plc.nc.set("NcResetting", False)
    plc.scan()
    assert not plc.nc.get("EStopActive")
    assert not plc.nc.get("NcReset"), "an NC reset is not echoed back to the NC"


def test_air_pressure_loss_gives_feed_hold_and_an_alarm_in_the_same_scan(plc):
    plc.nc.set("NcInCycle", True)
    plc.run(50)
    plc.io.inject("air_pressure_loss")
    plc.scan()
    assert plc.nc.get("FeedHold") and 1040 in plc.rt.alarms
    assert plc.nc.get("PlcAlarmNumber") == 1040
    plc.io.clear("air_pressure_loss")
    plc.run(50)
    assert plc.nc.get("FeedHold") and 1040 in plc.rt.alarms, "held until reset"
    plc.io.press("PanelCycleStart")
    plc.scan()
    assert not plc.nc.get("CycleStart"), "no start with an alarm active"
    plc.io.release("PanelCycleStart")
    plc.io.press("PanelReset")
    plc.scan()
    plc.io.release("PanelReset")
    plc.scan()
    assert 1040 not in plc.rt.alarms and not plc.nc.get("FeedHold")


def test_coolant_pressure_lost_while_running(plc):
    plc.function("M", 8)
    plc.io.inject("coolant_pump_fail")
    t0 = plc.now
    t = plc.until(lambda: 1006 in plc.rt.alarms, 4000)
    assert t - t0 == 3000


def test_lubrication_pulses_and_its_alarms():
    p = Plc()
    p.nc.set("NcReady", True)
    p.nc.set("NcMode", MODE_AUTO)
    # the first pulse runs at power-on for 2 s, then one every 30 s
    pulses, was = [], False
    for _ in range(6500):
        p.scan()
        on = p.io.output("LubePump")
        if on and not was:
            pulses.append(p.last)
        was = on
    # 2 s pulse + 30 s pause; after the first pulse (latched before its timer rung) the pulse
    # timer starts one scan after the latch, so later periods are 32 s + 1 scan
    assert pulses == [0, 32000, 64000 + PERIOD]
    assert p.rt.alarms == {}
    p.io.inject("lube_pump_fail")
    t = p.until(lambda: 1042 in p.rt.alarms, 40000)
    assert t == 64000 + PERIOD + 2000 + PERIOD  # at the end of the running third pulse
    p.io.inject("lube_level_low")
    p.scan()
    assert 1041 in p.rt.alarms
    p.io.press("PanelCycleStart")
    p.scan()
    assert not p.nc.get("CycleStart")


def test_spindle_drive_not_ready_alarm():
    p = Plc()
    p.io.inject("spindle_drive_fault")
    p.nc.set("NcReady", True)
    t = p.until(lambda: 1002 in p.rt.alarms, 2000)
    assert t == 1000  # enabled and supervised from the first scan


# --- cycle start, feed hold, modes -------------------------------------------------------------


@pytest.mark.parametrize(
    ("mode", "ready", "accepted"),
    [(MODE_AUTO, True, True), (MODE_MDI, True, True), (MODE_JOG, True, False),
     (MODE_AUTO, False, False)],
)  # fmt: skip
def test_cycle_start_interlocks(mode, ready, accepted):
    p = Plc()
    p.ready(mode)
    p.nc.set("NcReady", ready)
    p.io.press("PanelCycleStart")
    p.scan()
    assert p.nc.get("CycleStart") is accepted
    assert p.read("CycleStartRefused") is (not accepted)


def test_feed_hold_latches_until_cycle_start(plc):
    plc.io.press("PanelFeedHold")
    plc.scan()
    plc.io.release("PanelFeedHold")
    plc.run(50)
    assert plc.nc.get("FeedHold")
    plc.io.press("PanelCycleStart")
    plc.scan()
    assert plc.nc.get("CycleStart") and not plc.nc.get("FeedHold")


def test_mode_requests(plc):
    plc.rt.write_once("RemModeReq", MODE_MDI)
    plc.scan()
    assert plc.nc.get("ModeSelect") == MODE_MDI and plc.read("RemModeReq") == 0
    plc.nc.set("NcInCycle", True)
    plc.rt.write_once("RemModeReq", MODE_JOG)
    plc.scan()
    assert plc.nc.get("ModeSelect") == MODE_MDI and plc.read("ModeRefused")
    plc.nc.set("NcInCycle", False)
    plc.rt.write_once("RemModeReq", 9)
    plc.scan()
    assert plc.nc.get("ModeSelect") == MODE_MDI and plc.read("ModeRefused")


def test_lockstep_runs_are_identical():
    def trace() -> list:
        p = Plc()
        p.ready()
        p.function("T", 6)
        p.spindle_on(4000)
        p.function("M", 8)
        p.function("M", 6)
        out = []
        for _ in range(100):
            p.scan()
            out.append((p.rt.snapshot.qx[:40], p.rt.snapshot.qw[:10], p.io.state.spindle_rpm))
        return out + [sorted(p.rt.alarms)]

    assert trace() == trace()


def test_with_the_input_filter_an_estop_counts_at_the_fourth_sample():
    """RuntimeConfig(debounce_samples=4) (the GE 1050 filter): the E-stop is seen, and every
    actuator dropped, in the scan of the 4th identical sample; a 3-scan glitch is ignored."""
    from plc.runtime import RuntimeConfig

    p = Plc()
    p.rt, p.io = machine_plc(RuntimeConfig(debounce_samples=4))
    p.nc = p.io.nc
    p.run(100)  # the filter starts from all-zero inputs: the chain reads open at first
    assert p.nc.get("EStopActive") and p.io.input("EStopChainOk")
    p.io.press("PanelReset")  # so the power-on E-stop is reset like on a real machine
    p.run(40)
    p.io.release("PanelReset")
    p.run(40)
    p.nc.set("NcReady", True)
    p.run(300)
    assert not p.nc.get("EStopActive") and p.io.output("SpindleEnable")
    p.io.press_estop()
    p.run(30)
    p.io.release_estop()
    p.run(50)
    assert not p.nc.get("EStopActive"), "a 3-sample glitch never reaches the logic"
    p.io.press_estop()
    for _ in range(3):
        p.scan()
        assert p.io.output("SpindleEnable")
    p.scan()
    assert p.nc.get("EStopActive") and [n for n in ACTUATORS if p.io.output(n)] == []


@pytest.mark.parametrize("abort", ["estop", "panel_reset", "nc_reset", "remote_reset"])
@pytest.mark.parametrize(("kind", "value"), [("M", 3), ("M", 8), ("T", 12), ("M", 6)])
def test_handshake_aborted_by_estop_or_reset_and_then_repeated(kind, value, abort):
    p = Plc()
    p.ready()
    if (kind, value) == ("M", 6):
        p.function("T", 5)
    p.nc.set("SCode", 2000)
    p.strobe(kind, value)
    p.run(200)  # mid-function: door locking / ramping / pumping / indexing / orienting
    assert not p.nc.get(kind + "Finish")
    if abort == "estop":
        p.io.press_estop()
    elif abort == "panel_reset":
        p.io.press("PanelReset")
    elif abort == "nc_reset":
        p.nc.set("NcResetting", True)
    else:
        p.rt.write_once("RemReset", True)
    p.scan()
    assert not p.nc.get(kind + "Finish")
    assert [n for n in ("SpindleFwd", "CoolantPump", "CarouselGo", "SpindleOrient")
            if p.io.output(n)] == []  # fmt: skip
    assert p.read("ToolStep") == 0
    p.nc.set(kind + "Strobe", False)  # the NC abandons the function
    p.io.release_estop()
    p.io.release("PanelReset")
    p.nc.set("NcResetting", False)
    p.run(50)
    if abort == "estop":
        assert 1001 in p.rt.alarms
        p.io.press("PanelReset")
        p.scan()
        p.io.release("PanelReset")
        p.run(300)  # the drive is ready again 200 ms after the enable
    assert p.rt.alarms == {}
    p.function(kind, value)  # the same function again, to its finish
    assert p.rt.alarms == {} and p.io.state.crashes == []
