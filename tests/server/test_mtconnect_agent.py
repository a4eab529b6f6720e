"""The agent core: sequence semantics, parameter checks and errors as cppagent has them."""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mtconnect import Agent, CircularBuffer, Observation, build_device
from mtconnect.buffer import Checkpoint
from tests.server.test_mtconnect_support import (
    FakeClock,
    error_code,
    header,
    parse,
    schema_problems,
    seqs,
    small_agent,
    values,
)

TS = "2026-11-21T06:00:00.000000Z"


def feed(agent: Agent, n: int, device: str = "m1") -> None:
    """n observations that each change `line`."""
    for i in range(n):
        agent.ingest_line(device, f"{TS}|line|{1000 + agent.buffer.next_sequence + i}")


def doc(agent: Agent, kind: str, device: str | None = None, **params) -> tuple[int, str]:
    return agent.request(kind, device, {k.rstrip("_"): str(v) for k, v in params.items()})


# --- the empty agent -------------------------------------------------------------------------


def test_every_item_starts_unavailable_with_its_own_sequence():
    a = small_agent()
    n = sum(len(d.all_items) for d in a.devices)
    status, text = doc(a, "current")
    root = parse("Streams", text)
    assert status == 200
    h = header(root)
    assert (h["firstSequence"], h["lastSequence"], h["nextSequence"]) == ("1", str(n), str(n + 1))
    assert sorted(seqs(root)) == list(range(1, n + 1))
    assert all(v == ["UNAVAILABLE"] for v in values(root).values())


def test_instance_id_and_buffer_size_in_header():
    a = small_agent(buffer_size=64, instance_id=77)
    h = header(parse("Streams", doc(a, "current")[1]))
    assert h["instanceId"] == "77" and h["bufferSize"] == "64"
    assert small_agent(clock=FakeClock(1234.5)).instance_id == 1234


# --- sample: from / count / to ------------------------------------------------------------


def test_sample_default_count_is_100_from_the_first_sequence():
    a = small_agent()
    feed(a, 150)
    root = parse("Streams", doc(a, "sample")[1])
    assert seqs(root) == list(range(1, 101))
    assert header(root)["nextSequence"] == "101"


def test_sample_from_and_count():
    a = small_agent()
    feed(a, 50)
    root = parse("Streams", doc(a, "sample", from_=60, count=5)[1])
    assert seqs(root) == [60, 61, 62, 63, 64]
    assert header(root)["nextSequence"] == "65"


def test_empty_stream_when_nothing_new():
    a = small_agent()
    nxt = a.buffer.next_sequence
    root = parse("Streams", doc(a, "sample", from_=nxt)[1])
    assert seqs(root) == []
    assert header(root)["nextSequence"] == str(nxt)


def test_negative_count_gives_the_latest():
    a = small_agent()
    feed(a, 20)
    last = a.buffer.last_sequence
    root = parse("Streams", doc(a, "sample", count=-5)[1])
    assert seqs(root) == list(range(last - 4, last + 1))
    # cppagent walks backwards and reports where it stopped
    assert header(root)["nextSequence"] == str(last - 5)


def test_negative_count_from_walks_back_from_from():
    a = small_agent()
    feed(a, 20)
    root = parse("Streams", doc(a, "sample", from_=30, count=-3)[1])
    assert seqs(root) == [28, 29, 30]


def test_from_to_is_inclusive_and_next_is_to_plus_one():
    a = small_agent()
    feed(a, 20)
    root = parse("Streams", doc(a, "sample", from_=10, to=15)[1])
    assert seqs(root) == list(range(10, 16))
    h = header(root)
    assert h["nextSequence"] == "16"
    assert h["firstSequence"] == "10"  # cppagent reports `from` as firstSequence here


def test_to_with_small_count_takes_the_last_before_to():
    a = small_agent()
    feed(a, 20)
    root = parse("Streams", doc(a, "sample", from_=10, to=20, count=3)[1])
    assert seqs(root) == [18, 19, 20]
    assert header(root)["nextSequence"] == "21"


def test_to_alone_counts_back_from_to():
    a = small_agent()
    root = parse("Streams", doc(a, "sample", to=12, count=4)[1])
    assert seqs(root) == [9, 10, 11, 12]


OUT_OF_RANGE = [
    # (params, message) for an agent of buffer size 1024 holding sequences 1..next-1
    ({"from": "0"}, "'from' must be greater than 0"),
    ({"from": "{next1}"}, "'from' must be less than {next1}"),
    ({"count": "0"}, "'count' must not be zero(0)"),
    ({"count": "{size1}"}, "'count' must be less than {size1}"),
    ({"count": "-{size1}"}, "'count' must be greater than -{size1}"),
    ({"from": "10", "to": "10"}, "'to' must be greater than 10"),
    ({"from": "10", "to": "9"}, "'to' must be greater than 10"),
    ({"to": "{next1}"}, "'to' must be less than {next1}"),
    ({"to": "12", "count": "-2"}, "'count' must be greater than 0"),
]


@pytest.mark.parametrize(("params", "message"), OUT_OF_RANGE)
def test_sample_out_of_range_like_cppagent(params, message):
    a = small_agent(buffer_size=1024)
    nxt = a.buffer.next_sequence
    fill = {"next1": nxt + 1, "size1": 1025}
    status, text = a.request("sample", None, {k: v.format(**fill) for k, v in params.items()})
    assert status == 400
    assert error_code(text) == ("OUT_OF_RANGE", message.format(**fill))


def test_from_below_first_after_wrap_is_out_of_range():
    a = small_agent(buffer_size=16)
    feed(a, 40)
    first = a.buffer.first_sequence
    assert first > 1 and a.buffer.next_sequence - first == 16
    status, text = doc(a, "sample", from_=first - 1)
    assert (status, error_code(text)) == (
        400,
        ("OUT_OF_RANGE", f"'from' must be greater than {first - 1}"),
    )
    # the default count=100 is out of range for a 16-slot buffer, as in cppagent
    assert error_code(doc(a, "sample", from_=first)[1]) == (
        "OUT_OF_RANGE",
        "'count' must be less than 17",
    )
    root = parse("Streams", doc(a, "sample", from_=first, count=16)[1])
    assert seqs(root)[0] == first and header(root)["firstSequence"] == str(first)


# --- current?at ------------------------------------------------------------------------------


def test_current_at_is_the_state_at_that_sequence():
    a = small_agent(checkpoint_frequency=7)
    a.ingest_line("m1", f"{TS}|exec|ACTIVE|line|1")
    at = a.buffer.last_sequence
    a.ingest_line("m1", f"{TS}|exec|FEED_HOLD|line|2")
    v = values(parse("Streams", doc(a, "current", at=at)[1]))
    assert v["m1_exec"] == ["ACTIVE"] and v["m1_line"] == ["1"]
    v = values(parse("Streams", doc(a, "current")[1]))
    assert v["m1_exec"] == ["FEED_HOLD"]


@pytest.mark.parametrize(("at", "message"), [(0, "greater than 0"), ("next", "less than {n}")])
def test_current_at_out_of_range(at, message):
    a = small_agent()
    n = a.buffer.next_sequence
    status, text = doc(a, "current", at=n if at == "next" else at)
    assert status == 400
    assert error_code(text) == ("OUT_OF_RANGE", f"'at' must be {message.format(n=n)}")


@settings(max_examples=40, deadline=None)
@given(
    size=st.integers(2, 12),
    freq=st.integers(1, 5),
    ops=st.lists(
        st.tuples(st.integers(0, 2), st.sampled_from(["A", "B", "N1", "N2"])), max_size=60
    ),
)
def test_checkpoint_at_equals_replaying_the_whole_history(size, freq, ops):
    dev = build_device("m", ["X"])
    cond = dev.by_key["nc_cond"]
    line = dev.by_key["line"]
    buf = CircularBuffer(size, freq)
    history = []
    for kind, v in ops:
        if kind == 0:
            obs = Observation(line, TS, v)
        elif v in ("A", "B"):
            obs = Observation(cond, TS, "t", level="FAULT", native_code=v)
        else:
            obs = Observation(cond, TS, "", level="NORMAL", native_code="A" if v == "N1" else "")
        history.append(buf.add(obs))
    for at in range(buf.first_sequence, buf.next_sequence):
        replay = Checkpoint()
        for obs in history[:at]:
            replay.add(obs)
        got = buf.checkpoint_at(at)
        for di in (cond, line):
            assert got.get(di.id) == replay.get(di.id), at


def test_sequences_are_not_truncated_at_32_bits():
    dev = build_device("m", ["X"])
    buf = CircularBuffer(8)
    buf.next_sequence = buf.first_sequence = 2**33 + 5
    obs = buf.add(Observation(dev.by_key["line"], TS, "1"))
    assert obs.sequence == 2**33 + 5 and buf.get(2**33 + 5) is obs


# --- path, device, parameter errors -----------------------------------------------------


@pytest.mark.parametrize(
    ("device", "path", "expected"),
    [
        (
            None,
            '//Linear[@name="X"]',
            {"m1_Xact", "m1_Xcmd", "m1_Xservo", "m2_Xact", "m2_Xcmd", "m2_Xservo"},
        ),
        ("m1", '//Linear[@name="X"]', {"m1_Xact", "m1_Xcmd", "m1_Xservo"}),
        (None, "//DataItem[@type='EXECUTION']", {"m1_exec", "m2_exec"}),
        (
            "m2",
            "//Controller//DataItem[@category='CONDITION']",
            {"m2_nc_cond", "m2_plc_cond", "m2_bus_cond", "m2_dnc_cond"},
        ),
        (
            None,
            '//DataItem[@name="exec"]|//DataItem[@name="line"]',
            {"m1_exec", "m2_exec", "m1_line", "m2_line"},
        ),
        (
            None,
            '/MTConnectDevices/Devices/Device[@name="m2"]/DataItems/DataItem',
            {"m2_avail", "m2_asset_chg", "m2_asset_rem"},
        ),
        ("fmscell-m2", "//Path//DataItem[@type='PROGRAM']", {"m2_program"}),
    ],
)
def test_path_filter(device, path, expected):
    a = small_agent()
    status, text = doc(a, "current", device, path=path)
    assert status == 200, text
    assert set(values(parse("Streams", text))) == expected


@pytest.mark.parametrize(
    "path",
    ["//Linear[@name='Q']", "//DataItem[@type=", "Linear", "//Nothing", "//a[(1)]", ""],
)
def test_bad_or_empty_path_is_invalid_xpath(path):
    a = small_agent()
    status, text = doc(a, "sample", path=path)
    code, message = error_code(text)
    assert (status, code) == (400, "INVALID_PATH")
    assert message.startswith("The path could not be parsed. Invalid syntax:")


@pytest.mark.parametrize(
    "path", ["//Foo[", "//Foo[@", "//Foo[1", "//Foo]", "//Foo[@name=']", "//*[@x='1'][", "//["]
)
@pytest.mark.parametrize("kind", ["current", "sample"])
def test_unparsable_path_answers_the_reference_agent_error_without_python_text(kind, path):
    """cppagent's answer to a path it cannot parse: the message names the path, nothing
    else (issue 14, item 12: "//Foo[" leaked "'NoneType' object is not callable")."""
    a = small_agent()
    status, text = doc(a, kind, path=path)
    assert status == 400
    assert error_code(text) == (
        "INVALID_PATH",
        f"The path could not be parsed. Invalid syntax: {path}",
    )
    for leak in ("NoneType", "object", "Traceback", "callable", "Exception"):
        assert leak not in text
    assert schema_problems(text) == []


@pytest.mark.parametrize("kind", ["probe", "current", "sample"])
def test_unknown_device(kind):
    status, text = small_agent().request(kind, "nope", {})
    assert (status, error_code(text)) == (404, ("NO_DEVICE", "Could not find the device 'nope'"))


@pytest.mark.parametrize(
    ("kind", "params", "code"),
    [
        ("sample", {"count": "abc"}, "INVALID_REQUEST"),
        ("sample", {"from": "-1"}, "INVALID_REQUEST"),
        ("sample", {"count": "99999999999"}, "INVALID_REQUEST"),
        ("current", {"at": "1.5"}, "INVALID_REQUEST"),
        ("sample", {"interval": "100"}, "UNSUPPORTED"),
        ("current", {"interval": "100"}, "UNSUPPORTED"),
        ("probe", {"format": "json"}, "UNSUPPORTED"),
        ("probe", {"deviceType": "Robot"}, "INVALID_REQUEST"),
        ("sample", {"pretty": "maybe"}, "INVALID_REQUEST"),
        ("assets", {}, "INVALID_URI"),
    ],
)
def test_parameter_errors(kind, params, code):
    status, text = small_agent().request(kind, None, params)
    assert status in (400, 404)
    assert error_code(text)[0] == code


def test_interval_range_is_checked_before_unsupported():
    status, text = small_agent().request("sample", None, {"interval": "-2"})
    assert error_code(text) == ("OUT_OF_RANGE", "'interval' must be greater than -1")


# --- ingest: conditions, duplicates, disconnects ------------------------------------------


def test_condition_activation_and_clearing():
    a = small_agent()
    a.ingest_line("m1", f"{TS}|nc_cond|FAULT|1012|FAULT||following error X")
    a.ingest_line("m1", f"{TS}|nc_cond|WARNING|2001|WARNING|HIGH|low air")
    assert a.value("m1", "nc_cond") == "FAULT,WARNING"
    v = values(parse("Streams", doc(a, "current", "m1", path="//DataItem[@name='nc_cond']")[1]))
    assert v == {"m1_nc_cond": ["FAULT", "WARNING"]}
    a.ingest_line("m1", f"{TS}|nc_cond|NORMAL|1012|||")
    assert a.value("m1", "nc_cond") == "WARNING"
    a.ingest_line("m1", f"{TS}|nc_cond|NORMAL||||")
    assert a.value("m1", "nc_cond") == "NORMAL"


def test_condition_attributes_in_the_document():
    a = small_agent()
    a.ingest_line("m1", f"{TS}|Xservo|FAULT|1012|FAULT|HIGH|following error X")
    root = parse("Streams", doc(a, "current", "m1", path="//DataItem[@name='Xservo']")[1])
    (fault,) = [e for e in root.iter() if e.get("dataItemId") == "m1_Xservo"]
    assert fault.tag.endswith("}Fault") and fault.text == "following error X"
    assert (fault.get("nativeCode"), fault.get("qualifier"), fault.get("type")) == (
        "1012",
        "HIGH",
        "ACTUATOR",
    )


def test_duplicates_are_filtered():
    a = small_agent()
    assert a.ingest_line("m1", f"{TS}|exec|ACTIVE") == 1
    assert a.ingest_line("m1", f"{TS}|exec|ACTIVE") == 0
    assert a.ingest_line("m1", f"{TS}|nc_cond|NORMAL||||") == 1
    assert a.ingest_line("m1", f"{TS}|nc_cond|NORMAL||||") == 0
    assert a.ingest_line("m1", f"{TS}|nc_cond|NORMAL|77|||") == 0  # clears nothing


def test_unavailable_is_not_duplicated_when_disconnected():
    a = small_agent()
    a.ingest_line("m1", f"{TS}|exec|ACTIVE|nc_cond|NORMAL||||")
    assert a.disconnected("m1") == 2  # only what was available changes
    assert a.disconnected("m1") == 0
    assert a.value("m1", "exec") == "UNAVAILABLE"
    assert a.value("m1", "nc_cond") == "UNAVAILABLE"
    assert a.value("m1", "asset_chg") == "UNAVAILABLE"


def test_adapter_timestamps_are_kept_unless_ignored():
    a = small_agent()
    a.ingest_line("m1", "2026-01-02T03:04:05.5|exec|ACTIVE")
    assert a.latest("m1", "exec").timestamp == "2026-01-02T03:04:05.5Z"
    b = small_agent(ignore_timestamps=True, clock=FakeClock(0.0))
    b.ingest_line("m1", "2026-01-02T03:04:05.5|exec|ACTIVE")
    assert b.latest("m1", "exec").timestamp == "1970-01-01T00:00:00.000000Z"
    b.ingest_line("m1", "garbage|exec|READY")
    assert b.latest("m1", "exec").timestamp == "1970-01-01T00:00:00.000000Z"


def test_unavailable_literals_and_unknown_keys():
    a = small_agent()
    a.ingest_line("m1", f"{TS}|exec|ACTIVE|bogus|1|line|5")
    assert a.value("m1", "line") == "5"
    a.ingest_line("m1", f"{TS}|exec|@UNAVAILABLE@|line|unavailable")
    assert a.value("m1", "exec") == "UNAVAILABLE" and a.value("m1", "line") == "UNAVAILABLE"


def test_text_with_markup_and_japanese_characters():
    a = small_agent()
    a.ingest_line("m1", f'{TS}|program|"O1 <&> 日本語 \\| x"')
    v = values(parse("Streams", doc(a, "current", "m1", path="//DataItem[@name='program']")[1]))
    assert v == {"m1_program": ["O1 <&> 日本語 | x"]}


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=120))
def test_malformed_lines_never_crash_ingest(line):
    a = _FUZZ_AGENT
    a.ingest_line("m1", line)
    status, text = a.request("current", "m1", {})
    assert status == 200
    parse("Streams", text)
    assert schema_problems(text) == []  # nothing an adapter sends makes a document invalid


@settings(max_examples=150, deadline=None)
@given(
    key=st.sampled_from(sorted(build_device("m1", ["X", "Y", "Z"]).by_key)),
    fields=st.lists(
        st.one_of(
            st.sampled_from(["1.5", "-0", "1e3", "ACTIVE", "HIGH", "low", "UNAVAILABLE", "FAULT"]),
            st.text(alphabet='ab1.-<&>|" NORMALWARNING', max_size=8),
        ),
        min_size=1,
        max_size=6,
    ),
    stamp=st.sampled_from([TS, "2026-13-40T99:00:00Z", "x", "2026-02-29T00:00:00"]),
)
def test_any_adapter_line_for_a_known_key_keeps_documents_valid(key, fields, stamp):
    a = _FUZZ_AGENT
    a.ingest_line("m1", "|".join([stamp, key, *fields]))
    assert schema_problems(a.request("current", "m1", {})[1]) == []


_FUZZ_AGENT = small_agent(buffer_size=256)


def test_probe_document():
    a = small_agent()
    root = parse("Devices", doc(a, "probe")[1])
    ns = "{urn:mtconnect.org:MTConnectDevices:2.5}"
    devices = root.findall(f"{ns}Devices/{ns}Device")
    assert [d.get("name") for d in devices] == ["m1", "m2"]
    ids = [e.get("id") for e in root.iter() if e.get("id")]
    assert len(ids) == len(set(ids))  # ids are document-unique
    linear = root.findall(f".//{ns}Linear")
    assert [c.get("name") for c in linear] == ["X", "Y", "Z", "X", "Z"]
    xact = next(e for e in root.iter(f"{ns}DataItem") if e.get("id") == "m1_Xact")
    assert xact.attrib == {
        "category": "SAMPLE",
        "id": "m1_Xact",
        "name": "Xact",
        "type": "POSITION",
        "subType": "ACTUAL",
        "units": "MILLIMETER",
    }
    one = parse("Devices", doc(a, "probe", "m2")[1])
    assert [d.get("name") for d in one.findall(f"{ns}Devices/{ns}Device")] == ["m2"]


def test_agent_from_the_default_cell():
    from server.config import default_cell_config

    a = Agent.from_cell(default_cell_config(), clock=FakeClock())
    assert [d.name for d in a.devices] == list(default_cell_config().machines)


def test_refuses_empty_or_duplicate_devices():
    with pytest.raises(ValueError):
        Agent([])
    with pytest.raises(ValueError, match="unique"):
        Agent([build_device("a", ["X"]), build_device("a", ["X"])])


def test_random_streams_keep_header_invariants():
    rng = random.Random(7)
    a = small_agent(buffer_size=32, checkpoint_frequency=5)
    for _ in range(200):
        a.ingest_line(rng.choice(["m1", "m2"]), f"{TS}|line|{rng.randint(0, 9)}")
        h = header(parse("Streams", doc(a, "current")[1]))
        first, last, nxt = int(h["firstSequence"]), int(h["lastSequence"]), int(h["nextSequence"])
        assert nxt == last + 1 and nxt - first <= 32 and first >= 1


# --- structure: what the MTConnect 2.5 schemas require, checked by hand ------------------

STANDARD_ELEMENTS = {
    "AVAILABILITY": "Availability",
    "EMERGENCY_STOP": "EmergencyStop",
    "CONTROLLER_MODE": "ControllerMode",
    "EXECUTION": "Execution",
    "PROGRAM": "Program",
    "LINE_NUMBER": "LineNumber",
    "BLOCK": "Block",
    "PATH_FEEDRATE": "PathFeedrate",
    "PATH_FEEDRATE_OVERRIDE": "PathFeedrateOverride",
    "PART_COUNT": "PartCount",
    "POSITION": "Position",
    "ROTARY_VELOCITY": "RotaryVelocity",
    "ROTARY_VELOCITY_OVERRIDE": "RotaryVelocityOverride",
    "ROTARY_MODE": "RotaryMode",
    "LOAD": "Load",
    "ASSET_CHANGED": "AssetChanged",
    "ASSET_REMOVED": "AssetRemoved",
    "x:MODE_DETAIL": "x:ModeDetail",
}


def test_streams_structure_matches_the_probe():
    from cnc.faces.shdr import ShdrFormatter
    from cnc.status import Alarm, AxisStatus, MachineStatus
    from mtconnect.model import pascal

    a = small_agent()
    f = ShdrFormatter(("X", "Y", "Z"))
    status = MachineStatus(
        execution="ACTIVE",
        axes={"X": AxisStatus(1.0, 1.0)},
        alarms=(Alarm(1, "a", "NC"), Alarm(2, "b", "NC", "WARNING")),
    )
    for line in f.dump(status, TS):
        a.ingest_line("m1", line)
    probe = parse("Devices", doc(a, "probe")[1])
    dns = "{urn:mtconnect.org:MTConnectDevices:2.5}"
    items = {e.get("id"): e.attrib for e in probe.iter(f"{dns}DataItem")}
    comps = {
        e.get("id"): e.tag.removeprefix(dns)
        for e in probe.iter()
        if e.get("id") and not e.tag.endswith("DataItem")
    }
    for t, name in STANDARD_ELEMENTS.items():
        assert pascal(t) == name
    root = parse("Streams", doc(a, "current")[1])
    sns = "{urn:mtconnect.org:MTConnectStreams:2.5}"
    xns = "{urn:fmscell:MTConnectStreams:2.5}"
    seen = set()
    for ds in root.find(f"{sns}Streams"):
        assert ds.tag == f"{sns}DeviceStream" and ds.get("uuid")
        for cs in ds:
            assert cs.tag == f"{sns}ComponentStream"
            assert comps[cs.get("componentId")] == cs.get("component")
            order = [g.tag.removeprefix(sns) for g in cs]
            assert order == sorted(order, key=["Samples", "Events", "Condition"].index)
            for group in cs:
                for obs in group:
                    di = items[obs.get("dataItemId")]
                    seen.add(di["id"])
                    assert int(obs.get("sequence")) >= 1
                    assert obs.get("timestamp").endswith("Z")
                    assert obs.get("name") == di["name"]
                    assert obs.get("subType") == di.get("subType")
                    tag = obs.tag.replace(sns, "").replace(xns, "x:")
                    if di["category"] == "CONDITION":
                        assert group.tag == f"{sns}Condition"
                        assert tag in ("Normal", "Warning", "Fault", "Unavailable")
                        assert obs.get("type") == di["type"]
                    else:
                        assert tag == pascal(di["type"])
                        wrapper = "Samples" if di["category"] == "SAMPLE" else "Events"
                        assert group.tag == f"{sns}{wrapper}"
                        if di["category"] == "SAMPLE" and obs.text != "UNAVAILABLE":
                            float(obs.text)
    assert set(items) == seen  # every data item of every device has a current value


# --- the MTConnect 2.5 schema rules, on every kind of document (docs/mtconnect.md) ---------


def _busy_cell_agent(**kw) -> Agent:
    """A mill and a lathe with every kind of value this agent publishes: samples with and
    without units, every event, conditions Normal/Warning/Fault/Unavailable (with and without
    native code and qualifier), and the lathe's adapter gone (everything UNAVAILABLE)."""
    from cnc.faces.shdr import ShdrFormatter
    from cnc.status import Alarm, AxisStatus, MachineStatus

    kw.setdefault("clock", FakeClock())
    a = Agent([build_device("mill", ["X", "Y", "Z"]), build_device("lathe", ["X", "Z"])], **kw)
    for name, axes in (("mill", ("X", "Y", "Z")), ("lathe", ("X", "Z"))):
        status = MachineStatus(
            execution="ACTIVE",
            mode_detail="AUTO",
            program='O1000 <&> "x"',
            line=120,
            block="G01 X1 F100",
            path_feed_rate=600.0,
            axes={ax: AxisStatus(1.5, 1.25) for ax in axes},
            spindle_speed=1200.0,
            spindle_load=12.5,
            part_count=3,
            adaptive_control="ACTIVE",
            alarms=(
                Alarm(1012, "following error", "DRIVE", "FAULT", "X"),
                Alarm(2001, "low air", "PLC", "WARNING"),
                Alarm(3, "nc", "NC", "FAULT"),
                Alarm(5, "dnc", "DNC", "FAULT"),
            ),
        )
        for line in ShdrFormatter(axes).dump(status, TS):
            a.ingest_line(name, line)
    a.ingest_line("mill", f"{TS}|bus_cond|WARNING|||HIGH|bus load high")
    a.ingest_line("mill", f"{TS}|nc_cond|NORMAL|3|||")
    a.disconnected("lathe")
    return a


SCHEMA_REQUESTS = [
    ("probe", None, {}),
    ("probe", "mill", {}),
    ("probe", "lathe", {}),
    ("probe", None, {"deviceType": "Device"}),
    ("current", None, {}),
    ("current", "mill", {}),
    ("current", "lathe", {}),
    ("current", None, {"at": "30"}),
    ("current", None, {"path": "//DataItem[@category='CONDITION']"}),
    ("current", "mill", {"path": "//Controller"}),
    ("sample", None, {"count": "1000"}),
    ("sample", None, {"count": "-1000"}),  # walks back to sequence 1
    ("sample", None, {"from": "5", "count": "20"}),
    ("sample", None, {"from": "10", "to": "60"}),
    ("sample", None, {"to": "40", "count": "5"}),
    ("sample", "lathe", {"count": "500"}),
    ("sample", None, {"path": '//Linear[@name="X"]', "count": "500"}),
    ("sample", None, {"from": "next"}),  # an empty page
    ("sample", None, {"from": "0"}),  # OUT_OF_RANGE
    ("current", None, {"at": "0"}),  # OUT_OF_RANGE
    ("current", "nope", {}),  # NO_DEVICE
    ("probe", None, {"deviceType": "Agent"}),  # NO_DEVICE: no Agent device is published
    ("sample", None, {"path": "//Nothing"}),  # INVALID_PATH
    ("sample", None, {"count": "abc"}),  # INVALID_REQUEST
    ("probe", None, {"deviceType": "Robot"}),  # INVALID_REQUEST
    ("probe", None, {"format": "json"}),  # UNSUPPORTED
    ("sample", None, {"interval": "100"}),  # UNSUPPORTED
    ("assets", None, {}),  # INVALID_URI
]


@pytest.mark.parametrize(("kind", "device", "params"), SCHEMA_REQUESTS)
def test_every_document_keeps_the_25_schema_rules(kind, device, params):
    a = _BUSY_AGENT
    if params.get("from") == "next":
        params = {"from": str(a.buffer.next_sequence)}
    status, text = a.request(kind, device, params)
    assert schema_problems(text) == [], (status, text[:300])


_BUSY_AGENT = _busy_cell_agent(buffer_size=4096)


def test_streamed_parts_keep_the_25_schema_rules():
    import asyncio

    from web_api.mtconnect import stream_parts

    a = _busy_cell_agent(buffer_size=64)
    plan = a.stream_plan("sample", None, {"interval": "10", "heartbeat": "10", "count": "5"})
    bodies = []

    async def sleep(_):
        a.ingest_line("mill", f"{TS}|line|{len(bodies) + 1}")

    async def take(n: int):
        gen = stream_parts(a, plan, "b", sleep=sleep, clock=lambda: 20.0 * len(bodies))
        async for part in gen:
            bodies.append(part.split(b"\r\n\r\n", 1)[1].rsplit(b"\r\n", 1)[0].decode())
            if len(bodies) == n:
                break
        await gen.aclose()

    asyncio.run(take(3))
    assert len(bodies) == 3
    for body in bodies:
        assert schema_problems(body) == []


def _first(text: str, local: str, **attrs) -> ET.Element:
    root = ET.fromstring(text.encode())
    for el in root.iter():
        if el.tag.endswith("}" + local) and all(el.get(k) == v for k, v in attrs.items()):
            return el
    raise AssertionError(f"no {local} {attrs}")


def test_fault_and_warning_carry_condition_id_normal_does_not():
    text = _BUSY_AGENT.request("current", "mill", {})[1]
    fault = _first(text, "Fault", dataItemId="mill_Xservo")
    assert (fault.get("conditionId"), fault.get("nativeCode")) == ("1012", "1012")
    warning = _first(text, "Warning", dataItemId="mill_bus_cond")
    # no native code from the adapter: the data item id names the activation
    assert warning.get("conditionId") == "mill_bus_cond" and warning.get("nativeCode") is None
    normal = _first(text, "Normal", dataItemId="mill_Yservo")
    assert normal.get("conditionId") is None
    lathe = _BUSY_AGENT.request("current", "lathe", {})[1]
    assert _first(lathe, "Unavailable", dataItemId="lathe_nc_cond").get("conditionId") is None


@pytest.mark.parametrize("element", ["AssetChanged", "AssetRemoved"])
def test_asset_events_carry_asset_type(element):
    text = _BUSY_AGENT.request("current", "mill", {})[1]
    el = _first(text, element)
    assert (el.get("assetType"), el.text) == ("UNAVAILABLE", "UNAVAILABLE")


@pytest.mark.parametrize(
    ("kind", "params", "has_model_change_time"),
    [
        ("probe", {}, True),
        ("current", {}, True),
        ("sample", {}, True),
        ("sample", {"from": "0"}, False),  # an Error document
    ],
)
def test_device_model_change_time_only_outside_error_documents(kind, params, has_model_change_time):
    text = _BUSY_AGENT.request(kind, None, params)[1]
    head = ET.fromstring(text.encode())[0]
    assert ("deviceModelChangeTime" in head.attrib) is has_model_change_time


@pytest.mark.parametrize(
    ("key", "statistic"), [("bus_load", "AVERAGE"), ("bus_load_peak", "MAXIMUM")]
)
def test_average_and_peak_are_statistics_not_sub_types(key, statistic):
    probe = _BUSY_AGENT.request("probe", "mill", {})[1]
    item = _first(probe, "DataItem", id=f"mill_{key}")
    assert (item.get("statistic"), item.get("subType")) == (statistic, None)
    current = _BUSY_AGENT.request("current", "mill", {})[1]
    obs = _first(current, "CanBusLoad", dataItemId=f"mill_{key}")
    assert (obs.get("statistic"), obs.get("subType")) == (statistic, None)


def test_agent_device_type_is_no_device_not_an_empty_devices_element():
    status, text = _BUSY_AGENT.request("probe", None, {"deviceType": "Agent"})
    assert (status, error_code(text)[0]) == (404, "NO_DEVICE")


def test_backward_walk_to_the_first_sequence_keeps_next_sequence_at_least_one():
    a = small_agent()
    root = parse("Streams", a.request("sample", None, {"count": f"-{a.buffer.size}"})[1])
    assert seqs(root)[0] == 1 and header(root)["nextSequence"] == "1"


# Adapter values the 2.5 schema would reject: the item becomes UNAVAILABLE instead of making
# every later document invalid. (key, value)
BAD_ADAPTER_VALUES = [
    ("Xact", "abc"),  # a sample is xs:float
    ("Xact", "inf"),  # xs:float spells it INF
    ("path_feedrate", "1,5"),
    ("bus_load", "high"),  # extension samples too
    ("line", "12.5"),  # LineNumber is an IntegerEvent
    ("part_count", "three"),
    ("feed_ovr", "100%"),  # PathFeedrateOverride is a FloatEvent
    ("exec", "RUNNING"),  # not an Execution word
    ("mode", "AUTO"),
    ("estop", "PRESSED"),
    ("avail", "YES"),
    ("Cmode", "TURNING"),
]


@pytest.mark.parametrize(("key", "value"), BAD_ADAPTER_VALUES)
def test_a_value_the_schema_rejects_becomes_unavailable(key, value):
    a = small_agent()
    good = {"Xact": "1.5", "path_feedrate": "2", "bus_load": "3", "line": "12", "part_count": "3"}
    good |= {"feed_ovr": "100", "exec": "ACTIVE", "mode": "AUTOMATIC", "estop": "ARMED"}
    good |= {"avail": "AVAILABLE", "Cmode": "SPINDLE"}
    a.ingest_line("m1", f"{TS}|{key}|{good[key]}")
    assert a.value("m1", key) == good[key]
    a.ingest_line("m1", f"{TS}|{key}|{value}")
    assert a.value("m1", key) == "UNAVAILABLE"
    assert schema_problems(a.request("current", "m1", {})[1]) == []


@pytest.mark.parametrize(("qualifier", "kept"), [("HIGH", "HIGH"), ("low", "LOW"), ("WEIRD", None)])
def test_condition_qualifier_is_high_or_low_or_dropped(qualifier, kept):
    a = small_agent()
    a.ingest_line("m1", f"{TS}|nc_cond|FAULT|9|FAULT|{qualifier}|text")
    fault = _first(a.request("current", "m1", {})[1], "Fault")
    assert (fault.get("qualifier"), fault.text) == (kept, "text")


@pytest.mark.parametrize(
    "stamp", ["2026-13-01T00:00:00Z", "2026-02-30T10:00:00.5", "2026-01-01T25:00:00"]
)
def test_adapter_timestamp_that_is_no_date_is_replaced(stamp):
    a = small_agent(clock=FakeClock(0.0))
    a.ingest_line("m1", f"{stamp}|exec|ACTIVE")
    assert a.latest("m1", "exec").timestamp == "1970-01-01T00:00:00.000000Z"


@pytest.mark.parametrize("name", ["1mill", "mill one", "mill:1", ""])
def test_machine_name_that_cannot_be_an_xml_id_is_refused(name):
    with pytest.raises(ValueError, match="xs:ID"):
        build_device(name, ["X"])


# The checker itself: each broken rule, put into an otherwise valid document, is reported.
# (request, old text, new text, expected problem)
CHECKER_CASES = [
    (
        ("sample", {"from": "0"}),
        "bufferSize=",
        'deviceModelChangeTime="2026-01-01T00:00:00Z" bufferSize=',
        "Header may not carry deviceModelChangeTime",
    ),
    (("current", {}), 'conditionId="1012" ', "", "lacks conditionId"),
    (("current", {}), ' assetType="UNAVAILABLE"', "", "lacks assetType"),
    (("current", {}), 'statistic="AVERAGE"', 'subType="AVERAGE"', "is not a 2.5 subType"),
    (("probe", {}), 'statistic="AVERAGE"', 'subType="AVERAGE"', "is not a 2.5 subType"),
    (("current", {}), 'nextSequence="', 'nextSequence="-', "nextSequence='-"),
    (("current", {}), ">ACTIVE</Execution>", ">RUNNING</Execution>", "not valid for Execution"),
    (("current", {}), ">120</LineNumber>", ">12.5</LineNumber>", "not valid for LineNumber"),
    (("current", {}), ">1.5000</Position>", ">abc</Position>", "not valid for Position"),
    (("current", {}), 'qualifier="HIGH"', 'qualifier="VERY"', "not HIGH or LOW"),
    (
        ("sample", {"count": "abc"}),
        'errorCode="INVALID_REQUEST"',
        'errorCode="BAD"',
        "not a 2.5 ErrorCodeType",
    ),
    (("probe", {}), 'id="mill_axes"', 'id="1mill_axes"', "no NCName"),
    (("probe", {}), 'assetCount="0"', "", "Header lacks assetCount"),
]


@pytest.mark.parametrize(("request_", "old", "new", "problem"), CHECKER_CASES)
def test_the_rule_checker_reports_each_broken_rule(request_, old, new, problem):
    kind, params = request_
    text = _BUSY_AGENT.request(kind, "mill" if kind != "sample" else None, params)[1]
    assert schema_problems(text) == []
    assert old in text
    broken = text.replace(old, new, 1)
    assert any(problem in p for p in schema_problems(broken)), schema_problems(broken)


@pytest.mark.parametrize("document", ["/mtconnect/current", "/mtconnect/mill/sample"])
def test_streams_name_the_served_extension_schema_that_declares_every_x_element(document):
    from urllib.parse import urljoin

    from fastapi import FastAPI
    from fastapi.testclient import TestClient

    from web_api.mtconnect import mtconnect_router

    app = FastAPI()
    app.include_router(mtconnect_router(_BUSY_AGENT), prefix="/mtconnect")
    client = TestClient(app)
    text = client.get(document, params={"count": "1000"} if "sample" in document else {}).text
    root = ET.fromstring(text.encode())
    pairs = root.get("{http://www.w3.org/2001/XMLSchema-instance}schemaLocation").split()
    locations = dict(zip(pairs[::2], pairs[1::2], strict=True))
    ext_ns = "urn:fmscell:MTConnectStreams:2.5"
    # the location is relative: it resolves beside the document, whatever the prefix
    r = client.get(urljoin("http://testserver" + document, locations[ext_ns]))
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/xml")
    xs = "{http://www.w3.org/2001/XMLSchema}"
    schema = ET.fromstring(r.content)
    assert schema.get("targetNamespace") == ext_ns
    declared = {e.get("name"): e.get("substitutionGroup") for e in schema.iter(f"{xs}element")}
    heads = {"Samples": "m:CommonSample", "Events": "m:StringEvent"}
    used = {
        (obs.tag.split("}")[1], heads[group.tag.split("}")[1]])
        for group in root.iter()
        if group.tag.split("}")[1] in heads
        for obs in group
        if obs.tag.startswith("{" + ext_ns + "}")
    }
    assert used  # the busy agent emits extension samples and events
    for local, head in used:
        assert declared.get(local) == head, (local, declared)
    bad = client.get("/mtconnect/schemas/other.xsd")
    assert bad.status_code == 404 and error_code(bad.text)[0] == "INVALID_URI"
