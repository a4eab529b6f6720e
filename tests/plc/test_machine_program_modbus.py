"""The remote operator panel through the real Modbus face (127.0.0.1, port 0) and a stock
pymodbus client, with the machine-tool program scanned in lockstep by the test: the host's
commands go through the same rungs and interlocks as the machine panel."""

from __future__ import annotations

import pytest
from pymodbus.client import ModbusTcpClient

from plc.modbus import ModbusFace
from plc.remote_panel import (
    ANSWER_COILS,
    COMMAND_COILS,
    WRITABLE,
    RemotePanel,
    RemotePanelError,
    coil_of,
)
from plc.signals import MODE_AUTO, MODE_MDI
from tests.plc.test_machine_program import Plc


@pytest.fixture
def cell():
    plc = Plc()
    plc.ready(MODE_AUTO)
    face = ModbusFace(
        lambda: plc.rt.snapshot, plc.rt.writes, plc.rt.image.size, port=0, writable=WRITABLE
    )
    face.start_in_thread()
    client = ModbusTcpClient("127.0.0.1", port=face.bound_port, timeout=3)
    assert client.connect()
    yield plc, RemotePanel(client), client
    client.close()
    face.stop_thread()


def test_remote_cycle_start_is_refused_with_the_door_open(cell):
    plc, panel, client = cell
    assert plc.io.open_door()  # spindle off: the door is not locked
    panel.cycle_start()
    plc.scan()  # the write is applied at the start of this scan
    assert not plc.nc.get("CycleStart")
    st = panel.status()
    assert st["CycleStartRefused"] and not st["CycleStart"] and not st["DoorClosed"]
    assert client.read_coils(COMMAND_COILS["RemCycleStart"], count=1).bits[0] is False
    # door closed: the same request is accepted, for one scan
    plc.io.close_door()
    panel.cycle_start()
    plc.scan()
    assert plc.nc.get("CycleStart")
    assert not panel.status()["CycleStartRefused"]
    plc.scan()
    assert not plc.nc.get("CycleStart"), "a remote start is a one-scan pulse"


def test_remote_feed_hold_reset_and_overrides(cell):
    plc, panel, client = cell
    panel.feed_hold()
    plc.scan()
    assert plc.nc.get("FeedHold") and panel.status()["FeedHold"]
    panel.set_feed_override(120)
    panel.set_spindle_override(0)
    panel.set_rapid_override(25)
    plc.scan()
    st = panel.status()
    assert (st["FeedOverride"], st["SpindleOverride"], st["RapidOverride"]) == (120, 0, 25)
    plc.io.inject("air_pressure_loss")
    plc.scan()
    assert panel.status()["PlcAlarmNumber"] == 1040
    plc.io.clear("air_pressure_loss")
    panel.reset()
    plc.scan()
    st = panel.status()
    assert st["PlcAlarmNumber"] == 0 and st["NcReset"] and not st["FeedHold"]


@pytest.mark.parametrize("value", [65535, 201, 250, 0x8000, -3])
def test_out_of_range_override_is_refused_with_exception_03(cell, value):
    """A real control refuses an override outside 0..200 % (issue 14, item 12: 65535 had
    set 0 %): exception 03, nothing queued, the override unchanged."""
    plc, panel, client = cell
    panel.set_feed_override(80)
    plc.scan()
    rr = client.write_register(1024, value & 0xFFFF)  # RemFeedOvr, holding register 1024
    assert rr.isError() and rr.exception_code == 3
    rr = client.write_registers(1024, [100, 100, value & 0xFFFF])  # FC16 refused whole
    assert rr.isError() and rr.exception_code == 3
    with pytest.raises(RemotePanelError):
        panel.set_spindle_override(value)
    plc.scan()
    st = panel.status()
    assert (st["FeedOverride"], st["SpindleOverride"]) == (80, 100)


def test_ladder_still_limits_an_override_written_around_the_face(cell):
    """Defence in depth: a value that reaches the image by another way is limited by the
    program's own rung to 0..200."""
    from plc.image import Write

    plc, panel, _ = cell
    plc.rt.writes.put((Write("MW", 0, (250,)), Write("MW", 2, (-3,))))
    plc.scan()
    plc.scan()
    st = panel.status()
    assert (st["FeedOverride"], st["SpindleOverride"]) == (200, 0)


def test_remote_mode_request(cell):
    plc, panel, _ = cell
    panel.request_mode(MODE_MDI)
    plc.scan()
    assert plc.nc.get("ModeSelect") == MODE_MDI and not panel.status()["ModeRefused"]
    panel.request_mode(7)
    plc.scan()
    assert plc.nc.get("ModeSelect") == MODE_MDI and panel.status()["ModeRefused"]


def test_outputs_and_answers_are_not_writable(cell):
    plc, _, client = cell
    for address in (coil_of("CycleStart"), coil_of("SpindleFwd"), ANSWER_COILS["ModeRefused"]):
        assert client.write_coil(address, True).isError(), address
    assert client.write_register(0, 1).isError()  # ModeSelect %QW0
    plc.scan()
    assert not plc.io.output("SpindleFwd") and not plc.nc.get("CycleStart")
    with pytest.raises(ValueError, match="not a coil"):
        coil_of("FeedOverride")


def test_remote_starts_during_estop_never_start_anything(cell):
    plc, panel, client = cell
    plc.io.press_estop()
    plc.scan()
    for _ in range(50):
        panel.cycle_start()
        client.write_coils(8192, [True, False, False])
        plc.scan()
        assert not plc.nc.get("CycleStart") and plc.nc.get("EStopActive")
        assert not any(plc.io.output(n) for n in ("SpindleFwd", "CoolantPump", "ArmToGrip"))
    assert panel.status()["CycleStartRefused"]


def test_panel_errors_name_the_request(cell):
    plc, _, client = cell
    bad = RemotePanel(client)
    bad.client = _Refusing(client)
    with pytest.raises(RemotePanelError, match="write coil RemCycleStart"):
        bad.cycle_start()


class _Refusing:
    """A client whose every coil write comes back as a Modbus exception (address 02)."""

    def __init__(self, client) -> None:
        self.client = client

    def write_coil(self, address, value):
        return self.client.write_coil(coil_of("SpindleFwd"), value)
