"""PDO configuration by SDO (CiA 301 procedure, CTT PDO 22-33) and transmission behaviour."""

import pytest

TPDO3_COMM, TPDO3_MAP = "0218", "021A"  # little-endian index bytes of 0x1802 / 0x1A02
RPDO1_COMM, RPDO1_MAP = "0014", "0016"


def sdo(cell, command, index_le, sub, value_hex="00000000"):
    return cell.send(f"605#{command}{index_le}{sub:02X}{value_hex}")


def disable_tpdo3_mapping(cell):
    # TPDO3 is invalid by default (0x80000385); set the count to 0 first.
    assert sdo(cell, "2F", TPDO3_MAP, 0) == ["585#60021A0000000000"]


@pytest.mark.parametrize(
    ("title", "entry", "code"),
    [
        ("not mappable object", "10001017", "41000406"),  # 0x1017 heartbeat (PDOMapping=0)
        ("non-existent object", "20000060", "41000406"),  # 0x6000 not in the EDS
        ("wrong length", "10006460", "43000406"),  # 0x6064 is 32 bits, 16 requested
        ("dummy of wrong length", "08000300", "43000406"),  # INT16 dummy with 8 bits
    ],
)
def test_tpdo_mapping_entry_refusals(cell, slave, title, entry, code):
    disable_tpdo3_mapping(cell)
    assert sdo(cell, "23", TPDO3_MAP, 1, entry) == [f"585#80021A01{code}"], title


def test_rpdo_refuses_read_only_objects(cell, slave):
    sdo(cell, "23", RPDO1_COMM, 1, "05020080")  # invalidate RPDO1
    sdo(cell, "2F", RPDO1_MAP, 0)
    # Statusword 0x6041 is ro: it cannot be written by an RPDO.
    assert sdo(cell, "23", RPDO1_MAP, 1, "10004160") == ["585#8000160141000406"]
    assert sdo(cell, "23", RPDO1_MAP, 1, "10004060") == ["585#6000160100000000"]


def test_mapping_while_pdo_valid_is_refused_with_device_state(cell, slave):
    assert sdo(cell, "2F", RPDO1_MAP, 0) == ["585#8000160022000008"]
    assert sdo(cell, "23", RPDO1_MAP, 1, "10004060") == ["585#8000160122000008"]


def test_entries_only_after_count_is_zero(cell, slave):
    # TPDO3 invalid but its count is 2: entries are locked until sub0 = 0.
    assert sdo(cell, "23", TPDO3_MAP, 1, "20006460") == ["585#80021A0122000008"]


def test_mapping_longer_than_64_bits_is_refused(cell, slave):
    disable_tpdo3_mapping(cell)
    for sub, entry in ((1, "20006460"), (2, "20006C60"), (3, "10004160")):
        assert sdo(cell, "23", TPDO3_MAP, sub, entry)[0].startswith("585#60")
    assert sdo(cell, "2F", TPDO3_MAP, 0, "03000000") == ["585#80021A0042000406"]
    assert sdo(cell, "2F", TPDO3_MAP, 0, "02000000") == ["585#60021A0000000000"]


def test_count_above_eight_is_refused(cell, slave):
    disable_tpdo3_mapping(cell)
    assert sdo(cell, "2F", TPDO3_MAP, 0, "09000000") == ["585#80021A0031000906"]


@pytest.mark.parametrize(
    ("title", "index", "sub", "value", "answer"),
    [
        ("restricted CAN-ID", TPDO3_COMM, 1, "05070000", "80021801 30000906"),
        ("29-bit ID", TPDO3_COMM, 1, "85030020", "80021801 30000906"),
        ("reserved bits of 11-bit ID", TPDO3_COMM, 1, "85030100", "80021801 30000906"),
        ("reserved transmission type", TPDO3_COMM, 2, "F1000000", "80021802 30000906"),
        ("RPDO RTR-only type", RPDO1_COMM, 2, "FC000000", "80001402 30000906"),
        ("TPDO RTR-only type ok", TPDO3_COMM, 2, "FC000000", "60021802 00000000"),
        ("COB-ID change while valid", RPDO1_COMM, 1, "06020000", "80001401 30000906"),
        ("inhibit time while valid", "0018", 3, "0A000000", "80001803 30000906"),
        ("inhibit time while invalid", TPDO3_COMM, 3, "0A000000", "60021803 00000000"),
        ("SYNC start value above 240", TPDO3_COMM, 6, "F1000000", "80021806 30000906"),
        ("event timer any time", "0018", 5, "64000000", "60001805 00000000"),
    ],
)
def test_communication_parameter_rules(cell, slave, title, index, sub, value, answer):
    width = "23" if sub == 1 else ("2B" if sub in (3, 5) else "2F")
    assert sdo(cell, width, index, sub, value) == ["585#" + answer.replace(" ", "")], title


def test_full_remap_procedure_and_sync_transmission(cell, app, slave):
    sdo(cell, "23", TPDO3_COMM, 1, "85030080")
    disable_tpdo3_mapping(cell)
    sdo(cell, "23", TPDO3_MAP, 1, "20006460")  # position actual
    sdo(cell, "23", TPDO3_MAP, 2, "08000500")  # U8 dummy
    sdo(cell, "23", TPDO3_MAP, 3, "10007760")  # torque actual
    sdo(cell, "2F", TPDO3_MAP, 0, "03000000")
    sdo(cell, "2F", TPDO3_COMM, 2, "01000000")
    assert sdo(cell, "23", TPDO3_COMM, 1, "85030000") == ["585#6002180100000000"]
    cell.send("000#0105")
    cell.advance(0.001)
    app.values[(0x6077, 0)] = -2
    assert cell.send("080#") == ["385#E8030000" + "00" + "FEFF"]


def test_transmission_type_0_sends_only_on_change(cell, app, slave):
    sdo(cell, "2F", TPDO3_COMM, 2, "00000000")
    sdo(cell, "23", TPDO3_COMM, 1, "85030000")
    cell.send("000#0105")
    cell.advance(0.001)
    assert cell.send("080#") == ["385#500200000000"]
    assert cell.send("080#") == []
    app.values[(0x606C, 0)] = 1
    assert cell.send("080#") == ["385#500201000000"]


def test_event_driven_tpdo_respects_inhibit_time_and_event_timer(cell, app, slave):
    # TPDO1 type 255: invalidate, inhibit 5 ms (50 x 100 us), event timer 20 ms, valid.
    sdo(cell, "23", "0018", 1, "85010080")
    sdo(cell, "2B", "0018", 3, "32000000")
    sdo(cell, "2B", "0018", 5, "14000000")
    sdo(cell, "23", "0018", 1, "85010000")
    cell.send("000#0105")
    sent = []
    for step in range(40):
        app.values[(0x6064, 0)] = step  # changes every millisecond
        sent += [(step, f) for f in cell.advance(0.001) if f.startswith("185#")]
    steps = [s for s, _ in sent]
    assert steps[0] == 0
    assert all(b - a >= 5 for a, b in zip(steps, steps[1:], strict=False))
    app.values[(0x6064, 0)] = 1234
    quiet = []
    for _ in range(45):
        quiet += [f for f in cell.advance(0.001) if f.startswith("185#")]
    assert len(quiet) == 3  # the change once, then the 20 ms event timer twice


def test_rtr_on_tpdo_returns_fresh_data(cell, app, slave):
    cell.send("000#0105")
    cell.advance(0.001)
    app.values[(0x6064, 0)] = 5
    assert cell.send("185#R") == ["185#500205000000"]


def test_rpdo_too_long_raises_8220_but_applies(cell, app, slave):
    cell.send("000#0105")
    cell.advance(0.001)
    assert cell.send("405#E803000000") == ["085#2082110000000000"]  # RPDO3: target, 5 bytes
    assert app.values[(0x607A, 0)] == 1000
    assert ("fault", 0x8220) in app.calls


def test_rpdo_length_error_is_signalled_once_until_cleared(cell, app, slave):
    cell.send("000#0105")
    cell.advance(0.001)
    assert cell.send("205#0F") == ["085#1082110000000000"]
    assert cell.send("205#0F") == []
    assert cell.send("205#0F00") == ["085#0000000000000000"]
    assert app.calls.count(("fault", 0x8210)) == 1


def test_application_refusing_an_rpdo_value_keeps_the_node_alive(cell, app, slave):
    cell.send("000#0105")
    cell.send("205#FF01")  # controlword 0x01FF refused by the application
    assert slave.pdo.refused_writes == 1
    cell.send("405#E8030000")  # the next RPDO is still processed
    assert app.values[(0x607A, 0)] == 1000


def test_default_mapping_of_the_eds(slave):
    rpdo1, tpdo1 = slave.pdo.rpdos[0], slave.pdo.tpdos[0]
    # one object per RPDO (a master changing one never sends a stale copy of another)
    rpdo_objects = [[(e.index, e.subindex) for e in c.targets] for c in slave.pdo.rpdos]
    assert rpdo_objects == [[(0x6040, 0)], [(0x6060, 0)], [(0x607A, 0)], [(0x60FF, 0)]]
    assert [c.cob_id for c in slave.pdo.rpdos] == [0x205, 0x305, 0x405, 0x505]
    assert all(c.valid for c in slave.pdo.rpdos)
    assert [(e.index, e.subindex) for e in tpdo1.targets] == [(0x6041, 0), (0x6064, 0)]
    assert rpdo1.cob_id == 0x205 and tpdo1.cob_id == 0x185
    assert [c.valid for c in slave.pdo.tpdos] == [True, True, False, False]


def test_event_tpdo_answers_an_event_rpdo_at_once(cell, app, slave):
    cell.send("000#0105")
    cell.advance(0.001)
    app.values[(0x6041, 0)] = 0x0221  # what a profile would do on "shutdown"
    assert cell.send("205#0600") == ["185#2102E8030000", "285#210200"]
