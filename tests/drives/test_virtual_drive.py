"""VirtualDrive: a CiA 301 slave + Drive402 on a lockstep hub, on python-can's virtual bus."""

from __future__ import annotations

import can
import canopen
import pytest

import drives
from drives import EDS_PATH, VirtualDrive
from drives.bus import CanHub, connect_network


@pytest.fixture
def rig():
    hub = CanHub()
    network = connect_network(canopen.Network(), hub.endpoint("master"))
    node = canopen.RemoteNode(3, EDS_PATH)
    network.add_node(node)
    vd = VirtualDrive(3, hub.endpoint("node3"), objects={0x6065: 5_000})
    yield hub, network, node, vd
    hub.close()


def test_exports():
    assert drives.VirtualDrive is VirtualDrive
    assert "VirtualDrive" in drives.__all__


def test_lockstep_drive_is_clocked_by_the_hub(rig):
    hub, network, node, vd = rig
    assert vd.slave in hub.clocked
    t0 = vd.drive.time
    hub.advance(0.002)
    assert vd.drive.time == pytest.approx(t0 + 0.002)
    assert vd.state_name == "SWITCH ON DISABLED"  # transition 1 at the first advance
    assert node.sdo[0x6065].raw == 5_000  # initial object from the constructor
    assert node.sdo[0x6041].raw & 0x4F == 0x40


def test_lockstep_refuses_start(rig):
    hub, network, node, vd = rig
    with pytest.raises(RuntimeError, match="lockstep"):
        vd.start()


def test_nmt_reset_node_is_a_power_on_reset(rig):
    hub, network, node, vd = rig
    hub.advance(0.002)
    node.sdo[0x6065].raw = 7_000
    node.sdo[0x607C].raw = 1234  # home offset, default 0
    vd.drive.homed = True
    seen = []
    network.subscribe(0x703, lambda cob, data, ts: seen.append(bytes(data)))
    node.nmt.send_command(0x81)  # reset node
    assert seen == [b"\x00"]  # boot-up
    assert vd.nmt_state == "PRE-OPERATIONAL"
    assert node.sdo[0x6065].raw == 5_000  # back to the constructor's value
    assert node.sdo[0x607C].raw == 0
    assert vd.drive.homed is False
    assert vd.state_name == "NOT READY TO SWITCH ON"


def test_nmt_reset_communication_keeps_the_application(rig):
    hub, network, node, vd = rig
    hub.advance(0.002)
    node.sdo[0x607C].raw = 1234
    node.nmt.send_command(0x82)
    assert node.sdo[0x607C].raw == 1234
    assert vd.state_name == "SWITCH ON DISABLED"


def test_plant_overrides_and_substep():
    hub = CanHub()
    vd = VirtualDrive(
        4,
        hub.endpoint("n4"),
        substep=1e-3,
        switches={"initial_position": 0.1},
        loops={"kv": 30.0},
    )
    assert vd.drive.params.loops.substep == 1e-3
    assert vd.drive.params.loops.kv == 30.0
    assert vd.table_position_m == pytest.approx(0.1)
    hub.close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gears": {}}, "unknown parameter group"),
        ({"loops": {"kp": 1.0}}, "unknown field"),
        ({"loops": 3}, "must be a dict"),
        ({"substep": 0}, "substep"),
        ({"tick_s": 0}, "tick_s"),
    ],
)
def test_bad_parameters_are_named(kwargs, match):
    hub = CanHub()
    with pytest.raises(ValueError, match=match):
        VirtualDrive(4, hub.endpoint("n4"), **kwargs)
    hub.close()


def test_bad_object_value_is_refused():
    hub = CanHub()
    with pytest.raises(Exception, match="0x0609003"):
        VirtualDrive(4, hub.endpoint("n4"), objects={0x605A: 99})
    hub.close()


def test_inject_and_power_cycle(rig):
    hub, network, node, vd = rig
    hub.advance(0.002)
    vd.inject("winding_temperature", celsius=90.0)
    assert vd.drive.plant.winding_temp == pytest.approx(90.0)
    with pytest.raises(ValueError, match="known"):
        vd.inject("gremlins")
    seen = []
    network.subscribe(0x703, lambda cob, data, ts: seen.append(bytes(data)))
    vd.power_cycle()
    assert seen == [b"\x00"]


def test_close_detaches_from_the_hub(rig):
    hub, network, node, vd = rig
    vd.close()
    assert vd.slave not in hub.clocked
    with pytest.raises(canopen.sdo.exceptions.SdoCommunicationError):
        node.sdo.RESPONSE_TIMEOUT = 0.01
        node.sdo.upload(0x1000, 0)


def test_realtime_on_python_can_virtual_bus():
    channel = "fmscell-test-vd-realtime"
    drive_bus = can.Bus(interface="virtual", channel=channel)
    network = canopen.Network()
    node = canopen.RemoteNode(6, EDS_PATH)
    network.add_node(node)
    network.connect(interface="virtual", channel=channel)
    vd = VirtualDrive(6, drive_bus).start()
    try:
        assert node.sdo[0x1000].raw == 0x00020192
        t0 = vd.drive.time
        node.sdo[0x1017].raw = 20
        assert node.nmt.wait_for_heartbeat(timeout=5.0) == "PRE-OPERATIONAL"
        assert vd.drive.time > t0  # the plant moves with the wall clock
    finally:
        vd.stop()
        network.disconnect()
        drive_bus.shutdown()
