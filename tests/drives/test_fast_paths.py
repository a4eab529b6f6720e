"""The speed-ups compute exactly what the readable paths compute."""

from __future__ import annotations

import math

import pytest

from drives.cia402 import Drive402, State
from drives.plant import POSITION, Plant, PlantParams

T = 0.001


def _enabled(params: PlantParams | None) -> Drive402:
    d = Drive402(params, objects={0x6060: 8})
    d.advance(T)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        d.advance(T)
    assert d.state == State.OPERATION_ENABLED
    return d


def _plant_state(p: Plant) -> tuple:
    return (
        p.theta,
        p.omega,
        p.current,
        p.voltage,
        p.vdc,
        p.table_x,
        p.counts,
        p.vel_meas,
        p.vel_integral,
        p.winding_temp,
        p.i2t,
        p.chopper,
        p.blocked_for,
        p.mains_lost_for,
        p.current_limited,
        p.velocity_limited,
    )


def _trace(d: Drive402, targets: list[int]) -> list[tuple]:
    out = []
    for target in targets:
        d.write_object(0x607A, 0, target)
        d.on_sync()
        d.advance(T)
        out.append(
            (
                d.state,
                d.read_object(0x6041, 0),
                d.read_object(0x6064, 0),
                d.read_object(0x603F, 0),
                *_plant_state(d.plant),
                d._fe_timer,
            )
        )
    return out


@pytest.mark.parametrize("substep", [None, 1e-3])
@pytest.mark.parametrize(
    "scenario",
    [
        "sine",  # plain following
        "negative_limit",  # runs onto the -5 mm limit switch: fault 0x8612 mid-cycle
        "following_error",  # a jump beyond the 0x6065 window: fault 0x8611
        "loaded_backlash",  # load force, backlash, hot ambient: every term of the plant
        "blocked",  # a blocked axis at the current limit: fault 0x7121
        "supply_loss",  # mains lost while moving: the DC link sags, 0x3130
        "encoder_noise",  # a noisy reading on every sub-step
        "encoder_break",  # 0x7305 on the first sub-step
        "inverter_fault",  # a shorted switch: the current runs away, 0x2310
    ],
)
def test_csp_substep_loop_equals_the_generic_substep(substep, scenario):
    params = PlantParams().for_substep(substep) if substep else None
    fast, slow = _enabled(params), _enabled(params)
    slow.csp_fast_path = False  # every sub-step generic
    x0 = fast.read_object(0x6064, 0)
    if scenario == "sine":
        targets = [x0 + round(10_000 * math.sin(2 * math.pi * k * T)) for k in range(400)]
    elif scenario == "negative_limit":
        # 200 mm down to the switch at -5 mm at 100 mm/s ends in a limit fault
        targets = [x0 - 100 * k for k in range(2200)]
    elif scenario == "following_error":
        targets = [x0] * 5 + [x0 + 200_000] * 50
    else:
        for d in (fast, slow):
            if scenario == "loaded_backlash":
                d.inject("load_force", newtons=800.0)
                d.inject("backlash", metres=20e-6)
                d.inject("ambient_temperature", celsius=60.0)
            elif scenario == "encoder_noise":
                d.inject("encoder_noise", counts=50)
            elif scenario in ("blocked", "encoder_break", "inverter_fault", "supply_loss"):
                d.inject(scenario)
        targets = [x0 + round(20_000 * math.sin(2 * math.pi * k * T)) for k in range(600)]
    a, b = _trace(fast, targets), _trace(slow, targets)
    assert a == b
    if scenario == "negative_limit":
        assert fast.read_object(0x603F, 0) == 0x8612
    if scenario == "following_error":
        assert fast.read_object(0x603F, 0) == 0x8611
    if scenario in ("encoder_break", "inverter_fault"):
        assert fast.read_object(0x603F, 0) == (0x7305 if scenario == "encoder_break" else 0x2310)


@pytest.mark.parametrize("noise", [0.0, 30.0])
def test_follow_ramp_is_step_on_the_ramp_demand(noise):
    # the ramp as the CSP fine interpolator runs it: each sub-step controls on the demand at
    # its start, with the ramp speed as feed-forward
    h, n, speed, ramp_time = 125e-6, 40, 20.0, 30 * 125e-6
    fast, slow = Plant(), Plant()
    for p in (fast, slow):
        p.load_force = 150.0
        p.set_encoder_noise(noise)
    done, fault, inputs, pos, vel, seg_t, _ = fast.follow_ramp(
        h, n, 0.0, 0.0, ramp_time, speed * ramp_time, speed, 6.0, False, False, None, 0.0, 0.01, 0
    )
    assert (done, fault, inputs) == (n, 0, 0)
    demand, t = 0.0, 0.0
    for _ in range(n):
        start = demand
        if t < ramp_time:
            t += h
            demand = speed * ramp_time if t >= ramp_time else demand + speed * h
            ff = speed
        else:
            ff = 0.0
        assert slow.step(h, POSITION, start, ff, 0.0, 6.0) == 0
    assert (pos, vel, seg_t) == (demand, 0.0, t)
    assert _plant_state(fast) == _plant_state(slow)
    assert fast.omega > 1.0  # rad/s: the motor turns, the loops were working
