"""NMT: the pure transition table and the gating of services per state (CiA 301 7.3.2)."""

import pytest

from drives.cia301.nmt import (
    RESET_COMMUNICATION,
    RESET_NODE,
    NmtState,
    emcy_allowed,
    nmt_transition,
    pdo_allowed,
    sdo_allowed,
    sync_allowed,
)

PRE, OP, STOP = NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL, NmtState.STOPPED
CASES = [
    (state, command, expected)
    for state in (PRE, OP, STOP)
    for command, expected in (
        (0x01, OP),
        (0x02, STOP),
        (0x80, PRE),
        (0x81, RESET_NODE),
        (0x82, RESET_COMMUNICATION),
        (0x00, None),
        (0x03, None),
        (0x7F, None),
        (0xFF, None),
    )
]


@pytest.mark.parametrize(("state", "command", "expected"), CASES)
def test_transition_table(state, command, expected):
    assert nmt_transition(state, command) == expected


@pytest.mark.parametrize(
    ("state", "sdo", "pdo", "emcy", "sync"),
    [
        (NmtState.INITIALISING, False, False, False, False),
        (PRE, True, False, True, True),
        (OP, True, True, True, True),
        (STOP, False, False, False, False),
    ],
)
def test_services_per_state(state, sdo, pdo, emcy, sync):
    assert (sdo_allowed(state), pdo_allowed(state), emcy_allowed(state), sync_allowed(state)) == (
        sdo,
        pdo,
        emcy,
        sync,
    )


@pytest.mark.parametrize(
    ("commands", "state", "heartbeat"),
    [
        ([], "PRE-OPERATIONAL", "705#7F"),
        (["000#0105"], "OPERATIONAL", "705#05"),
        (["000#0205"], "STOPPED", "705#04"),
        (["000#0105", "000#0205", "000#8005"], "PRE-OPERATIONAL", "705#7F"),
        (["000#0205", "000#0100"], "OPERATIONAL", "705#05"),
        (["000#0105", "000#0106"], "OPERATIONAL", "705#05"),  # other node: ignored
        (["000#01"], "PRE-OPERATIONAL", "705#7F"),  # wrong length: ignored
        (["000#0705"], "PRE-OPERATIONAL", "705#7F"),  # unknown command: ignored
    ],
)
def test_state_reached_and_heartbeat_reports_it(cell, app, slave, commands, state, heartbeat):
    cell.send("605#2B1710000A000000")  # 0x1017 = 10 ms
    for command in commands:
        cell.send(command)
    assert slave.state.label == state
    assert [f for f in cell.advance(0.01) if f.startswith("705#")] == [heartbeat]


def test_reset_communication_restores_communication_objects_only(cell, app, slave):
    cell.send("605#2B1710000A000000")
    cell.send("605#2F02180205000000")  # TPDO3 transmission type 5
    app.values[(0x6065, 0)] = 99  # an application object survives
    assert cell.send("000#8205") == ["705#00"]
    assert slave.od.get(0x1017, 0) == 0
    assert slave.od.get(0x1802, 2) == 1  # back to the EDS default
    assert app.values[(0x6065, 0)] == 99


def test_reset_node_restores_manufacturer_storage(cell, app, slave):
    cell.send("605#2100210001000000")
    cell.send("605#0D5A000000000000")  # "Z"
    assert slave.od.get(0x2100, 0) == "Z"
    cell.send("000#8205")
    assert slave.od.get(0x2100, 0) == "Z"
    cell.send("000#8105")
    assert slave.od.get(0x2100, 0) == "axis"


def test_sync_in_pre_operational_reaches_the_application_without_pdos(cell, app, slave):
    assert cell.send("080#") == []
    assert app.sync_count == 1


def test_heartbeat_stops_while_initialising_only(cell, app, slave):
    cell.send("605#2B1710000A000000")
    cell.send("000#0205")
    out = []
    for _ in range(20):
        out += cell.advance(0.001)
    assert out == ["705#04", "705#04"]


def test_optional_reset_hook_tells_node_from_communication(cell, app, slave):
    scopes = []
    app.on_nmt_reset = scopes.append
    cell.send("000#8205")
    cell.send("000#8105")
    assert scopes == ["communication", "node"]
