"""A stock `canopen` master (RemoteNode, BaseNode402) talks to the slave over the hub."""

import threading

import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from drives import EDS_PATH
from drives.application import EmcyRequest
from drives.bus import CanHub, connect_network
from drives.cia301 import CanopenSlave
from tests.drives.conftest import FakeDrive


@pytest.fixture
def rig():
    hub = CanHub()
    network = connect_network(canopen.Network(), hub.endpoint("master"))
    app = FakeDrive()
    node = canopen.RemoteNode(5, EDS_PATH)
    network.add_node(node)
    slave = CanopenSlave(5, hub.endpoint("node5"), app)
    yield hub, network, node, slave, app
    hub.close()


def test_sdo_reads_of_every_basic_type(rig):
    hub, network, node, slave, app = rig
    assert node.sdo[0x1000].raw == 0x00020192
    assert node.sdo[0x1018][1].raw == 0x464D5343
    assert node.sdo[0x1018][4].raw == 5  # serial = $NODEID
    assert node.sdo[0x1400][1].raw == 0x205
    assert node.sdo[0x605A].raw == 0  # owned by the application: FakeDrive answers 0
    assert node.sdo[0x6064].raw == 1000
    assert node.sdo[0x6502].raw == 0x1A5
    assert node.sdo[0x1005].raw == 0x80


def test_sdo_writes_reach_storage_and_application(rig):
    hub, network, node, slave, app = rig
    node.sdo[0x1017].raw = 250
    assert slave.od.get(0x1017, 0) == 250
    node.sdo[0x607A].raw = -123456
    assert app.values[(0x607A, 0)] == -123456


def test_segmented_upload_of_the_device_name(rig):
    hub, network, node, slave, app = rig
    assert node.sdo[0x1008].raw == "fmscell virtual servo drive"
    assert node.sdo[0x100A].raw == "fmscell 0.1"


def test_segmented_download_of_a_string(rig):
    hub, network, node, slave, app = rig
    node.sdo[0x2100].raw = "X axis of machine 1"
    assert node.sdo[0x2100].raw == "X axis of machine 1"


@pytest.mark.parametrize("crc", [True, False])
def test_block_download_and_upload_of_a_4k_domain(rig, crc):
    hub, network, node, slave, app = rig
    payload = bytes((i * 7) % 256 for i in range(4096))
    with node.sdo.open(
        0x2101, 0, "wb", block_transfer=True, size=len(payload), request_crc_support=crc
    ) as f:
        f.write(payload)
    assert slave.od.get(0x2101, 0) == payload
    with node.sdo.open(0x2101, 0, "rb", block_transfer=True, request_crc_support=crc) as f:
        assert f.read() == payload


@pytest.mark.parametrize(
    ("index", "sub", "value", "code"),
    [
        (0x1000, 0, 1, 0x06010002),  # read-only
        (0x605A, 0, 9, 0x06090031),  # above HighLimit
        (0x6083, 0, 0, 0x06090032),  # below LowLimit
        (0x1003, 0, 3, 0x06090030),  # only 0 clears the error history
        (0x6040, 0, 0x1FF, 0x06090030),  # refused by the application
        (0x1600, 1, 0x60400010, 0x08000022),  # mapping changed while RPDO1 is valid
    ],
)
def test_sdo_download_aborts_reach_the_client(rig, index, sub, value, code):
    hub, network, node, slave, app = rig
    is_var = isinstance(node.object_dictionary[index], canopen.objectdictionary.ODVariable)
    variable = node.sdo[index] if is_var else node.sdo[index][sub]
    with pytest.raises(SdoAbortedError) as info:
        variable.raw = value
    assert info.value.code == code


def test_upload_of_unknown_object_and_sub_index(rig):
    hub, network, node, slave, app = rig
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.upload(0x1004, 0)
    assert info.value.code == 0x06020000
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.upload(0x1000, 1)
    assert info.value.code == 0x06090011
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.upload(0x1016, 9)
    assert info.value.code == 0x06090011


def test_pdo_remap_by_the_stock_master_then_sync(rig):
    hub, network, node, slave, app = rig
    node.tpdo.read()
    node.rpdo.read()
    assert [v.index for v in node.tpdo[1].map] == [0x6041, 0x6064]
    tpdo = node.tpdo[3]
    tpdo.clear()
    tpdo.add_variable(0x6064)
    tpdo.add_variable(0x60F4)
    tpdo.trans_type = 1
    tpdo.enabled = True
    rpdo = node.rpdo[1]
    rpdo.clear()
    rpdo.add_variable(0x6040)
    rpdo.add_variable(0x607A)
    rpdo.trans_type = 1
    rpdo.enabled = True
    node.tpdo.save()
    node.rpdo.save()
    assert slave.od.get(0x1A02, 0) == 2
    assert slave.od.get(0x1A02, 2) == 0x60F40020
    node.nmt.state = "OPERATIONAL"
    app.values[(0x60F4, 0)] = -3
    rpdo["Controlword"].raw = 0x0F
    rpdo["Target position"].raw = 4242
    rpdo.transmit()
    network.sync.transmit()
    assert app.values[(0x607A, 0)] == 4242
    assert tpdo["Following error actual value"].raw == -3
    assert tpdo["Position actual value"].raw == 1000


def test_base_node_402_accepts_the_eds_and_reads_state_from_tpdo():
    hub = CanHub()
    network = connect_network(canopen.Network(), hub.endpoint("master"))
    node = canopen.BaseNode402(5, EDS_PATH)
    network.add_node(node)
    app = FakeDrive()
    CanopenSlave(5, hub.endpoint("node5"), app)
    node.setup_402_state_machine()
    assert 0x6041 in node.tpdo_values and 0x6040 in node.rpdo_pointers
    node.nmt.state = "OPERATIONAL"
    hub.advance(0.001)  # event-driven TPDO1 carries the statusword
    assert node.statusword == 0x0250
    assert node.state == "SWITCH ON DISABLED"
    assert node.is_op_mode_supported("CYCLIC SYNCHRONOUS POSITION")
    node.controlword = 0x06  # RPDO1 is event-driven: sent and applied at once
    assert app.values[(0x6040, 0)] == 0x06
    hub.close()


def test_scanner_finds_exactly_the_attached_nodes():
    hub = CanHub()
    network = connect_network(canopen.Network(), hub.endpoint("master"))
    for node_id in (3, 5, 9):
        CanopenSlave(node_id, hub.endpoint(f"n{node_id}"), FakeDrive())
    network.scanner.search()
    assert sorted(network.scanner.nodes) == [3, 5, 9]
    hub.close()


def test_emcy_consumer_and_heartbeat_seen_by_the_master(rig):
    hub, network, node, slave, app = rig
    node.sdo[0x1017].raw = 10
    hub.advance(0.01)
    assert node.nmt.state == "PRE-OPERATIONAL"
    app.emcy.append(EmcyRequest(0x8611, 0x21))
    hub.advance(0.001)
    assert [e.code for e in node.emcy.active] == [0x8611]
    app.emcy.append(EmcyRequest(0x0000, 0x00))
    hub.advance(0.001)
    assert node.emcy.active == []


def test_threaded_master_with_notifier_on_the_same_hub():
    hub = CanHub()
    network = canopen.Network(hub.endpoint("master"))
    node = canopen.RemoteNode(5, EDS_PATH)
    network.add_node(node)
    network.connect()
    try:
        CanopenSlave(5, hub.endpoint("node5"), FakeDrive())
        assert node.sdo[0x1008].raw == "fmscell virtual servo drive"
        booted = threading.Event()
        node.nmt.add_heartbeat_callback(lambda state: booted.set())
        network.nmt.send_command(0x82)  # reset communication -> boot-up
        assert booted.wait(5.0)
    finally:
        network.disconnect()
        hub.close()


def test_slave_serves_on_python_can_virtual_bus_in_realtime():
    import can

    channel = "fmscell-test-virtual"
    slave_bus = can.Bus(interface="virtual", channel=channel)
    network = canopen.Network()
    node = canopen.RemoteNode(5, EDS_PATH)
    network.add_node(node)
    network.connect(interface="virtual", channel=channel)
    slave = CanopenSlave(5, slave_bus, FakeDrive())
    slave.start()
    try:
        assert node.sdo[0x1000].raw == 0x00020192
        node.sdo[0x1017].raw = 20
        assert node.nmt.wait_for_heartbeat(timeout=5.0) == "PRE-OPERATIONAL"
    finally:
        slave.stop()
        network.disconnect()
        slave_bus.shutdown()


class _PowerStages(FakeDrive):
    """Just enough CiA 402 to let BaseNode402 walk to OPERATION ENABLED."""

    STATUS = {0x06: 0x0231, 0x07: 0x0233, 0x0F: 0x0237, 0x00: 0x0250, 0x80: 0x0250}

    def write_object(self, index, subindex, value):
        super().write_object(index, subindex, value)
        if index == 0x6040 and value in self.STATUS:
            self.values[(0x6041, 0)] = self.STATUS[value]


def test_base_node_402_changes_state_in_lockstep_without_advancing_time():
    hub = CanHub()
    network = connect_network(canopen.Network(), hub.endpoint("master"))
    node = canopen.BaseNode402(5, EDS_PATH)
    network.add_node(node)
    app = _PowerStages()
    CanopenSlave(5, hub.endpoint("node5"), app)
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    hub.advance(0.001)
    node.state = "OPERATION ENABLED"  # each controlword RPDO is answered by TPDO1 at once
    assert node.state == "OPERATION ENABLED"
    assert [c[3] for c in app.calls if c[:2] == ("write", 0x6040)] == [0x06, 0x07, 0x0F]
    hub.close()


def test_realtime_hub_with_stock_sync_producer_and_synchronous_tpdo():
    hub = CanHub(mode="realtime")
    network = canopen.Network(hub.endpoint("master"))
    node = canopen.RemoteNode(5, EDS_PATH)
    network.add_node(node)
    network.connect()
    CanopenSlave(5, hub.endpoint("node5"), FakeDrive()).start()  # starts the hub thread
    try:
        node.tpdo.read()
        node.tpdo[1].trans_type = 1
        node.tpdo.save()
        node.nmt.state = "OPERATIONAL"
        network.sync.start(0.005)
        assert node.tpdo[1].wait_for_reception(timeout=2.0) is not None
        assert node.tpdo[1]["Position actual value"].raw == 1000
        network.sync.stop()
        assert hub.load.total_frames > 0
    finally:
        network.disconnect()
        hub.close()
