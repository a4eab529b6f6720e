"""The stops of the CiA 402 power state machine, table by table: which stop each option code
starts (0x605A quick stop, 0x605E fault reaction), what finishing it leaves behind, and what
happens to a stop in progress when other controlwords arrive. The pure core first, then the
same option codes on a moving axis through the Drive402 application (the "quick stop 3/4 on a
moving axis" case that a standstill table cannot tell apart from a coast).

Written against the mutation survivors of `make mutation` (tests/mutation.py): each table
row says in the trade's words what a drive must do, and each is what a mutant got wrong.
"""

from __future__ import annotations

import pytest

from drives.cia402 import Drive402
from drives.cia402.statemachine import (
    STATE_BITS,
    SW_VOLTAGE_ENABLED,
    Conditions,
    Options,
    PowerState,
    State,
    Stop,
    state_from_statusword,
    statusword_state_bits,
    step,
)

S = State
QUICK_STOP_CW = 0x0B  # enable voltage, switch on, enable operation set; quick stop (bit 2) low
ENABLE_CW = 0x0F

# 0x605A: option code -> (stop that runs, hold in QUICK STOP ACTIVE after standstill)
QUICK_STOP_OPTIONS = [
    (0, Stop.COAST, False),
    (1, Stop.SLOW_DOWN, False),
    (2, Stop.QUICK_STOP, False),
    (3, Stop.CURRENT_LIMIT, False),
    (4, Stop.VOLTAGE_LIMIT, False),
    (5, Stop.SLOW_DOWN, True),
    (6, Stop.QUICK_STOP, True),
    (7, Stop.CURRENT_LIMIT, True),
    (8, Stop.VOLTAGE_LIMIT, True),
]


def moving(**kw) -> PowerState:
    return PowerState(state=S.OPERATION_ENABLED, last_controlword=ENABLE_CW, **kw)


# ------------------------------------------------------------------ pure core: quick stop
@pytest.mark.parametrize(("option", "kind", "hold"), QUICK_STOP_OPTIONS)
def test_quick_stop_option_code_starts_its_stop(option, kind, hold):
    opts = Options(quick_stop=option)
    res = step(moving(), QUICK_STOP_CW, Conditions(), opts)
    assert res.state == S.QUICK_STOP_ACTIVE
    assert res.transitions == (11,)
    assert res.power.stop == kind
    assert res.power.pending is None
    # while the axis is still braking, nothing finishes and enable does not return (16)
    braking = step(res.power, None, Conditions(), opts)
    assert (braking.state, braking.power.stop, braking.transitions) == (
        S.QUICK_STOP_ACTIVE,
        kind,
        (),
    )
    again = step(res.power, ENABLE_CW, Conditions(), opts)
    if hold:
        assert again.state == S.OPERATION_ENABLED and again.transitions == (16,)
        assert again.power.stop is None  # 16 ends the stop
    else:
        assert again.state == S.QUICK_STOP_ACTIVE and again.transitions == ()
        assert again.power.stop == kind


@pytest.mark.parametrize(("option", "kind", "hold"), QUICK_STOP_OPTIONS)
def test_quick_stop_standstill_finishes_or_holds(option, kind, hold):
    opts = Options(quick_stop=option)
    qsa = step(moving(), QUICK_STOP_CW, Conditions(), opts).power
    for cw in (None, QUICK_STOP_CW):  # standstill seen with and without a new controlword
        done = step(qsa, cw, Conditions(stopped=True), opts)
        assert done.power.stop is None
        assert done.power.pending is None
        if hold:
            assert done.state == S.QUICK_STOP_ACTIVE and done.transitions == ()
        else:
            assert done.state == S.SWITCH_ON_DISABLED and done.transitions == (12,)


@pytest.mark.parametrize(("option", "kind", "hold"), QUICK_STOP_OPTIONS)
def test_disable_voltage_during_a_quick_stop_ends_it(option, kind, hold):
    opts = Options(quick_stop=option)
    qsa = step(moving(), QUICK_STOP_CW, Conditions(), opts).power
    res = step(qsa, 0x00, Conditions(), opts)
    assert (res.state, res.transitions, res.power.stop) == (S.SWITCH_ON_DISABLED, (12,), None)


# ------------------------------------------------------------------ pure core: fault reaction
# 0x605E: option code -> stop of the reaction on an energized (moving) axis
FAULT_REACTIONS = [
    (0, Stop.COAST),
    (1, Stop.SLOW_DOWN),
    (2, Stop.QUICK_STOP),
    (3, Stop.CURRENT_LIMIT),
    (4, Stop.VOLTAGE_LIMIT),
]


@pytest.mark.parametrize(("option", "kind"), FAULT_REACTIONS)
@pytest.mark.parametrize("start", [S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE])
def test_fault_reaction_option_code_on_a_moving_axis(option, kind, start):
    opts = Options(fault_reaction=option, quick_stop=6)
    ps = PowerState(state=start, last_controlword=ENABLE_CW, stop=Stop.QUICK_STOP)
    res = step(ps, None, Conditions(fault=True), opts)
    assert res.power.pending is None
    if kind == Stop.COAST:
        # nothing to ramp: 13 and 14 at once, and no stop left running in FAULT
        assert (res.state, res.transitions, res.power.stop) == (S.FAULT, (13, 14), None)
        return
    assert (res.state, res.transitions, res.power.stop) == (S.FAULT_REACTION_ACTIVE, (13,), kind)
    still = step(res.power, None, Conditions(), opts)
    assert (still.state, still.transitions, still.power.stop) == (S.FAULT_REACTION_ACTIVE, (), kind)
    done = step(res.power, None, Conditions(stopped=True), opts)
    assert (done.state, done.transitions, done.power.stop) == (S.FAULT, (14,), None)


@pytest.mark.parametrize(("option", "kind"), FAULT_REACTIONS)
def test_a_fault_that_forbids_a_ramp_coasts_whatever_the_option(option, kind):
    # encoder lost, power stage tripped: no controlled stop is possible
    opts = Options(fault_reaction=option)
    res = step(moving(), None, Conditions(fault=True, forced_coast=True), opts)
    assert (res.state, res.transitions, res.power.stop) == (S.FAULT, (13, 14), None)


@pytest.mark.parametrize(
    "state", [S.SWITCH_ON_DISABLED, S.READY_TO_SWITCH_ON, S.SWITCHED_ON], ids=lambda s: s.name
)
def test_a_fault_without_torque_goes_to_fault_at_once(state):
    res = step(PowerState(state=state), None, Conditions(fault=True), Options(fault_reaction=2))
    assert (res.state, res.transitions, res.power.stop) == (S.FAULT, (13, 14), None)


def test_a_fault_during_a_disable_operation_ramp_drops_the_pending_transition():
    opts = Options(disable_operation=1)
    ramp = step(moving(), 0x07, Conditions(), opts).power
    assert ramp.pending == S.SWITCHED_ON
    res = step(ramp, None, Conditions(fault=True), opts)
    assert res.state == S.FAULT_REACTION_ACTIVE
    assert res.power.pending is None
    done = step(res.power, None, Conditions(stopped=True), opts)
    assert (done.state, done.power.pending) == (S.FAULT, None)  # not SWITCHED ON


def test_fault_reset_leaves_no_stop_behind():
    latched = PowerState(state=S.FAULT, last_controlword=0x00, stop=Stop.QUICK_STOP)
    res = step(latched, 0x80, Conditions())
    assert (res.state, res.transitions, res.power.stop) == (S.SWITCH_ON_DISABLED, (15,), None)


def test_power_on_clears_a_stop_and_a_pending_transition():
    ps = PowerState(state=S.NOT_READY_TO_SWITCH_ON, pending=S.SWITCHED_ON, stop=Stop.SLOW_DOWN)
    res = step(ps, None)
    assert (res.state, res.transitions) == (S.SWITCH_ON_DISABLED, (1,))
    assert (res.power.pending, res.power.stop) == (None, None)


# ------------------------------------------------------------------ pure core: 5/8 ramps
@pytest.mark.parametrize(
    ("cw", "opts", "dest", "tr"),
    [
        (0x07, Options(disable_operation=1), S.SWITCHED_ON, (5,)),
        (0x06, Options(shutdown=1), S.READY_TO_SWITCH_ON, (8,)),
    ],
    ids=["disable-operation-5", "shutdown-8"],
)
def test_a_ramped_5_or_8_finishes_clean(cw, opts, dest, tr):
    res = step(moving(), cw, Conditions(), opts)
    assert (res.state, res.transitions) == (S.OPERATION_ENABLED, tr)
    assert (res.power.pending, res.power.stop) == (dest, Stop.SLOW_DOWN)
    # a controlword that is no command here (fault reset outside FAULT) leaves the ramp alone
    other = step(res.power, cw | 0x80, Conditions(), opts)
    assert (other.state, other.transitions) == (S.OPERATION_ENABLED, ())
    assert (other.power.pending, other.power.stop) == (dest, Stop.SLOW_DOWN)
    done = step(res.power, None, Conditions(stopped=True), opts)
    assert (done.state, done.power.pending, done.power.stop) == (dest, None, None)


def test_standstill_without_a_pending_transition_keeps_operation_enabled():
    # the axis stands still in OPERATION ENABLED (target reached): that finishes nothing
    for cw in (None, ENABLE_CW):
        res = step(moving(), cw, Conditions(stopped=True))
        assert (res.state, res.transitions, res.power.pending) == (S.OPERATION_ENABLED, (), None)


def test_a_quick_stop_in_progress_survives_a_repeated_quick_stop_word():
    qsa = step(moving(), QUICK_STOP_CW, Conditions(), Options(quick_stop=3)).power
    res = step(qsa, 0x02, Conditions(), Options(quick_stop=3))
    assert (res.state, res.power.stop) == (S.QUICK_STOP_ACTIVE, Stop.CURRENT_LIMIT)


# ------------------------------------------------------------------ statusword
@pytest.mark.parametrize("state", list(S), ids=lambda s: s.name)
@pytest.mark.parametrize("voltage", [False, True])
def test_statusword_voltage_enabled_bit(state, voltage):
    sw = statusword_state_bits(state, voltage_present=voltage)
    assert sw & ~SW_VOLTAGE_ENABLED == STATE_BITS[state]
    assert bool(sw & SW_VOLTAGE_ENABLED) == voltage


@pytest.mark.parametrize("state", list(S), ids=lambda s: s.name)
def test_statusword_decodes_whatever_the_dont_care_bits(state):
    # 0x4F states ignore bit 5 (quick stop); every state ignores bits 4 and 7..15
    dont_care = 0xFF90 | (
        0x20
        if state
        in (S.NOT_READY_TO_SWITCH_ON, S.SWITCH_ON_DISABLED, S.FAULT_REACTION_ACTIVE, S.FAULT)
        else 0
    )
    for extra in (0, dont_care, 0x0010, 0x0020 & dont_care, 0x0400):
        assert state_from_statusword(STATE_BITS[state] | extra) == state


# ------------------------------------------------------------------ on a moving axis
T = 0.002  # IPO cycle
SPEED = 200_000  # µm/s, profile velocity
# cycles from the quick stop to standstill: 0x6084 = 2 m/s² -> 50, 0x6085 = 10 m/s² -> 10,
# current / voltage limit: the torque limit brakes harder than either ramp
STANDSTILL = {
    Stop.SLOW_DOWN: (48, 54),
    Stop.QUICK_STOP: (9, 13),
    Stop.CURRENT_LIMIT: (1, 6),
    Stop.VOLTAGE_LIMIT: (1, 6),
}


def _spinning(option: int) -> Drive402:
    d = Drive402(objects={0x6060: 3, 0x605A: option})  # profile velocity
    d.advance(T)
    for cw in (0x06, 0x07, ENABLE_CW):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        d.advance(T)
    d.write_object(0x60FF, 0, SPEED)
    for _ in range(200):
        d.on_sync()
        d.advance(T)
    assert d.state == S.OPERATION_ENABLED
    assert abs(d.read_object(0x606C, 0) - SPEED) < SPEED // 100
    return d


@pytest.mark.parametrize(("option", "kind", "hold"), QUICK_STOP_OPTIONS)
def test_quick_stop_option_code_on_a_moving_axis(option, kind, hold):
    d = _spinning(option)
    d.write_object(0x6040, 0, 0x02)
    assert d.state == S.QUICK_STOP_ACTIVE  # always shown first, even for a coast
    cycles = 0
    while True:
        d.on_sync()
        d.advance(T)
        cycles += 1
        velocity = d.read_object(0x606C, 0)
        sw = d.read_object(0x6041, 0)
        if d.state != S.QUICK_STOP_ACTIVE or sw & 0x0400:  # left QSA, or standstill held
            break
        assert cycles < 100, f"option {option}: no standstill after {cycles} cycles"
    if kind == Stop.COAST:
        # the power stage is off at once: disabled one cycle later with the axis still running
        assert cycles == 1 and d.state == S.SWITCH_ON_DISABLED
        assert velocity > SPEED * 0.9
        return
    lo, hi = STANDSTILL[kind]
    assert lo <= cycles <= hi, f"option {option}: standstill after {cycles} cycles"
    # stopped under control (the last braking cycle may overshoot a little) before the
    # torque goes
    assert abs(velocity) < SPEED // 20
    if hold:
        assert d.state == S.QUICK_STOP_ACTIVE
        d.write_object(0x6040, 0, ENABLE_CW)
        assert d.state == S.OPERATION_ENABLED  # transition 16
    else:
        assert d.state == S.SWITCH_ON_DISABLED
