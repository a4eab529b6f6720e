"""The simulated CAN hub: arbitration, wire timing, load account, faults, candump, modes."""

import io
import threading
import warnings

import can
import pytest

from drives.bus import (
    BusLoadWarning,
    BusOverloadError,
    CanHub,
    CyclicFrame,
    axis_traffic,
    candump_frame,
    drop_hub,
    frame_bits,
    get_hub,
    open_bus,
    plan_load,
)


def msg(can_id, data=b"", **kw):
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False, **kw)


@pytest.fixture
def hub():
    h = CanHub(auto_deliver=False)
    yield h
    h.close()


def collect(endpoint):
    got = []
    endpoint.add_listener(got.append)
    return got


def test_lowest_identifier_wins_among_queued_frames(hub):
    a, b, c = hub.endpoint("a"), hub.endpoint("b"), hub.endpoint("c")
    spy = collect(hub.endpoint("spy"))
    a.send(msg(0x601, b"\x40\x00\x10\x00\x00\x00\x00\x00"))
    b.send(msg(0x181, b"\x01"))
    c.send(msg(0x080))
    assert hub.deliver() == 3
    assert [m.arbitration_id for m in spy] == [0x080, 0x181, 0x601]


def test_each_node_sends_in_fifo_order(hub):
    master = hub.endpoint("master")
    spy = collect(hub.endpoint("spy"))
    master.send(msg(0x201, b"\x0f\x00"))
    master.send(msg(0x080))  # RPDO before SYNC although SYNC has the lower identifier
    hub.deliver()
    assert [m.arbitration_id for m in spy] == [0x201, 0x080]


def test_11_bit_frame_beats_29_bit_frame_with_same_base_id(hub):
    a, b = hub.endpoint(), hub.endpoint()
    spy = collect(hub.endpoint())
    a.send(can.Message(arbitration_id=(0x123 << 18) | 5, is_extended_id=True))
    b.send(msg(0x123))
    hub.deliver()
    assert [m.is_extended_id for m in spy] == [False, True]


def test_wire_time_is_the_stuffed_length(hub):
    a = hub.endpoint()
    spy = collect(hub.endpoint())
    a.send(msg(0x080))
    a.send(msg(0x181, bytes(8)))
    hub.deliver()
    assert spy[0].timestamp == pytest.approx(51e-6)
    assert spy[1].timestamp == pytest.approx((51 + 126) * 1e-6)


def test_bitrate_scales_wire_time():
    h = CanHub(bitrate=250_000)
    a = h.endpoint()
    spy = collect(h.endpoint())
    a.send(msg(0x080))
    assert spy[0].timestamp == pytest.approx(51 / 250_000)
    h.close()


def test_load_account_per_sync_window(hub):
    master = hub.endpoint()
    for _ in range(3):
        master.send(msg(0x080))
        master.send(msg(0x181, bytes(8)))
        hub.deliver()
        hub.advance(0.001)
    windows = list(hub.load.windows)
    assert len(windows) == 2
    assert windows[0].bits == 51 + 126
    assert hub.load.mean == pytest.approx(177 / 1000)
    assert hub.load.peak == pytest.approx(177 / 1000)


def test_load_peak_tracks_the_busiest_window(hub):
    master = hub.endpoint()
    for extra in (0, 4, 1):
        master.send(msg(0x080))
        for _ in range(extra):
            master.send(msg(0x181, bytes(8)))
        hub.deliver()
        hub.advance(0.001)
    master.send(msg(0x080))
    hub.deliver()
    assert hub.load.peak == pytest.approx((51 + 4 * 126) / 1000)
    assert hub.load.mean == pytest.approx((3 * 51 + 5 * 126) / 3000)


def test_candump_log_is_readable_by_python_can(tmp_path):
    path = tmp_path / "trace.log"
    with path.open("w") as fh:
        h = CanHub(log=fh)
        a = h.endpoint()
        a.send(msg(0x123, b"\xde\xad\xbe\xef"))
        a.send(can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\x01"))
        a.send(msg(0x705, is_remote_frame=True, dlc=1))
        h.corrupt(0x181)
        a.send(msg(0x181, b"\x00"))
        h.close()
    lines = path.read_text().splitlines()
    assert (
        lines[0] == f"({frame_bits(0x123, bytes.fromhex('DEADBEEF')) * 1e-6:.6f}) can0 123#DEADBEEF"
    )
    assert lines[1].endswith(" can0 01ABCDEF#01")
    assert lines[2].endswith(" can0 705#R")
    assert lines[3].endswith(" can0 20000080#0000000000000000")
    read = list(can.CanutilsLogReader(path))
    assert [m.arbitration_id for m in read[:3]] == [0x123, 0x1ABCDEF, 0x705]
    assert read[2].is_remote_frame
    assert read[3].is_error_frame


def test_lockstep_delivery_is_synchronous_and_deterministic():
    def scenario():
        out = io.StringIO()
        h = CanHub(log=out)
        a, b = h.endpoint(), h.endpoint()
        b.add_listener(
            lambda m: b.send(msg(0x580 + 5, bytes(8))) if m.arbitration_id == 0x605 else None
        )
        for i in range(20):
            a.send(msg(0x605, bytes([0x40, i, 0x10, 0, 0, 0, 0, 0])))
            h.advance(0.0005)
        h.close()
        return out.getvalue()

    first, second = scenario(), scenario()
    assert first == second
    assert first.count("585#") == 20


def test_drop_fault_loses_frames(hub):
    a = hub.endpoint()
    spy = collect(hub.endpoint())
    hub.drop(0x181, count=2)
    for i in range(3):
        a.send(msg(0x181, bytes([i])))
    hub.deliver()
    assert [m.data[0] for m in spy] == [2]
    assert hub.dropped_frames == 2


def test_corrupt_fault_delivers_error_frame_to_others(hub):
    a = hub.endpoint()
    spy = collect(hub.endpoint())
    hub.corrupt(0x181)
    a.send(msg(0x181, b"\x01"))
    a.send(msg(0x181, b"\x02"))
    hub.deliver()
    assert spy[0].is_error_frame
    assert spy[1].data == bytearray(b"\x02")
    assert hub.error_frames == 1


def test_delay_fault_holds_a_frame_until_time_advances(hub):
    a = hub.endpoint()
    spy = collect(hub.endpoint())
    hub.delay(0x181, 0.002)
    a.send(msg(0x181, b"\x01"))
    a.send(msg(0x182, b"\x02"))
    hub.deliver()
    assert [m.arbitration_id for m in spy] == [0x182]
    hub.advance(0.001)
    assert len(spy) == 1
    hub.advance(0.001)
    assert [m.arbitration_id for m in spy] == [0x182, 0x181]
    assert spy[1].timestamp >= 0.002


def test_bus_off_node_cannot_send_and_others_see_nothing(hub):
    a, b = hub.endpoint("a"), hub.endpoint("b")
    spy = collect(hub.endpoint())
    a.send(msg(0x181))
    hub.bus_off(a)
    assert a.state == can.BusState.ERROR
    with pytest.raises(can.CanOperationError, match="bus-off"):
        a.send(msg(0x181))
    b.send(msg(0x182))
    hub.deliver()
    assert [m.arbitration_id for m in spy] == [0x182]
    hub.recover(a)
    a.send(msg(0x181))
    hub.deliver()
    assert spy[-1].arbitration_id == 0x181


def test_babbling_node_starves_higher_identifiers_but_not_lower():
    h = CanHub()
    a = h.endpoint()
    spy = collect(h.endpoint())
    h.babble(0x100)
    h.advance(0.001)
    babble = [m for m in spy if m.arbitration_id == 0x100]
    assert 7 <= len(babble) <= 10  # an 8-byte frame every ~111-135 us fills 1 ms
    a.send(msg(0x080))  # SYNC wins arbitration against the babbler
    a.send(msg(0x605, bytes(8)))  # SDO starves
    h.advance(0.001)
    ids = [m.arbitration_id for m in spy]
    assert 0x080 in ids and 0x605 not in ids
    assert h.stop_babble() > 0
    h.advance(0.001)
    assert spy[-1].arbitration_id == 0x605
    assert h.load.total_frames == len(spy)
    h.close()


def test_recv_queue_for_endpoints_without_listener(hub):
    a, b = hub.endpoint(), hub.endpoint()
    a.send(msg(0x181, b"\x01"))
    hub.deliver()
    got = b.recv(timeout=0)
    assert got.arbitration_id == 0x181 and got.data == bytearray(b"\x01")
    assert b.recv(timeout=0) is None


def test_receive_queue_is_bounded():
    h = CanHub(rx_queue_limit=3)
    a, b = h.endpoint(), h.endpoint()
    for _ in range(5):
        a.send(msg(0x181))
    assert b.rx_overruns == 2
    h.close()


def test_clocked_participants_tick_on_advance(hub):
    ticks = []

    class Node:
        def advance(self, dt):
            ticks.append(dt)

    hub.add_clocked(Node())
    hub.advance(0.001)
    hub.advance(0.002)
    assert ticks == [0.001, 0.002]
    assert hub.now == pytest.approx(0.003)


def test_realtime_hub_delivers_from_its_thread_with_wall_clock_stamps():
    h = CanHub(mode="realtime")
    a, b = h.endpoint(), h.endpoint()
    received = threading.Event()
    got = []

    def on(m):
        got.append((m, threading.current_thread().name))
        received.set()

    b.add_listener(on)
    h.start()
    try:
        a.send(msg(0x181, b"\x01"))
        assert received.wait(5.0)
    finally:
        h.close()
    m, thread = got[0]
    assert thread.startswith("canhub-")
    assert m.timestamp > 1e9  # wall clock, not virtual time


def test_lockstep_hub_refuses_start_and_realtime_refuses_advance():
    with pytest.raises(RuntimeError, match="advance"):
        CanHub().start()
    with pytest.raises(RuntimeError, match="lockstep"):
        CanHub(mode="realtime").advance(0.001)
    with pytest.raises(ValueError, match="mode"):
        CanHub(mode="fast")


def test_canopen_network_runs_on_an_endpoint_with_its_notifier():
    import canopen

    h = CanHub()
    network = canopen.Network(h.endpoint("master"))
    network.connect()
    other = h.endpoint("node")
    seen = threading.Event()
    network.subscribe(0x185, lambda *args: seen.set())
    other.send(msg(0x185, b"\x01"))
    assert seen.wait(5.0)
    network.disconnect()
    h.close()


# ------------------------------------------------------------------ configuration switch
def test_open_bus_sim_attaches_to_named_hub():
    drop_hub("cellA")
    bus = open_bus({"interface": "sim", "channel": "cellA", "bitrate": 500_000})
    assert bus.hub is get_hub("cellA")
    assert bus.hub.bitrate == 500_000
    drop_hub("cellA")


def test_open_bus_socketcan_goes_through_python_can(monkeypatch):
    calls = []
    monkeypatch.setattr(can, "Bus", lambda **kw: calls.append(kw) or "bus")
    assert open_bus({"interface": "socketcan", "channel": "can0"}) == "bus"
    assert calls == [{"interface": "socketcan", "channel": "can0", "receive_own_messages": False}]


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ({"interface": "pcan"}, "interface 'pcan'"),
        ({"channel": ""}, "channel"),
        ({"bitrate": -1}, "bitrate"),
        ({"bitrat": 1}, "unknown key"),
    ],
)
def test_open_bus_names_the_bad_key(config, message):
    with pytest.raises(ValueError, match=message):
        open_bus(config)


# ------------------------------------------------------------------ load planning
@pytest.mark.parametrize(
    ("axes", "period", "worst", "nominal"),
    [
        (3, 0.001, 0.865, 0.713),
        (6, 0.002, 0.8375, 0.6895),
        (12, 0.004, 0.82375, 0.67775),
    ],
)
def test_load_plan_reproduces_the_anchor_table(axes, period, worst, nominal):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = plan_load(axis_traffic(axes), sync_period_s=period)
    assert plan.worst_case_load == pytest.approx(worst)
    assert plan.nominal_load == pytest.approx(nominal)
    assert any(issubclass(w.category, BusLoadWarning) for w in caught)


def test_four_axes_at_1ms_are_refused_with_the_figures():
    with pytest.raises(BusOverloadError, match=r"113\.5%") as info:
        plan_load(axis_traffic(4), sync_period_s=0.001)
    assert info.value.plan.worst_case_bits == 55 + 8 * 135


def test_light_load_passes_silently_and_heartbeats_count():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plan = plan_load(axis_traffic(2, heartbeat_s=0.1), sync_period_s=0.004)
    assert plan.worst_case_bits == pytest.approx(55 + 4 * 135 + 2 * 65 * 0.04)


def test_load_plan_rejects_nonsense():
    with pytest.raises(ValueError, match="sync_period_s"):
        plan_load([CyclicFrame("x", 8)], sync_period_s=0)


def test_frame_bits_agree_with_wire_accounting(hub):
    a = hub.endpoint()
    a.send(msg(0x181, b"\x37\x06\xe8\x03\x00\x00"))
    hub.deliver()
    assert hub.load.total_bits == frame_bits(0x181, b"\x37\x06\xe8\x03\x00\x00")
    assert candump_frame(msg(0x181, b"\x37\x06")) == "181#3706"


def test_acceptance_filter_skips_other_identifiers(hub):
    a, b = hub.endpoint(), hub.endpoint()
    spy = []
    b.add_listener(spy.append, accept={0x181})
    a.send(msg(0x181, b"\x01"))
    a.send(msg(0x182, b"\x02"))
    a.send(can.Message(arbitration_id=0x181, is_extended_id=True))
    hub.deliver()
    assert [(m.arbitration_id, m.is_extended_id) for m in spy] == [(0x181, False)]


def test_a_listener_without_filter_disables_filtering(hub):
    a, b = hub.endpoint(), hub.endpoint()
    filtered, everything = [], []
    b.add_listener(filtered.append, accept={0x181})
    b.add_listener(everything.append)
    a.send(msg(0x182))
    hub.deliver()
    assert len(everything) == 1 and len(filtered) == 1  # listeners share the endpoint
    b.remove_listener(everything.append)
    a.send(msg(0x182))
    hub.deliver()
    assert len(filtered) == 1


def test_two_slaves_can_share_one_endpoint(app):
    from drives.cia301 import CanopenSlave
    from tests.drives.conftest import FakeDrive

    hub = CanHub()
    shared = hub.endpoint("drives")
    master = hub.endpoint("master")
    replies = collect(master)
    CanopenSlave(1, shared, app)
    CanopenSlave(2, shared, FakeDrive())
    assert {0x601, 0x602, 0x201, 0x202, 0x000, 0x080} <= shared.accept_ids
    assert 0x603 not in shared.accept_ids
    assert [m.arbitration_id for m in replies] == [0x701, 0x702]  # boot-ups
    replies.clear()
    master.send(msg(0x601, bytes.fromhex("4000100000000000")))
    master.send(msg(0x602, bytes.fromhex("4000100000000000")))
    assert [m.arbitration_id for m in replies] == [0x581, 0x582]
    hub.close()


def test_hub_checks_planned_load_at_its_bitrate():
    hub = CanHub(bitrate=500_000)
    with pytest.raises(BusOverloadError, match="500 kbit/s"):
        hub.check_load(axis_traffic(2), sync_period_s=0.001)
    assert hub.check_load(axis_traffic(1), sync_period_s=0.004).worst_case_load < 0.2
    hub.close()


def test_python_can_can_open_the_simulator_by_interface_name(monkeypatch):
    # What a `can.interface` entry point `fmscell = "drives.bus.hub:SimBus"` would register.
    import can.interfaces
    import can.util
    import canopen

    monkeypatch.setitem(can.interfaces.BACKENDS, "fmscell", ("drives.bus.hub", "SimBus"))
    monkeypatch.setattr(can.util, "VALID_INTERFACES", can.util.VALID_INTERFACES | {"fmscell"})
    drop_hub("cellB")
    node_side = can.Bus(interface="fmscell", channel="cellB", bitrate=500_000)
    network = canopen.Network().connect(interface="fmscell", channel="cellB")
    try:
        assert node_side.hub is get_hub("cellB") and node_side.hub.bitrate == 500_000
        seen = threading.Event()
        network.subscribe(0x185, lambda *args: seen.set())
        node_side.send(msg(0x185, b"\x01"))
        assert seen.wait(5.0)
    finally:
        network.disconnect()
        drop_hub("cellB")


def test_load_account_keeps_recent_windows_only(hub):
    """A cell runs for hours at a SYNC every 2 ms: the windows kept are bounded (they held
    some 20 MB per bus at 100 000), while mean and peak still cover the whole run."""
    master = hub.endpoint()
    master.send(msg(0x080))
    master.send(msg(0x181, bytes(8)))  # one fuller window first: the run's peak
    hub.deliver()
    hub.advance(0.001)
    for _ in range(2500):
        master.send(msg(0x080))
        hub.deliver()
        hub.advance(0.001)
    assert len(hub.load.windows) == 2000
    assert hub.load.summary()["windows"] == 2000
    assert hub.load.peak == pytest.approx(177 / 1000)  # from the first window, long gone
    assert hub.load.total_frames == 2502
