"""Modes of operation (PP, PV, CSP, CSV), objects and SDO abort codes of Drive402."""

from __future__ import annotations

import contextlib

import pytest

from drives.application import ObjectAccessError
from drives.cia402 import Drive402, State

T = 0.002


def enabled(mode: int, objects: dict | None = None) -> Drive402:
    od = {0x6060: mode}
    od.update(objects or {})
    d = Drive402(objects=od)
    d.advance(T)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        d.advance(T)
    assert d.state == State.OPERATION_ENABLED
    return d


def run(d: Drive402, cycles: int) -> None:
    for _ in range(cycles):
        d.on_sync()
        d.advance(T)


def sw(d: Drive402) -> int:
    return d.read_object(0x6041, 0)


# ----------------------------------------------------------------- profile position
def test_pp_set_point_handshake_and_target_reached():
    d = enabled(1)
    assert sw(d) & 0x0400  # at rest on its own position
    d.write_object(0x607A, 0, 20_000)  # 20 mm
    d.write_object(0x6040, 0, 0x1F)  # new set-point
    assert sw(d) & 0x1000  # set-point acknowledge
    assert not sw(d) & 0x0400
    d.write_object(0x6040, 0, 0x0F)
    assert not sw(d) & 0x1000  # ack follows bit 4 down
    cycles = 0
    while not sw(d) & 0x0400:
        run(d, 1)
        cycles += 1
        assert cycles < 2000
    assert abs(d.read_object(0x6064, 0) - 20_000) <= 10  # 0x6067 window
    # trapezoid 20 mm at 100 mm/s, 2 m/s²: 0.25 s, then the Kv lag (τ = 1/Kv = 60 ms, no
    # feed-forward) settles into the 10 µm window
    assert 0.25 <= cycles * T <= 0.8


def test_pp_profile_respects_profile_velocity():
    d = enabled(1, {0x6081: 50_000})
    d.write_object(0x607A, 0, 50_000)
    d.write_object(0x6040, 0, 0x1F)
    run(d, 300)
    assert d.read_object(0x606B, 0) == pytest.approx(50_000, abs=1)
    assert d.read_object(0x606C, 0) == pytest.approx(50_000, rel=0.02)


def test_pp_relative_move_adds_to_the_last_target():
    d = enabled(1)
    for _ in range(2):
        d.write_object(0x607A, 0, 5_000)
        d.write_object(0x6040, 0, 0x5F)  # new set-point, relative
        d.write_object(0x6040, 0, 0x4F)
        run(d, 400)
    assert abs(d.read_object(0x6064, 0) - 10_000) <= 10


def test_pp_change_set_immediately_replaces_the_running_target():
    d = enabled(1)
    d.write_object(0x607A, 0, 100_000)
    d.write_object(0x6040, 0, 0x1F)
    d.write_object(0x6040, 0, 0x0F)
    run(d, 50)
    d.write_object(0x607A, 0, 2_000)
    d.write_object(0x6040, 0, 0x3F)  # bit 5: change immediately
    run(d, 500)
    assert abs(d.read_object(0x6064, 0) - 2_000) <= 10


def test_pp_buffered_set_point_runs_after_the_first():
    d = enabled(1)
    d.write_object(0x607A, 0, 10_000)
    d.write_object(0x6040, 0, 0x1F)
    d.write_object(0x6040, 0, 0x0F)
    run(d, 10)
    d.write_object(0x607A, 0, -5_000)
    d.write_object(0x6040, 0, 0x1F)  # not immediate: queued
    assert sw(d) & 0x1000
    run(d, 200)
    assert d.read_object(0x6062, 0) < 10_000 or sw(d) & 0x0400
    run(d, 600)
    assert abs(d.read_object(0x6064, 0) + 5_000) <= 10


def test_pp_halt_stops_and_release_resumes():
    d = enabled(1)
    d.write_object(0x607A, 0, 30_000)
    d.write_object(0x6040, 0, 0x1F)
    run(d, 60)
    d.write_object(0x6040, 0, 0x11F)  # halt
    run(d, 300)  # ramp, then the Kv lag decays below the standstill speed
    stopped_at = d.read_object(0x6064, 0)
    assert sw(d) & 0x0400  # target reached = halted at standstill
    run(d, 20)
    assert d.read_object(0x6064, 0) == pytest.approx(stopped_at, abs=2)
    d.write_object(0x6040, 0, 0x01F)
    run(d, 600)
    assert abs(d.read_object(0x6064, 0) - 30_000) <= 10


def test_pp_software_limit_clamps_target_and_sets_internal_limit():
    d = enabled(1, {(0x607D, 1): -1_000, (0x607D, 2): 8_000})
    d.write_object(0x607A, 0, 50_000)
    d.write_object(0x6040, 0, 0x1F)
    assert sw(d) & 0x0800
    run(d, 500)
    assert abs(d.read_object(0x6064, 0) - 8_000) <= 10


# ----------------------------------------------------------------- cyclic synchronous
def test_csp_bit12_follows_and_software_limit_clamps():
    d = enabled(8, {(0x607D, 1): -5_000, (0x607D, 2): 5_000})
    assert sw(d) & 0x1000
    x = 0
    for _ in range(500):
        x += 40
        d.write_object(0x607A, 0, x)
        d.on_sync()
        d.advance(T)
    assert d.read_object(0x6062, 0) == 5_000
    assert sw(d) & 0x0800
    assert abs(d.read_object(0x6064, 0) - 5_000) <= 5


def test_csp_interpolation_period_from_60C2():
    d = enabled(8, {(0x60C2, 1): 4})  # 4 ms
    assert d.interpolation_period == pytest.approx(0.004)
    d.write_object(0x607A, 0, 400)
    d.on_sync()
    d.advance(0.002)
    assert d.read_object(0x6062, 0) == 200  # half way through the 4 ms segment
    d.advance(0.002)
    assert d.read_object(0x6062, 0) == 400


def test_csv_follows_target_velocity_each_sync():
    d = enabled(9)
    d.write_object(0x60FF, 0, 30_000)
    run(d, 200)
    assert d.read_object(0x606C, 0) == pytest.approx(30_000, rel=0.01)
    assert sw(d) & 0x1000


# ----------------------------------------------------------------- profile velocity
def test_pv_ramps_to_target_velocity_and_reports_target_reached():
    d = enabled(3)
    d.write_object(0x60FF, 0, -80_000)
    assert sw(d) & 0x1000  # speed = 0
    run(d, 10)
    assert not sw(d) & 0x0400
    assert d.read_object(0x606B, 0) == pytest.approx(-40_000, abs=2_100)  # 2 m/s² × 20 ms
    run(d, 100)
    assert sw(d) & 0x0400
    assert not sw(d) & 0x1000
    assert d.read_object(0x606C, 0) == pytest.approx(-80_000, rel=0.01)


def test_mode_change_is_displayed_and_supported_modes_reported():
    d = enabled(8)
    assert d.read_object(0x6502, 0) == 0x1A5
    for mode in (1, 3, 6, 9, 8):
        d.write_object(0x6060, 0, mode)
        assert d.read_object(0x6061, 0) == mode


# ----------------------------------------------------------------- objects and aborts
@pytest.mark.parametrize(
    ("index", "sub", "value", "abort"),
    [
        (0x6060, 0, 2, 0x06090030),  # velocity mode not supported
        (0x6060, 0, 200, 0x06090031),  # above INT8
        (0x605A, 0, 9, 0x06090031),
        (0x605A, 0, -1, 0x06090032),
        (0x605D, 0, 0, 0x06090032),
        (0x6007, 0, 4, 0x06090031),
        (0x6098, 0, 7, 0x06090030),  # homing method not implemented
        (0x6083, 0, 0, 0x06090032),
        (0x6072, 0, 3001, 0x06090031),
        (0x6040, 0, 0x10000, 0x06090031),
        (0x6041, 0, 0, 0x06010002),
        (0x6064, 0, 0, 0x06010002),
        (0x6502, 0, 0, 0x06010002),
        (0x607D, 0, 2, 0x06010002),
        (0x607D, 3, 0, 0x06090011),
        (0x6064, 1, 0, 0x06090011),
        (0x6100, 0, 0, 0x06020000),
        (0x607A, 0, b"\x01\x02", 0x06070010),
        (0x607A, 0, 1.5, 0x06070010),
        (0x607A, 0, "12", 0x06070010),
    ],
)
def test_refused_writes_abort_with_the_right_code(index, sub, value, abort):
    d = Drive402()
    before = None
    with contextlib.suppress(ObjectAccessError):
        before = d.read_object(index, sub)
    with pytest.raises(ObjectAccessError) as exc:
        d.write_object(index, sub, value)
    assert exc.value.abort_code == abort
    if before is not None:
        assert d.read_object(index, sub) == before  # refused unchanged


def test_feed_constant_refused_while_enabled():
    d = enabled(8)
    with pytest.raises(ObjectAccessError) as exc:
        d.write_object(0x6092, 1, 20_000)
    assert exc.value.abort_code == 0x08000022
    d.write_object(0x6040, 0, 0x06)
    d.write_object(0x6092, 1, 100_000)  # 0.1 µm units
    assert d.rad_per_unit == pytest.approx(2 * 3.141592653589793 / 100_000)


def test_bytes_values_are_decoded_little_endian_signed():
    d = Drive402()
    d.write_object(0x607A, 0, (-2).to_bytes(4, "little", signed=True))
    assert d.read_object(0x607A, 0) == -2


def test_owns_only_profile_objects():
    d = Drive402()
    assert d.owns(0x6040) and d.owns(0x607D)
    assert not d.owns(0x1000) and not d.owns(0x2000)


def test_max_motor_speed_6080_limits_and_sets_internal_limit():
    d = enabled(3, {0x6080: 600})  # 600 rpm = 100 mm/s on a 10 mm lead
    d.write_object(0x60FF, 0, 200_000)
    run(d, 200)
    assert d.read_object(0x606C, 0) == pytest.approx(100_000, rel=0.01)
    assert sw(d) & 0x0800
    with pytest.raises(ObjectAccessError) as exc:
        d.write_object(0x6080, 0, 6000)  # above the motor's 5000 rpm
    assert exc.value.abort_code == 0x06090031


def test_torque_and_current_actual_in_per_mille_of_rated():
    d = enabled(8)
    d.inject("load_force", newtons=-600.0)  # pulls toward −x; the motor holds against it
    run(d, 200)
    torque = 600.0 * 0.010 / (2 * 3.141592653589793 * 0.9)  # F·h/(2π·η) = 1.06 N·m
    rated = 0.45 * 2.8
    assert d.read_object(0x6077, 0) == pytest.approx(1000 * (torque + 0.04) / rated, rel=0.03)
    assert d.read_object(0x6078, 0) == pytest.approx(d.read_object(0x6077, 0), abs=1)
    assert d.read_object(0x6075, 0) == 2800 and d.read_object(0x6076, 0) == 1260
