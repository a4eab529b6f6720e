"""Life guarding, RPDO deadline, store/restore, and the slave under a realtime hub."""

import threading

import can

from drives.bus import CanHub
from drives.cia301 import CanopenSlave
from tests.drives.conftest import FakeDrive


def run(cell, ms):
    out = []
    for _ in range(ms):
        out += cell.advance(0.001)
    return out


def test_guarding_05_life_guarding_lost_raises_8130(cell, app, slave):
    cell.send("605#2B0C100064000000")  # guard time 100 ms
    cell.send("605#2F0D100003000000")  # life time factor 3 -> 300 ms
    assert run(cell, 400) == []  # not started before the first guard RTR
    assert cell.send("705#R") == ["705#7F"]
    assert run(cell, 299) == []
    assert run(cell, 2) == ["085#3081110000000000"]
    assert ("fault", 0x8130) in app.calls
    assert cell.send("705#R") == ["705#FF", "085#0000000000000000"]


def test_guarding_not_answered_while_heartbeat_runs(cell, app, slave):
    cell.send("605#2B1710000A000000")
    assert cell.send("705#R") == []


def test_rpdo_deadline_0x8250(cell, app, slave):
    cell.send("605#2300140105020080")  # RPDO1 invalid
    cell.send("605#2B00140514000000")  # event timer 20 ms = deadline
    cell.send("605#2300140105020000")  # valid
    cell.send("000#0105")
    assert run(cell, 50) == ["185#5002E8030000", "285#500200"]  # not monitored before 1st
    cell.send("205#0F00")
    out = run(cell, 25)
    assert "085#5082110000000000" in out
    assert ("fault", 0x8250) in app.calls
    assert cell.send("205#0F00") == ["085#0000000000000000"]


def test_other_01_store_with_wrong_signature_aborts(cell, slave):
    assert cell.send("605#2310100173617600") == ["585#8010100120000008"]


def test_other_02_store_then_reset_keeps_the_value(cell, app, slave):
    cell.send("605#2B17100064000000")  # 0x1017 = 100
    app.values[(0x6065, 0)] = 5000
    assert cell.send("605#2310100173617665") == ["585#6010100100000000"]  # "save"
    cell.send("605#2B17100000000000")
    cell.send("000#8205")
    assert slave.od.get(0x1017, 0) == 100
    app.values[(0x6065, 0)] = 1
    cell.send("000#8105")
    assert app.values[(0x6065, 0)] == 5000  # application parameter written back


def test_other_03_restore_defaults_with_load(cell, slave):
    cell.send("605#2B17100064000000")
    cell.send("605#2310100273617665")  # save communication parameters
    assert cell.send("605#231110026C6F6164") == ["585#6011100200000000"]  # "load"
    cell.send("000#8205")
    assert slave.od.get(0x1017, 0) == 0
    assert cell.send("605#231110026C6F6100") == ["585#8011100220000008"]


def test_store_reads_back_its_capability(cell, slave):
    assert cell.send("605#4010100100000000") == ["585#4310100101000000"]


def test_hub_reports_worst_sdo_latency_behind_pdos():
    hub = CanHub(auto_deliver=False)
    master, drive = hub.endpoint(), hub.endpoint()
    for n in range(3):
        drive.send(can.Message(arbitration_id=0x181 + n, data=bytes(8), is_extended_id=False))
    master.send(can.Message(arbitration_id=0x605, data=bytes(8), is_extended_id=False))
    hub.deliver()
    assert hub.worst_latency_s["sdo"] > 3 * 111e-6
    assert hub.worst_latency_s["pdo"] < hub.worst_latency_s["sdo"]
    hub.close()


def test_slave_runs_under_a_realtime_hub():
    hub = CanHub(mode="realtime")
    master = hub.endpoint("master")
    heartbeat = threading.Event()
    master.add_listener(lambda m: heartbeat.set() if m.data[:1] == b"\x7f" else None)
    slave = CanopenSlave(5, hub.endpoint("node5"), FakeDrive())
    slave.od.write(0x1017, 0, (10).to_bytes(2, "little"))
    slave.start()  # starts the realtime hub
    try:
        assert heartbeat.wait(5.0)
    finally:
        hub.close()


def test_start_on_a_lockstep_hub_is_refused(slave):
    import pytest

    with pytest.raises(RuntimeError, match="lockstep"):
        slave.start()


def test_export_dcf_carries_current_values_and_loads_back(cell, app, slave, tmp_path):
    import canopen

    cell.send("605#2B171000FA000000")  # 0x1017 = 250
    cell.send("605#2100210006000000")
    assert cell.send("605#0358206178697300") == ["585#2000000000000000"]  # "X axis", n=1, c
    app.values[(0x607C, 0)] = -1234
    path = tmp_path / "node5.dcf"
    slave.export_dcf(str(path))
    od = canopen.import_od(str(path))
    assert od.node_id == 5 and od.bitrate == 1_000_000
    assert od[0x1017].value == 250
    assert od[0x2100].value == "X axis"
    assert od[0x607C].value == -1234
    assert od[0x1400][1].default == 0x205 and od[0x1400][1].value == 0x205
