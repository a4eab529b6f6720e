"""The host's view of a machine that lost its reference, through the real chain: a lockstep
machine's status -> its SHDR lines -> the MTConnect agent -> the monitoring model. A machine
that is not homed is not idle for the scheduler, and a refused cycle start is reported with
the NC's reason at once (not as a silent timeout)."""

from __future__ import annotations

import pytest

from cnc.config import builtin_machine
from cnc.faces.shdr import ShdrFormatter
from cnc.machine import Machine
from dnc.scheduler import ALARM, IDLE
from mtconnect.agent import Agent
from mtconnect.model import build_device
from server.host import MonitoringModel, StartRefused, make_starter, start_refused_text
from server.supervisor import MachineLink

PROGRAM = "%\nO0100\nG90 G0 X-100 Y-100 Z-20\nM30\n%\n"


class Cell:
    """One lockstep machine whose status reaches an agent as SHDR lines."""

    def __init__(self) -> None:
        self.m = Machine(builtin_machine("mill3"), "m1")
        axes = self.m.axis_names
        self.fmt = ShdrFormatter(axes)
        self.agent = Agent([build_device("m1", axes)], ignore_timestamps=True)
        self.agent.connected("m1")
        self.prev = None
        self.link = MachineLink("m1", "mill", "127.0.0.1", {}, axes, 1 << 20, local=self.m)
        self.monitor = MonitoringModel(self.agent, {"m1": self.link})

    def publish(self) -> None:
        state = self.fmt.state(self.m.full_status())
        for line in self.fmt.diff_states(self.prev, state, "2026-01-01T00:00:00Z"):
            self.agent.ingest_line("m1", line)
        self.prev = state

    def step(self, n: int) -> None:
        self.m.step(n)
        self.publish()


@pytest.fixture
def cell():
    c = Cell()
    yield c
    c.m.close()


def lockstep_starter(cell, monkeypatch):
    """The host's starter for m1, its link's program select and panel press stepping the
    lockstep machine instead of going over Modbus."""
    m = cell.m

    def select_program(n: int, timeout_s: float = 20.0) -> None:
        m.command("select_program", number=n)
        cell.step(5)

    def panel(action: str, value=None) -> None:
        assert action == "cycle_start"
        m.press("PanelCycleStart")
        cell.step(3 * m.plc_every)

    monkeypatch.setattr(cell.link, "select_program", select_program)
    monkeypatch.setattr(cell.link, "panel", panel)
    return make_starter({"m1": cell.link}, cell.monitor, timeout_s=30.0)


def test_unreferenced_machine_is_not_idle_and_says_which_axes(cell):
    m = cell.m
    m.command("mode", mode="AUTO")
    cell.step(50)
    s = cell.monitor.status("m1")
    assert s["referenced"] is False and s["unreferenced_axes"] == ["X", "Y", "Z"]
    assert s["mode"] == "AUTOMATIC" and s["execution"] == "READY" and not s["alarms"]
    # READY, AUTO, no alarm before the first homing: still not for the cell
    assert cell.monitor.state("m1") == ALARM
    m.power_on()
    cell.publish()
    s = cell.monitor.status("m1")
    assert s["referenced"] is True and s["unreferenced_axes"] == []
    assert cell.monitor.state("m1") == IDLE


def test_a_drive_that_loses_its_position_drops_the_reference_until_homed(cell):
    m = cell.m
    m.power_on()
    cell.publish()
    assert cell.monitor.state("m1") == IDLE
    m.inject("drive:Y:power_cycle")
    cell.step(50)
    m.press("PanelReset")
    cell.step(50)
    s = cell.monitor.status("m1")
    assert not [a for a in s["alarms"] if a["level"] == "FAULT"], s["alarms"]
    assert s["referenced"] is False and "Y" in s["unreferenced_axes"]
    assert cell.monitor.state("m1") == ALARM
    # the axes quick-stopped by the fault lost their reference: a warning each
    warnings = {(a["code"], a["text"]) for a in s["alarms"] if a["level"] == "WARNING"}
    assert ("3031", "axis Y not referenced: home the machine (REF mode, home)") in warnings


def test_a_refused_cycle_start_reports_the_ncs_reason_at_once(cell, monkeypatch):
    m = cell.m
    m.command("mode", mode="AUTO")
    number = m.load_program(PROGRAM)
    cell.step(10)

    start = lockstep_starter(cell, monkeypatch)
    with pytest.raises(StartRefused) as err:
        start("m1", number)
    assert "refused by the NC" in str(err.value)
    assert "machine not homed (X, Y, Z)" in str(err.value)
    # the reason is in the API's status too, until the next select or start
    assert "not homed" in cell.monitor.status("m1")["cycle_start_refused"]


def test_a_reconnected_machine_is_not_judged_before_it_reports_its_part_counter(cell):
    """After a reconnect the agent marks the adapter connected before its first lines: every
    value is UNAVAILABLE then. A part counter read as 0 there would look like a restarted
    control to the allocations (a counted part lost): the machine is not yet answering."""
    m = cell.m
    m.power_on()
    cell.publish()
    (view,) = cell.monitor.views()
    assert view.connected and view.part_count == 0
    cell.agent.disconnected("m1")
    cell.agent.connected("m1")  # the TCP connection is back, no line read yet
    (view,) = cell.monitor.views()
    assert not view.connected and view.look().connected is False
    cell.prev = None  # the adapter sends everything again on a new connection
    cell.publish()
    (view,) = cell.monitor.views()
    assert view.connected and view.part_count == 0


def test_after_a_jam_and_reset_the_machine_says_not_referenced_and_refuses_cycle_start(
    cell, monkeypatch
):
    """The `blocked` fault (a jammed slide) in a move: following error 3010, every axis
    quick-stopped. After the cause is gone and RESET, no FAULT alarm is left, but the machine
    is not READY for the cell: it says it is not referenced (3031 per axis, `referenced`
    false), the scheduler does not take it, and a cycle start is refused at once with the
    NC's reason instead of READY with no alarm and a silent 30 s "running not seen"."""
    m = cell.m
    m.power_on()
    number = m.load_program("%\nO0100\nG90 G1 X-200 Y-200 Z-50 F6000\nM30\n%\n")
    m.command("select_program", number=number)
    m.command("cycle_start")
    cell.step(250)  # 0.5 s into the move: every axis moving
    assert m.status.execution == "ACTIVE"
    m.inject("drive:Y:blocked")
    assert m.run_until(lambda m: any(a.number == 3010 for a in m.alarms), 1.0), m.alarms
    assert m.run_until(lambda m: m.status.execution != "ACTIVE", 5.0)
    cell.step(round(0.5 / m.ipo_s))  # the quick stop to a standstill
    m.clear_fault("drive:Y:blocked")  # the slide freed
    m.press("PanelReset")
    cell.step(5 * m.plc_every)

    s = cell.monitor.status("m1")
    assert not [a for a in s["alarms"] if a["level"] == "FAULT"], s["alarms"]
    assert s["referenced"] is False and s["unreferenced_axes"] == ["X", "Y", "Z"]
    # the NC raises 3031 per axis; through SHDR/MTConnect the conditions of one data item
    # are keyed by native code, so the host keeps one 3031 (the last axis's) beside
    # `unreferenced_axes`, which names them all
    nc = {(a.number, a.severity, a.text) for a in m.alarms}
    assert nc == {
        (3031, "WARNING", f"axis {axis} not referenced: home the machine (REF mode, home)")
        for axis in "XYZ"
    }
    warnings = [(a["code"], a["text"]) for a in s["alarms"] if a["level"] == "WARNING"]
    assert warnings and all(code == "3031" for code, _ in warnings), warnings
    assert all("not referenced: home the machine" in text for _, text in warnings)
    assert cell.monitor.state("m1") == ALARM  # not dispatched to

    start = lockstep_starter(cell, monkeypatch)
    t0 = m.t
    with pytest.raises(StartRefused) as err:
        start("m1", number)
    # the NC's reason once, not "refused by the NC: cycle start refused: ..." (docs/recovery.md)
    assert str(err.value) == (
        "m1: cycle start of O0100 refused by the NC: machine not homed (X, Y, Z)"
    )
    assert m.t - t0 < 1.0, "refused at once, not after the start's time-out"
    assert "machine not homed (X, Y, Z)" in cell.monitor.status("m1")["cycle_start_refused"]
    assert m.status.execution != "ACTIVE"


@pytest.mark.parametrize(
    ("reason", "said"),
    [
        ("cycle start refused: machine not homed (X)", "machine not homed (X)"),
        ("cycle start refused: alarm 1041 active (lubricant level low: refill (cycle start refused))",
         "alarm 1041 active (lubricant level low: refill (cycle start refused))"),
        ("door open", "door open"),  # a reason in other words is passed on as it is
    ],
)  # fmt: skip
def test_the_hosts_refusal_says_cycle_start_refused_once(reason, said):
    assert start_refused_text("m2", "O0007", reason) == (
        f"m2: cycle start of O0007 refused by the NC: {said}"
    )
