"""The plant against theory: Kv following error, circle radius loss, motor and screw laws."""

from __future__ import annotations

import math

import pytest

from drives.cia402 import Drive402, State
from drives.plant import OFF, POSITION, VELOCITY, Plant, PlantParams

T = 0.002  # IPO cycle


def enabled(mode: int = 8, params: PlantParams | None = None, **objects) -> Drive402:
    od = {0x6060: mode}
    od.update(objects)
    d = Drive402(params, objects=od)
    d.advance(T)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        d.advance(T)
    assert d.state == State.OPERATION_ENABLED
    return d


def csp_cycle(d: Drive402, target: float) -> None:
    d.write_object(0x607A, 0, round(target))
    d.on_sync()
    d.advance(T)


@pytest.mark.parametrize(("kv", "v_mm_s"), [(16.67, 100.0), (30.0, 50.0), (10.0, 200.0)])
def test_steady_following_error_is_v_over_kv(kv, v_mm_s):
    params = PlantParams().with_(loops={"kv": kv})
    d = enabled(params=params)
    v = v_mm_s * 1000.0  # µm/s
    x = 0.0
    for _ in range(600):
        x += v * T
        csp_cycle(d, x)
    fe = d.read_object(0x60F4, 0)
    theory = v / kv
    assert abs(fe - theory) / theory < 0.01
    # the velocity actually reached the command (velocity PI has no steady error)
    assert abs(d.read_object(0x606C, 0) - v) / v < 0.01


def test_velocity_feedforward_removes_the_following_error():
    params = PlantParams().with_(loops={"velocity_feedforward": 1.0})
    d = enabled(params=params)
    x = 0.0
    for _ in range(600):
        x += 100_000 * T
        csp_cycle(d, x)
    # against 6000 µm without feed-forward: with the demand and the encoder sampled at the
    # same instant, full feed-forward leaves no steady lag (≤ 1 increment, CiA G7 goal)
    assert abs(d.read_object(0x60F4, 0)) <= 1


def test_two_axis_circle_radius_shrinks_by_v2_over_2RKv2():
    kv = 16.67
    radius, v = 50_000.0, 100_000.0  # µm, µm/s
    w = v / radius
    dx, dy = enabled(), enabled()
    radii = []
    n_turn = round(2 * math.pi / w / T)
    for k in range(1, int(1.5 * n_turn) + 1):
        t = k * T
        csp_cycle(dx, radius * (math.cos(w * t) - 1.0))
        csp_cycle(dy, radius * math.sin(w * t))
        if k > n_turn // 2:
            ax = dx.read_object(0x6064, 0) + radius
            ay = dy.read_object(0x6064, 0)
            radii.append(math.hypot(ax, ay))
    shrink = radius - sum(radii) / len(radii)
    theory = v * v / (2.0 * radius * kv * kv)
    assert abs(shrink - theory) / theory < 0.05
    assert max(radii) - min(radii) < 0.05 * theory  # a round circle, not an ellipse


def test_dc_motor_steady_state_voltage_equation():
    """V − R·I = Kb·ω once the speed is steady (REQ-DC-2 form of V = Kb·ω + R·I + L·dI/dt)."""
    p = Plant()
    m = p.params.motor
    for _ in range(8000):
        p.step(125e-6, VELOCITY, vel_demand=200.0)
    assert p.omega == pytest.approx(200.0, rel=0.01)
    assert p.voltage - m.resistance * p.current == pytest.approx(m.kb * p.omega, rel=1e-3)
    # torque balance: Km·I = Coulomb + viscous friction
    sc = p.params.screw
    assert m.km * p.current == pytest.approx(sc.coulomb_torque + sc.viscous * p.omega, rel=0.02)


def test_reflected_inertia_of_table_and_screw():
    sc = PlantParams().screw
    j_table = sc.table_mass * sc.lead**2 / (4 * math.pi**2)
    assert sc.reflected_inertia == pytest.approx(sc.screw_inertia + j_table)
    geared = PlantParams().with_(screw={"gear_ratio": 4.0}).screw
    assert geared.reflected_inertia == pytest.approx(sc.reflected_inertia / 16.0)


def test_acceleration_at_the_current_limit_is_torque_over_inertia():
    p = Plant()
    m, sc = p.params.motor, p.params.screw
    h = 125e-6
    for _ in range(40):  # 5 ms flat out
        p.step(h, VELOCITY, vel_demand=400.0)
    w0 = p.omega
    for _ in range(40):
        p.step(h, VELOCITY, vel_demand=400.0)
    acc = (p.omega - w0) / (40 * h)
    theory = (m.km * m.peak_current - sc.coulomb_torque - sc.viscous * p.omega) / p.inertia
    assert acc == pytest.approx(theory, rel=0.02)


def test_encoder_resolution_quantises_the_position():
    p = Plant()
    p.theta = 1.0e-6  # less than one count (6 µrad)
    p.step(125e-6, POSITION, pos_demand=1.0e-6)
    assert p.counts == 0
    p.theta = 2 * math.pi / p.params.encoder.counts_per_rev * 3.5
    p.step(125e-6, POSITION, pos_demand=p.theta)
    assert p.counts == 3


def test_backlash_shows_in_table_not_in_motor_encoder():
    params = PlantParams().with_(screw={"backlash": 20e-6})
    d = enabled(params=params)
    x0 = d.plant.table_x
    for k in range(1, 101):
        csp_cycle(d, 10.0 * k)  # +1 mm
    for k in range(1, 201):
        csp_cycle(d, 1000.0 - 10.0 * k)  # back to -1 mm
    for _ in range(200):
        csp_cycle(d, -1000.0)
    # the motor is back at -1 mm (encoder), the table lags by half the dead band
    assert d.read_object(0x6064, 0) == pytest.approx(-1000, abs=2)
    assert (d.plant.table_x - x0) * 1e6 == pytest.approx(-1000 + 10, abs=2)


def test_quick_stop_ramp_time_is_v_over_decel():
    d = enabled(mode=3)  # profile velocity
    d.write_object(0x60FF, 0, 200_000)
    for _ in range(200):
        d.on_sync()
        d.advance(T)
    decel = 10_000_000  # 0x6085 default, µm/s²
    d.write_object(0x605A, 0, 6)  # stay in QSA to watch the standstill bit
    d.write_object(0x6040, 0, 0x02)
    cycles = 0
    while not d.read_object(0x6041, 0) & 0x0400:
        d.advance(T)
        cycles += 1
        assert cycles < 100
    expect = 200_000 / decel / T  # 10 cycles
    assert abs(cycles - expect) <= 1


@pytest.mark.parametrize("substep", [250e-6, 500e-6, 1e-3])
def test_coarse_substeps_keep_the_kv_law(substep):
    params = PlantParams().for_substep(substep)
    assert params.loops.velocity_bandwidth_hz <= 0.05 / substep + 1e-9
    d = enabled(params=params)
    x = 0.0
    for _ in range(600):
        x += 100_000 * T
        csp_cycle(d, x)
    theory = 100_000 / params.loops.kv
    assert abs(d.read_object(0x60F4, 0) - theory) / theory < 0.01


@pytest.mark.parametrize(("substep", "settle_ms"), [(None, 2.0), (1e-3, 35.0)])
def test_quick_stop_in_csp_ends_at_standstill_shortly_after_the_ramp(substep, settle_ms):
    # The quick-stop ramp drives the velocity loop, so the motor itself decelerates on it;
    # ramping the position demand instead left the motor to run out its v/Kv following
    # error (3 mm, ~250 ms at 50 mm/s) before it fell below the standstill speed.
    params = PlantParams().for_substep(substep) if substep else None
    d = enabled(params=params)
    x = 0.0
    for _ in range(150):
        x += 50_000 * T  # 50 mm/s
        csp_cycle(d, x)
    start = d.read_object(0x6064, 0)
    d.write_object(0x6040, 0, 0x02)  # quick stop, 0x605A = 2: ramp 0x6085, then disabled
    elapsed = 0.0
    while d.state != State.SWITCH_ON_DISABLED:
        d.on_sync()
        d.advance(T)
        elapsed += T
        assert elapsed < 0.5
    ramp = 50_000 / d.read_object(0x6085, 0)  # 5 ms
    assert ramp <= elapsed <= ramp + settle_ms * 1e-3 + T
    stopped_at = d.read_object(0x6064, 0)
    # v²/2a = 125 µm on the ramp, plus the velocity loop's lag (a coarse loop overshoots back)
    assert 50 <= stopped_at - start <= 250
    for _ in range(20):
        d.advance(T)
    assert abs(d.read_object(0x6064, 0) - stopped_at) <= 2  # at standstill when disabled


def test_a_table_pushed_with_the_power_stage_off_stops_on_its_hard_stop():
    """No holding brake: a lasting force back-drives the screw; the table runs to the hard
    stop past the limit switch and rests there (it used to run metres off the screw)."""
    for force in (1800.0, -1800.0):
        p = Plant()
        p.load_force = force
        for _ in range(8000 * 3):  # 3 s of 125 us sub-steps
            p.step(125e-6, OFF)
        sw = p.params.switches
        end = sw.positive_limit if force > 0 else sw.negative_limit
        end += sw.end_stop_overtravel if force > 0 else -sw.end_stop_overtravel
        assert p.table_x == pytest.approx(end)
        assert p.omega == 0.0
        assert p.switch_inputs() & (2 if force > 0 else 1)  # on the limit switch
