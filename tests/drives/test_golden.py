"""CiA 301 golden-frame tests in candump notation, titled after the CTT cases (anchor §4.2).

Node 5 (`FakeDrive` application, shipped EDS) on a lockstep hub; the master sends raw frames
and each case asserts the exact frames that follow. Replies include the master's own request
first only where noted: `Cell.send` returns the frames the master *received*.
"""

import hashlib
import io

import pytest

from drives.application import EmcyRequest
from drives.bus import CanHub
from drives.cia301 import CanopenSlave
from tests.drives.conftest import Cell, FakeDrive


def boot(cell, app, node_id=5):
    return CanopenSlave(node_id, cell.hub.endpoint(f"node{node_id}"), app)


def test_state_01_boot_up_message_then_pre_operational(cell, app):
    slave = boot(cell, app)
    assert cell.seen() == ["705#00"]
    assert slave.state.label == "PRE-OPERATIONAL"


def test_state_02_pre_operational_answers_sdo_but_no_pdo(cell, app, slave):
    assert cell.send("605#4000100000000000") == ["585#4300100092010200"]
    assert cell.send("080#") == []
    assert cell.send("205#0F00E8030000") == []
    assert ("write", 0x6040, 0, 15) not in app.calls


def test_state_03_operational_sends_pdos(cell, app, slave):
    cell.send("000#0105")
    assert cell.advance(0.001) == ["185#5002E8030000", "285#500200"]


def test_state_04_stopped_answers_only_nmt_and_error_control(cell, app, slave):
    cell.send("605#2B17100064000000")  # heartbeat 100 ms
    cell.send("000#0205")
    assert cell.send("605#4000100000000000") == []
    assert cell.send("205#0F00E8030000") == []
    assert cell.send("080#") == []
    assert cell.advance(0.1) == ["705#04"]
    cell.send("000#0105")
    assert cell.advance(0.001)[:1] == ["185#5002E8030000"]


def test_transition_01_nmt_start_all_nodes(cell, app, slave):
    cell.send("000#0100")
    assert slave.state.label == "OPERATIONAL"
    assert ("nmt", "OPERATIONAL") in app.calls


def test_transition_02_enter_pre_operational(cell, app, slave):
    cell.send("000#0105")
    cell.send("000#8005")
    assert slave.state.label == "PRE-OPERATIONAL"


def test_transition_03_reset_communication_sends_boot_up_and_restores_1017(cell, app, slave):
    cell.send("605#2B17100064000000")
    assert cell.send("000#8205") == ["705#00"]
    assert cell.send("605#4017100000000000") == ["585#4B17100000000000"]
    assert slave.state.label == "PRE-OPERATIONAL"


def test_transition_04_reset_node_sends_boot_up(cell, app, slave):
    cell.send("000#0105")
    assert cell.send("000#8105") == ["705#00"]
    assert app.calls[-2:] == [("nmt", "INITIALISING"), ("nmt", "PRE-OPERATIONAL")]


def test_nmt_for_another_node_is_ignored(cell, app, slave):
    cell.send("000#0106")
    assert slave.state.label == "PRE-OPERATIONAL"


def test_sdo_01_expedited_upload_device_type(cell, app, slave):
    assert cell.send("605#4000100000000000") == ["585#4300100092010200"]


def test_sdo_02_expedited_download_and_read_back(cell, app, slave):
    assert cell.send("605#2B17100064000000") == ["585#6017100000000000"]
    assert cell.send("605#4017100000000000") == ["585#4B17100064000000"]


def test_sdo_03_segmented_upload_device_name(cell, app, slave):
    assert cell.send("605#4008100000000000") == ["585#410810001B000000"]
    assert cell.send("605#6000000000000000") == ["585#00666D7363656C6C"]  # "fmscell"
    assert cell.send("605#7000000000000000") == ["585#1020766972747561"]  # " virtua"
    assert cell.send("605#6000000000000000") == ["585#006C20736572766F"]  # "l servo"
    # 27 bytes = 7 + 7 + 7 + 6: the last segment has toggle 1, n = 1, c = 1 -> 0x13.
    assert cell.send("605#7000000000000000") == ["585#1320647269766500"]  # " drive"


def test_sdo_04_segmented_download_string(cell, app, slave):
    assert cell.send("605#2100210009000000") == ["585#6000210000000000"]
    assert cell.send("605#0058206178697320") == ["585#2000000000000000"]  # "X axis "
    assert cell.send("605#1B31320000000000") == ["585#3000000000000000"]  # "12", n=5, c
    assert slave.od.get(0x2100, 0) == "X axis 12"


def test_sdo_05_sub_index_of_a_var_does_not_exist(cell, app, slave):
    assert cell.send("605#4000100100000000") == ["585#8000100111000906"]


def test_sdo_06_object_does_not_exist(cell, app, slave):
    assert cell.send("605#4004100000000000") == ["585#8004100000000206"]


def test_sdo_07_write_read_only_object(cell, app, slave):
    assert cell.send("605#2300100001000000") == ["585#8000100002000106"]


def test_sdo_08_unknown_command_specifier(cell, app, slave):
    assert cell.send("605#E000100000000000") == ["585#8000100001000405"]


def test_sdo_09_toggle_bit_not_alternated(cell, app, slave):
    cell.send("605#4008100000000000")
    assert cell.send("605#7000000000000000") == ["585#8008100000000305"]


def test_sdo_10_data_too_long_and_too_short(cell, app, slave):
    assert cell.send("605#2317100064000000") == ["585#8017100012000706"]
    assert cell.send("605#2F05100080000000") == ["585#8005100013000706"]


def test_sdo_11_value_too_high(cell, app, slave):
    # 0x605A quick stop option code, HighLimit 8.
    assert cell.send("605#2B5A600009000000") == ["585#805A600031000906"]


def test_sdo_12_timeout_aborts_a_stalled_segmented_transfer(cell, app, slave):
    cell.send("605#4008100000000000")
    assert cell.advance(0.5) == []
    assert cell.advance(0.6) == ["585#8008100000000405"]


def test_heartbeat_01_producer_period(cell, app, slave):
    cell.send("605#2B17100064000000")
    out = []
    for _ in range(300):
        out += cell.advance(0.001)
    assert out == ["705#7F"] * 3


def test_heartbeat_05_consumer_timeout_raises_emcy_8130(cell, app, slave):
    # Monitor node 1 with 200 ms: 0x1016:01 = 0x000100C8.
    assert cell.send("605#231610 01C8000100".replace(" ", "")) == ["585#6016100100000000"]
    cell.send("000#0105")
    cell.advance(0.001)
    cell.send("701#05")  # first heartbeat starts monitoring
    out = []
    for _ in range(250):
        out += cell.advance(0.001)
    assert "085#3081110000000000" in out
    assert ("fault", 0x8130) in app.calls
    assert cell.send("701#05") == ["085#0000000000000000"]


def test_heartbeat_consumer_ignores_boot_up_until_first_heartbeat(cell, app, slave):
    cell.send("605#23161001C8000100")
    cell.send("701#00")  # boot-up only
    out = []
    for _ in range(500):
        out += cell.advance(0.001)
    assert not any(f.startswith("085#") for f in out)


def test_guarding_02_rtr_reply_toggles(cell, app, slave):
    assert cell.send("705#R") == ["705#7F"]
    assert cell.send("705#R") == ["705#FF"]
    assert cell.send("705#R") == ["705#7F"]


def test_synchronization_sync_plus_tpdo_type_1(cell, app, slave):
    # Remap TPDO3 (disabled by default: 0x80000385) to type 1 and enable it.
    assert cell.send("605#2F02180201000000") == ["585#6002180200000000"]
    assert cell.send("605#2302180185030000") == ["585#6002180100000000"]
    cell.send("000#0105")
    cell.advance(0.001)  # event-driven TPDO1/2 go out once
    assert cell.send("080#") == ["385#500200000000"]
    app.values[(0x606C, 0)] = 7
    assert cell.send("080#") == ["385#500207000000"]


def test_synchronization_type_2_every_second_sync(cell, app, slave):
    cell.send("605#2F02180202000000")
    cell.send("605#2302180185030000")
    cell.send("000#0105")
    cell.advance(0.001)
    replies = [cell.send("080#") for _ in range(4)]
    assert replies == [[], ["385#500200000000"], [], ["385#500200000000"]]


def test_sync_rpdo_is_applied_at_the_next_sync(cell, app, slave):
    assert cell.send("605#2300140105020080") == ["585#6000140100000000"]  # RPDO1 invalid
    assert cell.send("605#2F00140201000000") == ["585#6000140200000000"]  # type 1
    assert cell.send("605#2300140105020000") == ["585#6000140100000000"]  # valid again
    assert cell.send("605#2302140105040080") == ["585#6002140100000000"]  # RPDO3 likewise
    assert cell.send("605#2F02140201000000") == ["585#6002140200000000"]
    assert cell.send("605#2302140105040000") == ["585#6002140100000000"]
    cell.send("000#0105")
    cell.send("205#0F00")
    cell.send("405#E8030000")
    assert ("write", 0x6040, 0, 15) not in app.calls
    cell.send("080#")
    assert app.calls[-3:] == [("write", 0x6040, 0, 15), ("write", 0x607A, 0, 1000), ("sync",)]


def test_emergency_01_application_emcy_sets_1001_and_1003(cell, app, slave):
    cell.send("000#0105")
    app.emcy.append(EmcyRequest(0x8611, 0x21, b"\x01\x02\x03\x04\x05"))
    assert cell.advance(0.001)[0] == "085#1186210102030405"
    assert cell.send("605#4001100000000000") == ["585#4F01100021000000"]
    assert cell.send("605#4003100000000000") == ["585#4F03100001000000"]
    assert cell.send("605#4003100100000000") == ["585#4303100111860000"]


def test_emergency_02_writing_zero_clears_1003_other_values_abort(cell, app, slave):
    app.emcy.append(EmcyRequest(0x2310, 0x03))
    cell.advance(0.001)
    assert cell.send("605#2F03100001000000") == ["585#8003100030000906"]
    assert cell.send("605#2F03100000000000") == ["585#6003100000000000"]
    assert cell.send("605#4003100000000000") == ["585#4F03100000000000"]


def test_pdo_length_error_raises_emcy_8210(cell, app, slave):
    cell.send("000#0105")
    cell.advance(0.001)
    assert cell.send("205#0F") == ["085#1082110000000000"]
    assert ("fault", 0x8210) in app.calls
    cell.send("205#0F00")
    assert cell.seen()[-1] == "085#0000000000000000"


def test_emcy_while_stopped_is_sent_after_restart(cell, app, slave):
    cell.send("000#0205")
    app.emcy.append(EmcyRequest(0x4310, 0x09))
    assert cell.advance(0.001) == []
    assert cell.send("000#0105")[0] == "085#1043090000000000"


def scenario_trace() -> str:
    trace = io.StringIO()
    hub = CanHub(log=trace)
    cell = Cell.__new__(Cell)
    cell.trace, cell.hub = trace, hub
    cell.master = hub.endpoint("master")
    cell.frames = []
    cell.master.add_listener(cell.frames.append)
    app = FakeDrive()
    CanopenSlave(5, hub.endpoint("n5"), app)
    CanopenSlave(6, hub.endpoint("n6"), FakeDrive())
    cell.send("605#2B17100032000000")
    cell.send("606#2B17100032000000")
    cell.send("000#0100")
    for i in range(200):
        cell.send(f"205#0F00{i:02X}000000")
        cell.send("080#")
        if i == 50:
            app.emcy.append(EmcyRequest(0x8611, 0x21))
        cell.advance(0.001)
    hub.close()
    return trace.getvalue()


def test_lockstep_determinism_same_scenario_same_candump_hash():
    first, second = scenario_trace(), scenario_trace()
    assert hashlib.sha256(first.encode()).hexdigest() == hashlib.sha256(second.encode()).hexdigest()
    assert "085#1186" in first and first.count("705#05") == 4


@pytest.mark.parametrize("node_id", [0, 128])
def test_node_id_out_of_range_is_refused(cell, app, node_id):
    with pytest.raises(ValueError, match="node_id"):
        CanopenSlave(node_id, cell.hub.endpoint(), app)


def test_synchronization_counter_byte_and_sync_start_value(cell, app, slave):
    assert cell.send("605#2F19100001000000") == ["585#8019100030000906"]  # 1 is invalid
    assert cell.send("605#2F19100005000000") == ["585#6019100000000000"]  # counts 1..5
    cell.send("605#2F02180203000000")  # TPDO3 every 3rd SYNC
    cell.send("605#2F02180604000000")  # start at counter value 4
    cell.send("605#2302180185030000")
    cell.send("000#0105")
    cell.advance(0.001)
    sent = [bool(cell.send(f"080#{c:02X}")) for c in (1, 2, 3, 4, 5, 1, 2, 3, 4)]
    assert sent == [False, False, False, True, False, False, True, False, False]
    assert cell.send("080#") == ["085#4082110000000000"]  # counter byte missing


def test_synchronization_counter_refused_while_period_set(cell, slave):
    cell.send("605#23061000E8030000")
    assert cell.send("605#2F19100005000000") == ["585#8019100022000008"]


def test_od_05_sub_index_255_does_not_exist(cell, slave):
    assert cell.send("605#401810FF00000000") == ["585#801810FF11000906"]


def test_pdo_02_rtr_in_stopped_gets_no_answer(cell, app, slave):
    cell.send("000#0105")
    cell.advance(0.001)
    cell.send("000#0205")
    assert cell.send("185#R") == []


def test_heartbeat_03_disabling_stops_the_producer(cell, slave):
    cell.send("605#2B1710000A000000")
    assert cell.advance(0.01) == ["705#7F"]
    cell.send("605#2B17100000000000")
    assert cell.advance(0.05) == []


def test_heartbeat_04_same_consumer_entry_twice(cell, slave):
    assert cell.send("605#23161001E8030100") == ["585#6016100100000000"]
    assert cell.send("605#23161001E8030100") == ["585#6016100100000000"]  # same sub: fine
    assert cell.send("605#23161002E8030100") == ["585#8016100243000406"]  # node 1 again
    assert cell.send("605#23161002E8030200") == ["585#6016100200000000"]


def test_emergency_05_forced_emcy_matches_1003_sub1(cell, app, slave):
    app.emcy.append(EmcyRequest(0x7305, 0x21, b"\x00\x00\x00\x00\x07"))
    emcy = cell.advance(0.001)
    assert emcy == ["085#0573210000000007"]
    assert cell.send("605#4003100100000000") == ["585#4303100105730000"]
