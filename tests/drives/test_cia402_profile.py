"""Property tests of the set-point generators (the drive's little trajectory planner)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from drives.cia402 import Drive402
from drives.cia402.profile import Demand, ramp_velocity, stop_step, trapezoid_step

H = 125e-6


@settings(max_examples=60, deadline=None)
@given(
    start=st.floats(-100.0, 100.0),
    v0=st.floats(-300.0, 300.0),
    target=st.floats(-100.0, 100.0),
    vmax=st.floats(50.0, 500.0),
    acc=st.floats(500.0, 50_000.0),
    dec=st.floats(500.0, 50_000.0),
)
def test_trapezoid_lands_exactly_within_limits(start, v0, target, vmax, acc, dec):
    d = Demand(start, v0)
    peak_after_start = 0.0
    limit = max(abs(v0), vmax)
    # bound: the distance at vmax plus two full speed changes, with margin
    bound = (abs(target - start) / vmax + 4 * (abs(v0) + vmax) / min(acc, dec)) / H + 100
    for _ in range(int(2 * bound)):
        v_before = d.vel
        arrived = trapezoid_step(d, target, vmax, acc, dec, H)
        assert abs(d.vel) <= limit + 1e-9
        if not arrived:
            assert abs(d.vel - v_before) <= max(acc, dec) * H * (1 + 1e-9)
        if abs(v0) <= vmax:
            peak_after_start = max(peak_after_start, abs(d.vel))
        if arrived:
            break
    else:
        raise AssertionError("never arrived")
    assert d.pos == target and d.vel == 0.0
    assert peak_after_start <= vmax + 1e-9


@settings(max_examples=100, deadline=None)
@given(v0=st.floats(-500.0, 500.0), dec=st.floats(100.0, 100_000.0))
def test_stop_ramp_takes_v_over_dec(v0, dec):
    d = Demand(0.0, v0)
    n = 0
    while not stop_step(d, dec, H):
        n += 1
    assert abs(n * H - abs(v0) / dec) <= H + 1e-12
    # distance of a linear ramp: v²/2a (to within one sub-step of speed)
    assert abs(abs(d.pos) - v0 * v0 / (2 * dec)) <= abs(v0) * H + 1e-9


@settings(max_examples=100, deadline=None)
@given(v0=st.floats(-100.0, 100.0), target=st.floats(-100.0, 100.0))
def test_velocity_ramp_reaches_the_target_velocity_exactly(v0, target):
    d = Demand(0.0, v0)
    for _ in range(10_000):
        ramp_velocity(d, target, 1000.0, 2000.0, H)
    assert d.vel == target


def test_power_on_reset_loses_the_incremental_position_not_the_table():
    d = Drive402(objects={0x6060: 6, 0x6098: 37, 0x607C: 4321})
    d.advance(0.002)
    for cw in (0x06, 0x0F, 0x1F):
        d.write_object(0x6040, 0, cw)
    assert d.homed and d.read_object(0x6064, 0) == 4321
    table = d.plant.table_x
    d.power_on_reset()
    assert d.state_name == "NOT READY TO SWITCH ON"
    assert not d.homed
    assert d.read_object(0x6064, 0) == 0
    assert d.read_object(0x607C, 0) == 4321  # the constructor's objects are the defaults
    assert d.plant.table_x == table


def test_nmt_reset_node_reboots_the_drive_reset_communication_does_not():
    d = Drive402(objects={0x6060: 8})
    d.advance(0.002)
    for cw in (0x06, 0x0F):
        d.write_object(0x6040, 0, cw)
    d.write_object(0x6065, 0, 1234)
    d.on_nmt_reset("communication")
    assert d.state_name == "OPERATION ENABLED" and d.read_object(0x6065, 0) == 1234
    d.on_nmt_reset("node")
    assert d.state_name == "NOT READY TO SWITCH ON"
    assert d.read_object(0x6065, 0) == 60_000  # power-on default
    assert d.read_object(0x6060, 0) == 8  # the constructor's objects count as defaults
