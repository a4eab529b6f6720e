"""The axis group (CANopen master the NC uses) against virtual drives on a lockstep hub."""

from __future__ import annotations

import hashlib
import io
import math
import warnings

import can
import pytest

from drives import VirtualDrive
from drives.bus import BusLoadWarning, BusOverloadError, CanHub, open_bus
from drives.master import AxisConfig, AxisError, AxisGroup, power

KV = 16.67  # the plant's default position-loop gain, 1/s


class Rig:
    def __init__(self, n_axes=3, ipo=0.002, hub=None, drive_kwargs=None, **group_kwargs):
        self.trace = io.StringIO()
        self.hub = hub or CanHub(log=self.trace)
        names = "XYZABC"[:n_axes]
        kwargs = {"substep": 1e-3, **(drive_kwargs or {})}
        self.drives = {
            name: VirtualDrive(i + 1, self.hub.endpoint(f"n{i + 1}"), **kwargs)
            for i, name in enumerate(names)
        }
        axis_kwargs = group_kwargs.pop("axis", {})
        axes = [AxisConfig(name, i + 1, **axis_kwargs) for i, name in enumerate(names)]
        self.group = AxisGroup(self.hub.endpoint("master"), axes, ipo_cycle_s=ipo, **group_kwargs)

    def up(self):
        self.group.boot()
        self.group.configure()
        self.group.enable()
        return self


@pytest.fixture
def rig():
    r = Rig(master_node_id=100)
    yield r
    r.group.close()
    r.hub.close()


def test_configuration_written_by_sdo(rig):
    g = rig.group
    g.boot()
    g.configure()
    od = rig.drives["Y"].slave.od
    assert od.get(0x1600, 0) == 2
    assert [od.get(0x1600, 1), od.get(0x1600, 2)] == [0x60400010, 0x607A0020]
    assert od.get(0x1400, 2) == 1 and od.get(0x1400, 1) == 0x202
    assert [od.get(0x1A00, 1), od.get(0x1A00, 2)] == [0x60410010, 0x60640020]
    assert od.get(0x1800, 2) == 1
    assert od.get(0x1A01, 1) == 0x60F40020
    assert od.get(0x1401, 1) & 0x80000000  # unused PDOs off
    assert od.get(0x1017, 0) == 100
    assert od.get(0x1016, 1) == (100 << 16) | 300
    d = rig.drives["Y"].drive
    assert d.interpolation_period == pytest.approx(0.002)
    assert d.mode_display == 8
    assert rig.drives["Y"].nmt_state == "OPERATIONAL"


def test_limits_and_following_error_configuration():
    r = Rig(
        n_axes=1,
        axis={
            "min_mm": -5.0,
            "max_mm": 400.0,
            "following_error_window_mm": 2.5,
            "following_error_timeout_ms": 30,
            "max_velocity_mm_s": 500.0,
            "max_accel_mm_s2": 4000.0,
            "quick_stop_decel_mm_s2": 8000.0,
        },
    )
    r.group.boot()
    r.group.configure()
    d = r.drives["X"].drive
    assert d.read_object(0x607D, 1) == -5000 and d.read_object(0x607D, 2) == 400_000
    assert d.read_object(0x6065, 0) == 2500 and d.read_object(0x6066, 0) == 30
    assert d.read_object(0x607F, 0) == 500_000
    assert d.read_object(0x6083, 0) == 4_000_000 == d.read_object(0x6084, 0)
    assert d.read_object(0x6085, 0) == 8_000_000
    r.hub.close()


def test_enable_home_and_follow_a_ramp_with_the_kv_lag(rig):
    g = rig.up().group
    assert all(g.state(a) == "OPERATION ENABLED" for a in g.axis_names)
    g.home()
    fb = g.cycle()
    x0 = fb.position_mm["X"]
    v = 20.0  # mm/s
    for i in range(1, 751):
        fb = g.cycle({"X": x0 + v * i * g.ipo_cycle_s})
    assert fb.all_fresh and fb.faults == []
    assert fb.following_error_mm["X"] == pytest.approx(v / KV, rel=0.02)
    # feedback = 0x6064 sampled at this cycle's SYNC: one cycle behind the last target
    assert fb.position_mm["X"] == pytest.approx(x0 + v * 750 * 0.002 - v / KV, abs=0.1)
    assert fb.position_mm["Y"] == pytest.approx(0.0, abs=0.002)
    assert fb.state["X"] == "OPERATION ENABLED"


def test_home_with_dog_and_creep_per_axis_method():
    r = Rig(
        n_axes=2,
        drive_kwargs={"switches": {"initial_position": 0.030}},
        axis={
            "homing_method": 21,
            "homing_search_mm_s": 50.0,
            "homing_creep_mm_s": 5.0,
            "homing_accel_mm_s2": 2000.0,
            "home_offset_mm": 1.5,
        },
    )
    g = r.up().group
    g.home()
    for name, vd in r.drives.items():
        assert vd.drive.homed
        # the dog's edge is at 10 mm of table travel and reads as the home offset
        ref_m = vd.table_position_m - vd.position_actual * 1e-6
        assert ref_m + 1.5e-3 == pytest.approx(0.010, abs=5e-6)
        assert g.state(name) == "OPERATION ENABLED"
        assert vd.drive.mode_display == 8
    r.hub.close()


def test_homing_error_names_the_axis():
    r = Rig(n_axes=1, drive_kwargs={"switches": {"home_switch": None}}, axis={"homing_method": 21})
    g = r.up().group
    with pytest.raises(AxisError, match=r"axis X \(node 1\): homing method 21 failed"):
        g.home()
    r.hub.close()


def test_home_needs_enabled_axes(rig):
    rig.group.boot()
    rig.group.configure()
    with pytest.raises(AxisError, match="enable"):
        rig.group.home()


def test_enable_failure_names_axis_and_state(rig):
    g = rig.group
    g.boot()
    g.configure()
    rig.drives["Y"].inject("mains_voltage", volts=150.0)
    # the idle DC link bleeds down through its 47 kOhm (tau 15.5 s) below the 250 V needed
    rig.drives["Y"].drive.advance(30.0)
    with pytest.raises(AxisError) as info:
        g.enable(timeout_s=0.05)
    assert "axis Y (node 2) did not reach OPERATION ENABLED" in str(info.value)
    assert "READY TO SWITCH ON" in str(info.value)
    assert info.value.axes == ("Y",)


def test_emcy_reported_upward_then_fault_reset(rig):
    g = rig.up().group
    rig.drives["Z"].inject("encoder_break")
    faults = []
    for _ in range(5):
        faults += g.cycle().faults
    assert [(f.axis, f.node_id, f.emcy_code, f.source) for f in faults] == [
        ("Z", 3, 0x7305, "emcy")
    ]
    assert faults[0].error_register & 0x01 and "encoder" in faults[0].text
    assert g.state("Z") == "FAULT"
    assert [f.axis for f in g.faults] == ["Z"]
    with pytest.raises(AxisError, match=r"axis Z \(node 3\) is in FAULT"):
        g.enable()
    with pytest.raises(AxisError, match=r"axis Z \(node 3\) still in FAULT .*0x603F=0x7305"):
        g.fault_reset()
    rig.drives["Z"].clear_injection("encoder_break")
    g.fault_reset()
    assert g.state("Z") == "SWITCH ON DISABLED"
    assert g.faults == []
    g.enable()
    assert g.state("Z") == "OPERATION ENABLED"


def test_following_error_fault_on_a_jam(rig):
    g = rig.up().group
    rig.drives["X"].inject("blocked")
    x0 = g.position_mm("X")
    codes = []
    for i in range(1, 2000):
        fb = g.cycle({"X": x0 + 0.05 * i})  # 25 mm/s into a jammed table
        codes += [f.emcy_code for f in fb.faults]
        if codes:
            break
    assert codes and codes[0] in (0x8611, 0x7121)


def test_heartbeat_loss_of_a_drive_is_reported(rig):
    g = rig.up().group
    rig.hub.drop(0x702, count=None)  # node 2's heartbeats vanish
    faults = []
    for _ in range(250):  # 0.5 s > 3 x 100 ms
        faults += g.cycle().faults
    hb = [f for f in faults if f.source == "heartbeat"]
    assert [(f.axis, f.emcy_code) for f in hb] == [("Y", 0x8130)]
    assert 0.3 < hb[0].time <= 0.31  # configured at t = 0 plus 3 x 100 ms
    rig.hub.clear_faults()
    for _ in range(60):
        g.cycle()
    assert [f for f in g.faults if f.source == "heartbeat"] == []


def test_drives_fault_when_the_master_heartbeat_stops(rig):
    g = rig.up().group
    for _ in range(5):
        g.cycle()  # the first master heartbeat starts the drives' consumers
    rig.hub.run_for(0.5, 0.002)  # master silent: no SYNC, no heartbeat
    fb = g.cycle()
    codes = {(f.axis, f.emcy_code) for f in fb.faults}
    assert codes == {("X", 0x8130), ("Y", 0x8130), ("Z", 0x8130)}
    assert all(s == "FAULT" for s in fb.state.values())


def test_power_cycle_of_a_drive_is_reported(rig):
    g = rig.up().group
    g.cycle()
    rig.drives["X"].power_cycle()
    fb = g.cycle()
    assert [(f.axis, f.source) for f in fb.faults] == [("X", "bootup")]


def test_quick_stop_ramps_down_and_disables(rig):
    g = rig.up().group
    x0 = g.position_mm("X")
    for i in range(1, 300):
        g.cycle({"X": x0 + 0.1 * i})  # 50 mm/s
    g.quick_stop()
    states = []
    for _ in range(500):
        fb = g.cycle({"X": 1e3})  # ignored
        states.append(fb.state["X"])
        if states[-1] != "QUICK STOP ACTIVE":
            break
    assert states[0] == "QUICK STOP ACTIVE"
    assert states[-1] == "SWITCH ON DISABLED"  # 0x605A = 2: ramp 0x6085, then disabled
    still = g.position_mm("X")
    for _ in range(10):
        fb = g.cycle({"X": 1e3})
    assert fb.position_mm["X"] == pytest.approx(still, abs=0.01)
    g.enable()
    fb = g.cycle()
    assert fb.position_mm["X"] == pytest.approx(still, abs=0.01)  # re-enabled without a jump


def test_disable_is_a_controlled_stop(rig):
    g = rig.up().group
    g.disable()
    assert {g.state(a) for a in g.axis_names} == {"READY TO SWITCH ON"}


def test_boot_timeout_names_the_missing_drive():
    hub = CanHub()
    VirtualDrive(1, hub.endpoint("n1"))
    axes = [AxisConfig("X", 1), AxisConfig("Y", 7)]
    g = AxisGroup(hub.endpoint("master"), axes, boot_timeout_s=0.05)
    with pytest.raises(AxisError, match=r"no boot-up .* axis Y \(node 7\)$"):
        g.boot()
    hub.close()


def test_bus_load_plan_refuses_and_warns():
    hub = CanHub()
    axes = [AxisConfig(f"A{i}", i) for i in range(1, 7)]
    g = AxisGroup(hub.endpoint("master"), axes, ipo_cycle_s=0.001)
    with pytest.raises(BusOverloadError) as info:
        g.configure()
    assert "exceeds 100 %" in str(info.value)
    assert "CAN line 0" in "".join(info.value.__notes__)
    assert info.value.plan.worst_case_load > 1.0
    g3 = AxisGroup(hub.endpoint("m3"), axes[:3], ipo_cycle_s=0.001, following_error_every=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        (plan,) = g3.plan()
    assert 0.7 < plan.worst_case_load <= 1.0
    assert any(issubclass(w.category, BusLoadWarning) for w in caught)
    hub.close()


def test_two_can_lines_of_three_axes_at_1ms():
    hubs = [CanHub(channel="can0"), CanHub(channel="can1")]
    drives = [
        VirtualDrive(n, hubs[line].endpoint(f"n{n}"), substep=1e-3)
        for line in (0, 1)
        for n in (1, 2, 3)
    ]
    axes = [AxisConfig(name, i % 3 + 1, line=i // 3) for i, name in enumerate("XYZABC")]
    g = AxisGroup(
        [h.endpoint("master") for h in hubs], axes, ipo_cycle_s=0.001, following_error_every=4
    )
    g.boot()
    with pytest.warns(BusLoadWarning, match=r"CAN line \d") as record:
        g.configure()  # 81.8 % each: above 70 %, below 100 %
    assert any("CAN line 1" in str(w.message) and "axes A, B, C" in str(w.message) for w in record)
    assert all(p.worst_case_load <= 1.0 for p in g.load_plans)
    g.enable()
    fb = g.cycle({"A": 1.0, "X": -1.0})
    for _ in range(400):
        fb = g.cycle()
    assert fb.position_mm["A"] == pytest.approx(1.0, abs=0.01)
    assert fb.position_mm["X"] == pytest.approx(-1.0, abs=0.01)
    assert drives[3].drive.time == pytest.approx(drives[0].drive.time)
    for h in hubs:
        h.close()


def test_bad_targets_and_config():
    hub = CanHub()
    g = AxisGroup(hub.endpoint("m"), [AxisConfig("X", 1)])
    with pytest.raises(KeyError, match="unknown axis 'Q'; axes: X"):
        g.cycle({"Q": 1.0})
    with pytest.raises(ValueError, match="finite"):
        g.cycle({"X": math.nan})
    with pytest.raises(ValueError, match="used twice"):
        AxisGroup(hub.endpoint("m2"), [AxisConfig("X", 1), AxisConfig("X", 2)])
    with pytest.raises(ValueError, match="line 1"):
        AxisGroup(hub.endpoint("m3"), [AxisConfig("X", 1, line=1)])
    with pytest.raises(ValueError, match="min_mm"):
        AxisConfig("X", 1, min_mm=5, max_mm=1)
    with pytest.raises(ValueError, match="0.5..8 ms"):
        AxisGroup(hub.endpoint("m4"), [AxisConfig("X", 1)], ipo_cycle_s=0.02)
    hub.close()


def _scenario() -> str:
    r = Rig(n_axes=2, master_node_id=100)
    g = r.up().group
    g.home()
    x0 = g.position_mm("X")
    for i in range(1, 400):
        g.cycle({"X": x0 + 0.04 * i, "Y": -0.02 * i})
    r.drives["Y"].inject("encoder_break")
    for _ in range(20):
        g.cycle()
    r.hub.close()
    return hashlib.sha256(r.trace.getvalue().encode()).hexdigest()


def test_lockstep_determinism_same_candump_hash():
    assert _scenario() == _scenario()


def test_power_pure_helpers():
    assert power.state_name(0x0250) == "SWITCH ON DISABLED"
    assert power.enable_controlword(0x0250) == 0x06
    assert power.enable_controlword(0x0231) == 0x0F
    assert power.enable_controlword(0x0237) is None
    assert power.enable_controlword(0x0208) is None
    assert power.enable_controlword(0x0217) == 0x00
    assert power.homing_status(0x1637) == "TARGET REACHED"
    assert power.interpolation_period(0.002) == (2, -3)
    assert power.interpolation_period(0.0005) == (5, -4)
    with pytest.raises(ValueError):
        power.interpolation_period(1 / 3000)
    assert "following" in power.emcy_text(0x8611)
    assert "temperature" in power.emcy_text(0x4210)


# ---------------------------------------------------------------- real hardware boundary
class _RecordingBus(can.BusABC):
    """Stands in for a SocketCAN interface: records frames, never answers."""

    def __init__(self, channel=None, **kwargs):
        self.sent = []
        self.kwargs = kwargs
        self.channel_info = f"fake {channel}"
        super().__init__(channel=channel)

    def send(self, msg, timeout=None):
        self.sent.append(msg)

    def _recv_internal(self, timeout):
        return None, False


def test_socketcan_config_line_reaches_python_can_and_the_group_uses_it(monkeypatch):
    calls = []

    def fake_bus(**kwargs):
        calls.append(kwargs)
        return _RecordingBus(**kwargs)

    monkeypatch.setattr(can, "Bus", fake_bus)
    bus = open_bus({"interface": "socketcan", "channel": "can0"})
    assert calls == [{"interface": "socketcan", "channel": "can0", "receive_own_messages": False}]
    g = AxisGroup(bus, [AxisConfig("X", 2)], boot_timeout_s=0.05)
    assert not g.lockstep
    with pytest.raises(AxisError, match=r"axis X \(node 2\)"):
        g.boot()
    assert [(m.arbitration_id, bytes(m.data)) for m in bus.sent] == [(0x000, b"\x81\x02")]
    g.close()
    bus.shutdown()


def test_paced_lockstep_counts_cycles_on_the_wall_clock():
    r = Rig(n_axes=1, paced=True)
    g = r.up().group
    before = g.stats.cycles
    for _ in range(20):
        fb = g.cycle()
    assert g.stats.cycles == before + 20
    assert len(g.stats.lateness_s) >= 20
    assert fb.all_fresh
    assert set(g.stats.summary()) >= {"late_pct", "lateness_p99_us"}
    with pytest.raises(ValueError, match="paced"):
        AxisGroup(_RecordingBus(), [AxisConfig("X", 1)], paced=True)
    r.hub.close()


def test_realtime_group_on_a_realtime_hub():
    hub = CanHub(mode="realtime")
    drives = [VirtualDrive(n, hub.endpoint(f"n{n}"), substep=1e-3).start() for n in (1, 2)]
    g = AxisGroup(hub.endpoint("m"), [AxisConfig("X", 1), AxisConfig("Y", 2)])
    try:
        assert not g.lockstep
        g.boot()
        g.configure()
        g.enable(timeout_s=2.0)
        fresh = 0
        for i in range(100):
            fb = g.cycle({"X": 0.01 * i})
            fresh += fb.all_fresh
        assert fresh > 0  # on a loaded machine some cycles may be late: counted, not asserted
        assert g.stats.cycles >= 100
        assert drives[0].state_name == "OPERATION ENABLED"
    finally:
        g.close()
        hub.close()


def test_realtime_group_on_python_can_virtual_bus():
    channel = "fmscell-test-group-virtual"
    drive_bus = can.Bus(interface="virtual", channel=channel)
    master_bus = can.Bus(interface="virtual", channel=channel)
    vd = VirtualDrive(3, drive_bus, substep=1e-3).start()
    g = AxisGroup(master_bus, [AxisConfig("Z", 3)], ipo_cycle_s=0.004)
    try:
        g.boot()
        g.configure()
        g.enable(timeout_s=2.0)
        assert vd.state_name == "OPERATION ENABLED"
        z0 = g.position_mm("Z")
        for i in range(100):
            fb = g.cycle({"Z": z0 + 0.01 * i})
        assert fb.state["Z"] == "OPERATION ENABLED"
        assert g.position_mm("Z") > z0 + 0.3  # it followed the ramp (about 1 mm long)
    finally:
        g.close()
        vd.stop()
        master_bus.shutdown()
        drive_bus.shutdown()


def test_fault_reset_leaves_healthy_axes_enabled(rig):
    g = rig.up().group
    rig.hub.drop(0x702, count=None)
    for _ in range(200):
        g.cycle()
    assert [f.axis for f in g.faults] == ["Y"]  # heartbeat lost, drive itself fine
    rig.hub.clear_faults()
    g.fault_reset()
    assert g.faults == []
    assert {g.state(a) for a in g.axis_names} == {"OPERATION ENABLED"}
