"""Homing mode (6) against simulated limit switches, a home switch (dog) and the index."""

from __future__ import annotations

import math

import pytest

from drives.cia402 import Drive402, State
from drives.plant import PlantParams

T = 0.002
EDGE = 0.010  # m, home switch edge (default: dog over the negative end, active below)


def drive(start_m: float, method: int, offset: int = 0, creep: int = 5_000, **switches) -> Drive402:
    params = PlantParams().with_(switches={"initial_position": start_m, **switches})
    d = Drive402(
        params,
        objects={
            0x6060: 6,
            0x6098: method,
            0x607C: offset,
            (0x6099, 1): 50_000,
            (0x6099, 2): creep,
            0x609A: 2_000_000,
        },
    )
    d.advance(T)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.advance(T)
    assert d.state == State.OPERATION_ENABLED
    return d


def home(d: Drive402, limit_s: float = 6.0) -> int:
    d.write_object(0x6040, 0, 0x1F)
    assert d.read_object(0x6041, 0) & 0x3400 == 0x0000  # in progress at once
    for _ in range(int(limit_s / T)):
        d.on_sync()
        d.advance(T)
        status = d.read_object(0x6041, 0) & 0x3400
        if status in (0x1400, 0x2400):
            return status
    return d.read_object(0x6041, 0) & 0x3400


def reference_of(d: Drive402) -> float:
    """Table position (m) that the drive now calls 0, from the physical table position."""
    return d.plant.table_x - d.read_object(0x6064, 0) * 1e-6


@pytest.mark.parametrize("method", [35, 37])
def test_current_position_methods(method):
    d = drive(0.2, method, offset=1234)
    d.write_object(0x6040, 0, 0x1F)
    assert d.read_object(0x6041, 0) & 0x3400 == 0x1000  # attained
    d.on_sync()
    d.advance(T)
    assert d.read_object(0x6041, 0) & 0x3400 == 0x1400
    assert d.read_object(0x6064, 0) == 1234
    assert d.homed


@pytest.mark.parametrize("start", [0.060, 0.004])  # normal side, and on the dog
def test_method_22_dog_and_creep_same_direction_from_both_sides(start):
    d = drive(start, 22, offset=-500)
    assert home(d) == 0x1400
    # the reference is the switch edge, to the encoder/latch resolution
    assert reference_of(d) - 500e-6 == pytest.approx(EDGE, abs=2e-6)
    # the axis stops just past the edge: creep speed / Kv of position lag (5 mm/s / 16.67 /s
    # = 300 µm) is all it travels on, since the demand brakes at the latch
    assert 0 < -500 - d.read_object(0x6064, 0) < 5_000 / 16.67 + 20


def test_method_22_final_approach_is_at_creep_speed_in_the_negative_direction():
    d = drive(0.030, 22, creep=2_000)
    d.write_object(0x6040, 0, 0x1F)
    speeds = []
    prev_inputs = d.read_object(0x60FD, 0)
    prev_speed = 0
    for _ in range(3000):
        d.on_sync()
        d.advance(T)
        inputs = d.read_object(0x60FD, 0)
        if inputs != prev_inputs:
            speeds.append(prev_speed)  # the demand speed in the cycle before the crossing
        prev_inputs = inputs
        prev_speed = d.read_object(0x606B, 0)
        if d.read_object(0x6041, 0) & 0x3400 == 0x1400:
            break
    # the dog edge was crossed three times: fast (−), back off at creep (+), creep (−)
    assert len(speeds) == 3
    assert speeds[0] <= -40_000
    assert 0 < speeds[1] <= 2_000  # backing off, still accelerating to creep
    assert speeds[2] == pytest.approx(-2_000, abs=100)


@pytest.mark.parametrize("start", [0.060, 0.004])
def test_method_21_positive_final_approach(start):
    d = drive(start, 21)
    assert home(d) == 0x1400
    assert reference_of(d) == pytest.approx(EDGE, abs=2e-6)


@pytest.mark.parametrize("method", [5, 6])
def test_home_switch_with_index_is_repeatable_and_next_to_the_edge(method):
    refs = []
    for start in (0.060, 0.045, 0.004):
        d = drive(start, method)
        assert home(d) == 0x1400
        refs.append(reference_of(d))
    assert max(refs) - min(refs) < 2e-6  # the same index mark every time
    lead = 0.010
    if method == 6:  # moving negative past the edge: the first index below it
        assert EDGE - lead < refs[0] < EDGE
    else:  # method 5: moving positive off the dog: the first index above the edge
        assert EDGE < refs[0] < EDGE + lead


@pytest.mark.parametrize("method", [19, 20])
def test_positive_home_switch_methods(method):
    sw = {"home_switch": 0.500, "home_switch_active_below": False}
    for start in (0.460, 0.520):
        d = drive(start, method, **sw)
        assert home(d) == 0x1400
        assert reference_of(d) == pytest.approx(0.500, abs=2e-6)


@pytest.mark.parametrize(("method", "start", "edge"), [(17, 0.020, -0.005), (18, 0.530, 0.555)])
def test_limit_switch_methods_without_fault(method, start, edge):
    d = drive(start, method)
    assert home(d) == 0x1400
    assert reference_of(d) == pytest.approx(edge, abs=2e-6)
    assert d.state == State.OPERATION_ENABLED
    assert d.take_emcy() == []  # the limit switch is the reference here, not a fault


@pytest.mark.parametrize(("method", "direction"), [(33, -1), (34, 1)])
def test_index_pulse_methods(method, direction):
    d = drive(0.2, method)
    x0 = d.plant.table_x
    assert home(d) == 0x1400
    ref = reference_of(d)
    assert 0.0 < (ref - x0) * direction < 0.010  # within one revolution, in that direction
    # the index is at the configured rotor angle
    rev = ref / 0.010 * 2 * math.pi  # the rotor is keyed to the screw: angle = x / lead
    assert math.isclose(rev % (2 * math.pi), 0.5, abs_tol=2e-3)


def test_halt_interrupts_homing():
    d = drive(0.060, 22)
    d.write_object(0x6040, 0, 0x1F)
    for _ in range(50):
        d.on_sync()
        d.advance(T)
    d.write_object(0x6040, 0, 0x11F)
    d.on_sync()
    d.advance(T)
    assert d.read_object(0x6041, 0) & 0x3400 == 0x0400  # interrupted
    assert not d.homed


def test_homing_error_when_no_switch_is_found_before_the_limit():
    d = drive(0.540, 20, home_switch=None)
    status = home(d)
    assert status == 0x2400  # error, velocity zero
    assert not d.homed
    assert d.state == State.OPERATION_ENABLED


def test_homing_with_a_switch_method_hitting_the_wrong_limit_is_an_error():
    sw = {"home_switch": 0.500, "home_switch_active_below": False}
    d = drive(0.550, 20, **sw)  # starts on the dog, backs off negative ... fine
    assert home(d) == 0x1400
    d2 = drive(0.020, 19, home_switch=None)  # searches + for a dog that is not fitted
    assert home(d2, limit_s=15.0) == 0x2400
