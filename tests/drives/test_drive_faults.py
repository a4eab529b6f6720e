"""Each fault: EMCY code, 0x603F, 0x1001, statusword sequence, reaction, detection bound."""

from __future__ import annotations

from pathlib import Path

import pytest

from drives.application import EmcyRequest
from drives.cia402 import FAULTS, Drive402, State
from drives.plant import PlantParams

T = 0.002
H = 125e-6  # the default sub-step
OE, FRA, F = State.OPERATION_ENABLED, State.FAULT_REACTION_ACTIVE, State.FAULT


def enabled(mode: int = 8, params: PlantParams | None = None, objects: dict | None = None):
    od = {0x6060: mode}
    od.update(objects or {})
    d = Drive402(params, objects=od)
    d.advance(T)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        d.advance(T)
    assert d.state == OE
    d.take_emcy()
    return d


def until_fault(d: Drive402, limit_s: float, dt: float = H) -> float:
    """Advance in small steps until the drive leaves OPERATION ENABLED; the time taken."""
    t = 0.0
    while d.state == OE:
        d.on_sync()
        d.advance(dt)
        t += dt
        assert t < limit_s, "no fault detected"
    return t


def check_fault(d: Drive402, code: int, sequence: tuple[State, ...]) -> None:
    spec = FAULTS[code]
    assert d.read_object(0x603F, 0) == code
    assert d.error_register == spec.register
    assert d.take_emcy() == [EmcyRequest(code, spec.register)]
    seen = [d.state]
    for _ in range(500):
        if d.state == F:
            break
        d.advance(T)
        if d.state != seen[-1]:
            seen.append(d.state)
    assert tuple(seen) == sequence
    sw = d.read_object(0x6041, 0)
    assert sw & 0x4F == 0x08  # FAULT
    assert not sw & 0x04  # operation disabled: no torque


def reset(d: Drive402) -> None:
    d.write_object(0x6040, 0, 0x00)
    d.write_object(0x6040, 0, 0x80)


# ------------------------------------------------------------------ following error
def test_following_error_window_timeout_and_bound():
    d = enabled(objects={0x6065: 1_000, 0x6066: 10})
    d.write_object(0x607A, 0, 8_000)  # an excessive command step: 8 mm in one cycle
    d.on_sync()
    exceeded_at = None
    t = 0.0
    while d.state == OE:
        d.advance(H)
        t += H
        if exceeded_at is None and abs(d.read_object(0x60F4, 0)) > 1_000:
            exceeded_at = t
        assert t < 0.1
    assert exceeded_at is not None
    latency = t - exceeded_at
    # counted in sub-steps spent outside the window: 0x6066 ± 1 sub-step
    assert 0.010 - H - 1e-9 <= latency <= 0.010 + H + 1e-9
    assert d.read_object(0x6041, 0) & 0x2000  # bit 13 following error
    check_fault(d, 0x8611, (FRA, F))  # 0x605E = 2: quick-stop ramp first
    reset(d)
    assert d.state == State.SWITCH_ON_DISABLED
    assert d.take_emcy() == [EmcyRequest(0, 0)]
    assert d.read_object(0x603F, 0) == 0


def test_following_error_monitor_off_with_window_ffffffff():
    d = enabled(objects={0x6065: 0xFFFFFFFF, 0x6066: 0})
    d.write_object(0x607A, 0, 8_000)
    for _ in range(100):
        d.on_sync()
        d.advance(T)
    assert d.state == OE


# ------------------------------------------------------------------ current
def test_overcurrent_from_an_inverter_fault_within_one_substep():
    d = enabled()
    d.inject("inverter_fault")
    t = until_fault(d, 0.01)
    assert t <= 4 * H  # L·ΔI/V: 11 A at 325 V through 3 mH takes ≈ 0.1 ms, then 1 sub-step
    check_fault(d, 0x2310, (F,))  # forced coast, straight to FAULT
    reset(d)
    assert d.state == F  # the shorted switch is still there
    d.clear_injection("inverter_fault")
    reset(d)
    assert d.state == State.SWITCH_ON_DISABLED


def test_i2t_trips_after_the_predicted_time_with_warning_first():
    params = PlantParams().with_(thermal={"i2t_peak_time": 0.2})
    d = enabled(params=params)
    d.inject("load_force", newtons=1_300.0)  # ≈ 5 A holding current
    for _ in range(50):
        d.on_sync()
        d.advance(T)
    current = abs(d.plant.current)
    d.plant.i2t = 0.0  # count from the settled holding current, not the load-step transient
    m = params.motor
    predicted = (m.peak_current**2 - m.rated_current**2) * 0.2 / (current**2 - m.rated_current**2)
    warned = False
    t = 0.1
    warned = False
    while d.state == OE:
        d.on_sync()
        d.advance(T)
        t += T
        warned |= bool(d.read_object(0x6041, 0) & 0x0080)
        assert t < 5
    assert warned
    assert t - 0.1 == pytest.approx(predicted, rel=0.02)
    # holding still: the quick-stop reaction is over within the same 2 ms cycle
    check_fault(d, 0x2350, (F,))


# ------------------------------------------------------------------ temperature
def test_thermal_model_steady_rise_is_rth_times_losses():
    from drives.plant import VELOCITY, Plant

    params = PlantParams().with_(thermal={"time_constant": 0.5})
    p = Plant(params)
    p.load_force = 900.0
    for _ in range(int(5.0 / H)):
        p.step(H, VELOCITY, vel_demand=0.0)
    loss = p.current**2 * params.motor.resistance
    rise = p.winding_temp - params.thermal.ambient
    assert rise == pytest.approx(params.thermal.thermal_resistance * loss, rel=0.01)


def test_over_temperature_trips_at_the_threshold_after_warning():
    d = enabled()
    d.inject("load_force", newtons=1_300.0)
    d.inject("winding_temperature", celsius=149.8)
    d.on_sync()
    d.advance(T)
    assert d.read_object(0x6041, 0) & 0x0080  # warning above 130 °C
    until_fault(d, 5.0, dt=T)
    assert d.plant.winding_temp == pytest.approx(150.0, abs=0.01)
    check_fault(d, 0x4310, (F,))  # at standstill FRA ends inside the same cycle
    reset(d)
    assert d.state == F  # still above the warning temperature
    d.plant.winding_temp = 60.0
    reset(d)
    assert d.state == State.SWITCH_ON_DISABLED


# ------------------------------------------------------------------ DC link
def _spin(d: Drive402, speed: int, cycles: int = 60) -> None:
    d.write_object(0x60FF, 0, speed)
    for _ in range(cycles):
        d.on_sync()
        d.advance(T)


def test_braking_with_the_chopper_keeps_the_link_below_the_trip():
    d = enabled(mode=3, objects={0x6083: 20_000_000, 0x6085: 50_000_000})
    _spin(d, 750_000)
    d.write_object(0x605A, 0, 6)
    d.write_object(0x6040, 0, 0x02)
    peak = 0.0
    for _ in range(int(0.1 / H)):
        d.advance(H)
        peak = max(peak, d.plant.vdc)
    assert d.state == State.QUICK_STOP_ACTIVE
    assert 380.0 <= peak < 420.0  # the chopper clamps it


def test_dc_link_overvoltage_while_braking_with_a_failed_chopper():
    d = enabled(mode=3, objects={0x6083: 20_000_000, 0x6085: 50_000_000})
    _spin(d, 750_000)
    d.inject("chopper_failure")
    d.write_object(0x6040, 0, 0x02)
    t = 0.0
    while d.state == State.QUICK_STOP_ACTIVE:
        d.advance(H)
        t += H
        assert t < 0.1
    assert d.plant.vdc > 420.0
    check_fault(d, 0x3210, (F,))


def test_supply_loss_is_detected_by_the_mains_monitor():
    d = enabled()
    d.inject("supply_loss")
    t = until_fault(d, 0.1)
    assert 0.020 < t <= 0.020 + 2 * H
    check_fault(d, 0x3130, (FRA, F))


def test_dc_link_undervoltage_under_load_without_mains():
    params = PlantParams().with_(dc_link={"mains_loss_detect": 10.0})  # no mains monitor
    d = enabled(mode=3, params=params)
    d.inject("load_force", newtons=-1_200.0)
    _spin(d, 300_000, cycles=150)
    d.inject("supply_loss")
    until_fault(d, 1.0)
    assert d.plant.vdc < 200.0
    check_fault(d, 0x3220, (F,))


# ------------------------------------------------------------------ encoder
def test_encoder_break_detected_in_one_substep():
    d = enabled()
    d.inject("encoder_break")
    assert until_fault(d, 0.01) == pytest.approx(H)
    check_fault(d, 0x7305, (F,))


def test_encoder_count_jump_detected_by_plausibility():
    d = enabled()
    d.inject("encoder_jump", counts=50_000)
    assert until_fault(d, 0.01) == pytest.approx(H)
    check_fault(d, 0x7305, (F,))
    reset(d)
    assert d.state == State.SWITCH_ON_DISABLED  # a jump is gone once it has happened


# ------------------------------------------------------------------ motor blocked
def test_blocked_motor_after_blocked_time_at_the_current_limit():
    d = enabled(mode=3)
    _spin(d, 50_000, cycles=100)
    d.inject("blocked")
    t = until_fault(d, 1.0)
    assert 0.25 < t <= 0.25 + 0.01  # blocked_time, after the speed collapses
    check_fault(d, 0x7121, (FRA, F))


# ------------------------------------------------------------------ limit switches
def test_hardware_limit_switch_faults_then_allows_moving_away():
    params = PlantParams().with_(switches={"initial_position": 0.550})
    d = enabled(params=params)
    x = 0.0
    t = 0.0
    while d.state == OE:
        x += 100.0  # 50 mm/s toward the positive limit at 555 mm
        d.write_object(0x607A, 0, round(x))
        d.on_sync()
        d.advance(T)
        t += T
        assert t < 1.0
    assert d.read_object(0x60FD, 0) & 0x2
    check_fault(d, 0x8612, (FRA, F))
    reset(d)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
    pos = d.read_object(0x6064, 0)
    d.write_object(0x607A, 0, pos + 500)  # further into the switch: blocked
    for _ in range(20):
        d.on_sync()
        d.advance(T)
    assert d.read_object(0x6041, 0) & 0x0800  # internal limit active
    assert d.read_object(0x6064, 0) <= pos + 5
    for k in range(1, 200):
        d.write_object(0x607A, 0, pos - 50 * k)  # away from it
        d.on_sync()
        d.advance(T)
    assert d.state == OE
    assert not d.read_object(0x60FD, 0) & 0x2


# ------------------------------------------------------------------ communication
@pytest.mark.parametrize("code", [0x8130, 0x8110, 0x8140, 0x8210])
def test_communication_faults_follow_6007(code):
    d = enabled()
    d.on_communication_fault(code)
    assert d.state == FRA
    assert d.read_object(0x603F, 0) == code
    assert d.error_register == 0x11
    assert d.take_emcy() == []  # sent by the CiA 301 layer
    d.advance(T)
    assert d.state == F
    reset(d)
    assert d.state == State.SWITCH_ON_DISABLED
    assert d.take_emcy() == [EmcyRequest(0, 0)]


def test_fault_table_is_documented():
    doc = (Path(__file__).parents[2] / "docs" / "cia402.md").read_text(encoding="utf-8")
    for code in FAULTS:
        assert f"0x{code:04X}" in doc


def test_unknown_injection_kind_is_refused_with_the_list():
    d = Drive402()
    with pytest.raises(ValueError, match="load_force"):
        d.inject("gremlins")


def test_injection_with_a_missing_parameter_says_which():
    d = Drive402()
    with pytest.raises(ValueError, match="volts"):
        d.inject("mains_voltage")
