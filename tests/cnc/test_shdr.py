"""SHDR adapter: the pure formatter (table tests) and the TCP shell over real sockets."""

from __future__ import annotations

import socket
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cnc.faces.loop_thread import LoopThread
from cnc.faces.shdr import ShdrAdapter, ShdrFormatter, escape, shdr_items, shdr_timestamp
from cnc.status import Alarm, AxisStatus, CanBusLoad, MachineStatus
from mtconnect.shdr import parse_line, tokenize

TS = "2026-11-21T06:00:00.000000Z"
AXES = ("X", "Y", "Z")
BASE = MachineStatus(axes={a: AxisStatus(0.0, 0.0) for a in AXES})
F = ShdrFormatter(AXES)


def changed(**kw) -> list[str]:
    cur = MachineStatus(**{**_fields(BASE), **kw})
    return F.diff(BASE, cur, TS)


def _fields(s: MachineStatus) -> dict:
    return {name: getattr(s, name) for name in s.__dataclass_fields__}


# --- one row per data item: the field change and the single SHDR line it gives -----------

VALUE_CASES = [
    ({"execution": "ACTIVE"}, "exec|ACTIVE"),
    ({"execution": "FEED_HOLD"}, "exec|FEED_HOLD"),
    ({"controller_mode": "MANUAL", "mode_detail": "REF"}, "mode|MANUAL|mode_detail|REF"),
    (
        {"controller_mode": "MANUAL_DATA_INPUT", "mode_detail": "MDI"},
        "mode|MANUAL_DATA_INPUT|mode_detail|MDI",
    ),
    ({"program": "O1000"}, "program|O1000"),
    ({"line": 42}, "line|42"),
    ({"block": "N10 G1 X10 F600"}, "block|N10 G1 X10 F600"),
    ({"path_feed_rate": 600.0}, "path_feedrate|10.000"),  # mm/min -> mm/s
    ({"axes": {**BASE.axes, "X": AxisStatus(-12.5, -12.49996)}}, "Xact|-12.5000|Xcmd|-12.5000"),
    ({"axes": {**BASE.axes, "Z": AxisStatus(0.0, -3.25)}}, "Zcmd|-3.2500"),
    ({"spindle_speed": 1200.0}, "Cspeed|1200.0"),
    ({"spindle_load": 37.25}, "Cload|37.2"),
    ({"spindle_override": 110.0}, "Covr|110"),
    ({"feed_override": 50.0}, "feed_ovr|50"),
    ({"rapid_override": 25.0}, "rapid_ovr|25"),
    ({"part_count": 7}, "part_count|7"),
    ({"emergency_stop": "TRIGGERED"}, "estop|TRIGGERED"),
    ({"can_bus_load": CanBusLoad(31.04, 48.96)}, "bus_load|31.0|bus_load_peak|49.0"),
    ({"plc_scan_time_ms": 0.8125}, "plc_scan|0.812"),
    ({"adaptive_control": "LIMITING"}, "acc|LIMITING"),
    ({"unreferenced": ("X", "Z")}, "referenced|NOT_REFERENCED X Z"),
    (
        {"cycle_start_refused": "cycle start refused: machine not homed (X)"},
        "start_refused|cycle start refused: machine not homed (X)",
    ),
]


@pytest.mark.parametrize(("change", "expected"), VALUE_CASES)
def test_each_data_item_changes_alone(change, expected):
    assert changed(**change) == [f"{TS}|{expected}"]


def test_no_change_no_lines():
    assert F.diff(BASE, BASE, TS) == []


def test_negative_zero_is_zero():
    lines = changed(axes={**BASE.axes, "X": AxisStatus(-0.00001, 0.0)})
    assert lines == []  # -0.0000 would be a spurious change


# --- conditions ----------------------------------------------------------------------------

FOLLOWING = Alarm(1012, "following error X", "DRIVE", "FAULT", axis="X")
PARITY = Alarm(2001, "parity error at byte 17", "DNC", "FAULT")
DOOR = Alarm(7003, "door open", "PLC", "WARNING")
BUS = Alarm(8100, "bus off", "BUS", "FAULT")
SPINDLE = Alarm(5001, "spindle drive fault", "DRIVE", "FAULT")  # no axis: Axes condition
NC = Alarm(3010, "soft limit X+", "NC", "FAULT", axis="X")

CONDITION_CASES = [
    ((), (FOLLOWING,), ["Xservo|FAULT|1012|FAULT||following error X"]),
    ((), (PARITY,), ["dnc_cond|FAULT|2001|FAULT||parity error at byte 17"]),
    ((), (DOOR,), ["plc_cond|WARNING|7003|WARNING||door open"]),
    ((), (BUS,), ["bus_cond|FAULT|8100|FAULT||bus off"]),
    ((), (SPINDLE,), ["servo|FAULT|5001|FAULT||spindle drive fault"]),
    ((), (NC,), ["nc_cond|FAULT|3010|FAULT||soft limit X+"]),
    ((FOLLOWING,), (), ["Xservo|NORMAL||||"]),  # the last alarm reset clears the condition
    ((DOOR, Alarm(7004, "low air", "PLC", "WARNING")), (DOOR,), ["plc_cond|NORMAL|7004|||"]),
    (
        (DOOR,),
        (DOOR, Alarm(7004, "low air", "PLC", "WARNING")),
        ["plc_cond|WARNING|7004|WARNING||low air"],
    ),
    (
        (DOOR,),
        (Alarm(7003, "door open", "PLC", "FAULT"),),
        ["plc_cond|FAULT|7003|FAULT||door open"],
    ),
    ((FOLLOWING, PARITY), (FOLLOWING, PARITY), []),
]


@pytest.mark.parametrize(("before", "after", "expected"), CONDITION_CASES)
def test_conditions_raise_and_clear(before, after, expected):
    prev = MachineStatus(**{**_fields(BASE), "alarms": before})
    cur = MachineStatus(**{**_fields(BASE), "alarms": after})
    assert F.diff(prev, cur, TS) == [f"{TS}|{e}" for e in expected]


def test_escaping_of_pipe_in_alarm_text_round_trips():
    alarm = Alarm(9, 'bad "block" | N10 \\ end', "NC")
    prev = BASE
    cur = MachineStatus(**{**_fields(BASE), "alarms": (alarm,)})
    (line,) = F.diff(prev, cur, TS)
    assert line == f'{TS}|nc_cond|FAULT|9|FAULT||"bad \\"block\\" \\| N10 \\\\ end"'
    ts, values = parse_line(line, {"nc_cond"})
    assert ts == TS
    assert values[0].value == alarm.text and values[0].native_code == "9"


@pytest.mark.parametrize(
    "text",
    ["plain", "a|b", "|", '"quoted"', "back\\slash", "  padded  ", "x|y|z", 'mix "|\\'],
)
def test_escape_is_read_back_by_the_agent_tokenizer(text):
    tokens = tokenize(f"{TS}|program|{escape(text)}|line|5")
    assert tokens == [TS, "program", text.strip(), "line", "5"]


@settings(max_examples=300, deadline=None)
@given(st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")), max_size=60))
def test_any_text_survives_escape_and_tokenize(text):
    assert tokenize(f"{TS}|block|{escape(text)}|line|7") == [TS, "block", text.strip(), "line", "7"]


def test_line_breaks_in_text_cannot_split_a_record():
    assert escape("two\nlines\r\nhere") == "two lines here"


def test_unavailable_machine_reports_every_item_unavailable():
    cur = MachineStatus(**{**_fields(BASE), "availability": "UNAVAILABLE"})
    lines = F.diff(BASE, cur, TS)
    values = dict(zip(*[iter(lines[0].split("|")[1:])] * 2, strict=True))
    keys = [i.key for i in shdr_items(AXES) if i.category != "CONDITION"]
    changed_keys = [k for k in keys if k in values]
    assert values["avail"] == "UNAVAILABLE"
    assert all(values[k] == "UNAVAILABLE" for k in changed_keys)
    conds = [i.key for i in shdr_items(AXES) if i.category == "CONDITION"]
    assert lines[1:] == [f"{TS}|{k}|UNAVAILABLE||||" for k in conds]
    # and coming back states every value again
    back = F.diff(cur, BASE, TS)
    assert "avail|AVAILABLE" in back[0] and "Xact|0.0000" in back[0]
    assert back[1:] == [f"{TS}|{k}|NORMAL||||" for k in conds]


def test_missing_axis_is_unavailable():
    s = MachineStatus(axes={"X": AxisStatus(1.0, 1.0)})
    line = F.dump(s, TS)[0]
    assert "|Yact|UNAVAILABLE|Ycmd|UNAVAILABLE|" in line


def test_dump_states_every_item_once():
    lines = F.dump(BASE, TS)
    keys = []
    for line in lines:
        tokens = tokenize(line)[1:]
        conds = {i.key for i in F.items if i.category == "CONDITION"}
        keys.append(tokens[0]) if tokens[0] in conds else keys.extend(tokens[0::2])
    assert sorted(keys) == sorted(i.key for i in F.items)


def test_lathe_and_five_axis_spindle_names():
    assert [i.key for i in shdr_items(("X", "Z")) if i.component == "Spindle"][0] == "Cspeed"
    five = shdr_items(("X", "Y", "Z", "B", "C"))
    assert {i.key for i in five if i.component == "Spindle"} == {"Sspeed", "Sload", "Sovr", "Smode"}
    assert next(i for i in five if i.key == "Bact").type == "ANGLE"


def test_timestamps_come_from_the_caller():
    assert shdr_timestamp(0.25) == "1970-01-01T00:00:00.250000Z"
    assert shdr_timestamp(TS) == TS
    assert F.dump(BASE, 0.0)[0].startswith("1970-01-01T00:00:00.000000Z|avail|AVAILABLE|")


def test_many_items_split_into_bounded_lines():
    axes = tuple("XYZABCUVW")
    f = ShdrFormatter(axes)
    lines = f.dump(MachineStatus(), TS)
    data_lines = [ln for ln in lines if len(tokenize(ln)) > 7 or "|NORMAL|" not in ln]
    assert len(data_lines) >= 2
    assert all(len(tokenize(ln)) <= 1 + 2 * 32 for ln in data_lines)


@pytest.mark.parametrize(
    ("field", "value"),
    [("execution", "RUNNING"), ("controller_mode", "REF"), ("emergency_stop", "ON")],
)
def test_status_refuses_unknown_words(field, value):
    with pytest.raises(ValueError, match=field):
        MachineStatus(**{field: value})


def test_alarm_source_checked():
    with pytest.raises(ValueError, match="alarm source"):
        MachineStatus(alarms=(Alarm(1, "x", "SERVO"),))


# --- the TCP shell --------------------------------------------------------------------------


@pytest.fixture
def adapter():
    loop = LoopThread("shdr-test").start()
    a = ShdrAdapter(AXES, heartbeat_ms=250)
    loop.run(a.start)
    yield a, loop
    loop.run(a.stop)
    loop.stop()


class Reader:
    """Accumulates everything a socket has sent; waits (bounded) for a condition on it."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.buf = sock, b""

    def until(self, predicate, timeout: float = 5.0) -> list[str]:
        self.sock.settimeout(timeout)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            lines = self.buf.decode().splitlines()
            if predicate(lines):
                return lines
            chunk = self.sock.recv(65536)
            if not chunk:
                break
            self.buf += chunk
        raise AssertionError(f"condition not met; got {self.buf.decode()!r}")


def _read_until(sock: socket.socket, predicate, timeout: float = 5.0) -> list[str]:
    return Reader(sock).until(predicate, timeout)


def test_ping_pong_over_a_real_socket(adapter):
    a, _ = adapter
    with socket.create_connection(("127.0.0.1", a.bound_port)) as s:
        r = Reader(s)
        s.sendall(b"* PING\n")
        lines = r.until(lambda ls: "* PONG 250" in ls)
        assert lines[0] == "* shdrVersion: 2"
        s.sendall(b"* PING\r\n")
        r.until(lambda ls: ls.count("* PONG 250") == 2)
    assert a.stats.pings == 2


def test_new_agent_gets_a_full_dump_then_changes(adapter):
    a, _ = adapter
    a.publish(BASE, TS)  # before anyone is connected
    with socket.create_connection(("127.0.0.1", a.bound_port)) as s:
        r = Reader(s)
        lines = r.until(lambda ls: any("Zservo|NORMAL" in ln for ln in ls))
        assert lines[1] == F.dump(BASE, TS)[0]
        assert _wait(lambda: a.clients == 1)
        cur = MachineStatus(**{**_fields(BASE), "execution": "ACTIVE", "alarms": (DOOR,)})
        sent = a.publish(cur, "2026-11-21T06:00:01.000000Z")
        assert sent == [
            "2026-11-21T06:00:01.000000Z|exec|ACTIVE",
            "2026-11-21T06:00:01.000000Z|plc_cond|WARNING|7003|WARNING||door open",
        ]
        lines = r.until(lambda ls: any("door open" in ln for ln in ls))
        assert lines[-2:] == sent
    # a second agent connecting now gets the new state as its dump
    with socket.create_connection(("127.0.0.1", a.bound_port)) as s2:
        lines = _read_until(s2, lambda ls: any("door open" in ln for ln in ls))
        assert "exec|ACTIVE" in lines[1]


def test_publish_before_start_and_refuses_bad_heartbeat():
    a = ShdrAdapter(AXES)
    assert a.publish(BASE, TS) == F.dump(BASE, TS)
    assert a.publish(BASE, TS) == []
    with pytest.raises(ValueError, match="heartbeat"):
        ShdrAdapter(AXES, heartbeat_ms=0)
    with pytest.raises(RuntimeError):
        _ = a.bound_port


def test_for_machine_uses_the_configured_face():
    from cnc.config import builtin_machine

    a = ShdrAdapter.for_machine(builtin_machine("lathe2"))
    assert a.port == builtin_machine("lathe2").ports.shdr and a.formatter.axes == ("X", "Z")


def _wait(predicate, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return False
