"""EMCY producer: frame layout, 0x1001 composition, 0x1003 history, queueing, COB-ID."""

from drives.application import EmcyRequest


def test_history_is_newest_first_and_bounded(cell, app, slave):
    cell.send("000#0105")
    for code in range(0x1000, 0x100A):
        app.emcy.append(EmcyRequest(code, 0x01))
    cell.advance(0.001)
    assert slave.od.get(0x1003, 0) == 8
    assert slave.od.get(0x1003, 1) == 0x1009
    assert slave.od.get(0x1003, 8) == 0x1002


def test_reset_emcy_is_sent_but_not_recorded(cell, app, slave):
    cell.send("000#0105")
    app.emcy += [EmcyRequest(0x2310, 0x03), EmcyRequest(0x0000, 0x00)]
    assert cell.advance(0.001)[:2] == ["085#1023030000000000", "085#0000000000000000"]
    assert slave.od.get(0x1003, 0) == 1
    assert slave.od.get(0x1001, 0) == 0


def test_error_register_combines_application_and_communication_bits(cell, app, slave):
    cell.send("000#0105")
    app.emcy.append(EmcyRequest(0x4310, 0x09))
    cell.advance(0.001)
    cell.send("205#0F")  # PDO length error: communication bit 4
    assert slave.od.get(0x1001, 0) == 0x19
    assert cell.seen()[-1] == "085#1082190000000000"


def test_disabled_emcy_cob_id_sends_nothing(cell, app, slave):
    cell.send("605#2314100085000080")
    cell.send("000#0105")
    app.emcy.append(EmcyRequest(0x8611, 0x21))
    assert cell.advance(0.001)[:1] != ["085#1186210000000000"]
    assert not any(f.startswith("085#") for f in cell.seen())


def test_emcy_cob_id_can_be_moved(cell, app, slave):
    cell.send("605#2314100095000000")
    cell.send("000#0105")
    app.emcy.append(EmcyRequest(0x8611, 0x21))
    assert "095#1186210000000000" in cell.advance(0.001)


def test_sync_of_wrong_length_raises_8240(cell, app, slave):
    assert cell.send("080#0102") == ["085#4082110000000000"]


def test_sync_timeout_from_1006(cell, app, slave):
    cell.send("605#2306100010270000")  # 0x1006 = 10 000 us
    cell.send("000#0105")
    cell.send("080#")
    out = []
    for _ in range(16):
        out += cell.advance(0.001)
    assert "085#0081110000000000" in out
    assert ("fault", 0x8100) in app.calls
    assert cell.send("080#")[0] == "085#0000000000000000"


def test_bus_off_recovery_reports_8140(cell, app, slave):
    cell.send("605#2B1710000A000000")
    endpoint = slave.bus
    cell.hub.bus_off(endpoint)
    assert cell.advance(0.01) == []
    assert slave.send_failures == 1
    cell.hub.recover(endpoint)
    assert cell.advance(0.01) == ["705#7F", "085#4081110000000000"]
    assert ("fault", 0x8140) in app.calls


def test_emcy_inhibit_time_spaces_frames(cell, app, slave):
    assert cell.send("605#2B15100014000000") == ["585#6015100000000000"]  # 20 x 100 us
    cell.send("000#0105")
    cell.advance(0.001)
    app.emcy += [EmcyRequest(0x2310, 0x03), EmcyRequest(0x3210, 0x05), EmcyRequest(0, 0)]
    times = []
    for step in range(10):
        times += [(step, f) for f in cell.advance(0.001) if f.startswith("085#")]
    assert [s for s, _ in times] == [0, 2, 4]
    assert [f[4:8] for _, f in times] == ["1023", "1032", "0000"]


def test_sdo_server_parameter_record(cell, slave):
    assert cell.send("605#4000120100000000") == ["585#4300120105060000"]
    assert cell.send("605#4000120200000000") == ["585#4300120285050000"]
