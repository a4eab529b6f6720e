"""The pure power state machine against an independent oracle: the CiA 402 command table as
mask/value pairs (Beckhoff SSC), for every state and every combination of controlword bits
7, 3, 2, 1, 0 (with and without the mode-specific bits 4, 5, 6, 8 set)."""

from __future__ import annotations

import pytest

from drives.cia402.statemachine import (
    Conditions,
    Options,
    PowerState,
    State,
    Stop,
    decode,
    state_from_statusword,
    statusword_state_bits,
    step,
)

S = State
# (from, mask, value, to, transitions): the profile's table, first match wins
TABLE = [
    (S.SWITCH_ON_DISABLED, 0x87, 0x06, S.READY_TO_SWITCH_ON, (2,)),
    (S.READY_TO_SWITCH_ON, 0x8F, 0x07, S.SWITCHED_ON, (3,)),
    (S.READY_TO_SWITCH_ON, 0x8F, 0x0F, S.OPERATION_ENABLED, (3, 4)),
    (S.READY_TO_SWITCH_ON, 0x82, 0x00, S.SWITCH_ON_DISABLED, (7,)),
    (S.READY_TO_SWITCH_ON, 0x86, 0x02, S.SWITCH_ON_DISABLED, (7,)),
    (S.SWITCHED_ON, 0x8F, 0x0F, S.OPERATION_ENABLED, (4,)),
    (S.SWITCHED_ON, 0x87, 0x06, S.READY_TO_SWITCH_ON, (6,)),
    (S.SWITCHED_ON, 0x82, 0x00, S.SWITCH_ON_DISABLED, (10,)),
    (S.SWITCHED_ON, 0x86, 0x02, S.SWITCH_ON_DISABLED, (10,)),
    (S.OPERATION_ENABLED, 0x8F, 0x07, S.SWITCHED_ON, (5,)),
    (S.OPERATION_ENABLED, 0x87, 0x06, S.READY_TO_SWITCH_ON, (8,)),
    (S.OPERATION_ENABLED, 0x82, 0x00, S.SWITCH_ON_DISABLED, (9,)),
    (S.OPERATION_ENABLED, 0x86, 0x02, S.QUICK_STOP_ACTIVE, (11,)),
    (S.QUICK_STOP_ACTIVE, 0x82, 0x00, S.SWITCH_ON_DISABLED, (12,)),
    (S.FAULT, 0x80, 0x80, S.SWITCH_ON_DISABLED, (15,)),
]
# option codes that make 5 and 8 immediate; QSA variants add transition 16
IMMEDIATE = Options(quick_stop=2, shutdown=0, disable_operation=0, fault_reaction=2)
STAY_QSA = Options(quick_stop=6, shutdown=0, disable_operation=0, fault_reaction=2)


def oracle(state: State, cw: int, opts: Options) -> tuple[State, tuple[int, ...]]:
    if state == S.NOT_READY_TO_SWITCH_ON:
        return S.SWITCH_ON_DISABLED, (1,)
    for frm, mask, value, to, tr in TABLE:
        if frm == state and cw & mask == value:
            return to, tr
    if state == S.QUICK_STOP_ACTIVE and opts.quick_stop >= 5 and cw & 0x8F == 0x0F:
        return S.OPERATION_ENABLED, (16,)
    return state, ()


def _cases():
    for st in S:
        for opts in (IMMEDIATE, STAY_QSA) if st == S.QUICK_STOP_ACTIVE else (IMMEDIATE,):
            for combo in range(32):
                bits = [(combo >> i) & 1 for i in range(5)]  # → bits 0, 1, 2, 3, 7
                cw = bits[0] | bits[1] << 1 | bits[2] << 2 | bits[3] << 3 | bits[4] << 7
                if combo % 2:
                    cw |= 0x0170  # mode-specific bits must not change the command
                tag = f"{st.name}-cw{cw:04X}-qs{opts.quick_stop}"
                yield pytest.param(st, cw, opts, id=tag)


@pytest.mark.parametrize(("state", "cw", "opts"), list(_cases()))
def test_every_state_every_command_word(state, cw, opts):
    ps = PowerState(state=state, last_controlword=0)
    if state == S.QUICK_STOP_ACTIVE:
        ps = PowerState(state=state, last_controlword=0x02)  # standstill reached, holding
    if state == S.FAULT_REACTION_ACTIVE:
        ps = PowerState(state=state, stop=Stop.QUICK_STOP)
    res = step(ps, cw, Conditions(), opts)
    want_state, want_tr = oracle(state, cw, opts)
    assert res.state == want_state
    assert res.transitions == want_tr
    assert res.power.last_controlword == cw


def test_decoder_ignores_mode_specific_bits():
    for cw in range(0x100):
        assert decode(cw) == decode(cw | 0xFF70 & ~0x80 | (cw & 0x80))


@pytest.mark.parametrize("state", list(S), ids=lambda s: s.name)
def test_statusword_bits_decode_back_to_the_state(state):
    sw = statusword_state_bits(state, voltage_present=True) | 0x0200
    assert state_from_statusword(sw) == state


@pytest.mark.parametrize("state", [s for s in S if s not in (S.FAULT_REACTION_ACTIVE, S.FAULT)])
def test_fault_from_every_state_starts_the_reaction(state):
    ps = PowerState(state=state)
    res = step(ps, None, Conditions(fault=True))
    if state == S.NOT_READY_TO_SWITCH_ON:
        assert res.state == S.SWITCH_ON_DISABLED  # the self-test finishes first
    elif state in (S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE):
        assert res.state == S.FAULT_REACTION_ACTIVE
        assert res.transitions == (13,)
        assert res.power.stop == Stop.QUICK_STOP  # 0x605E = 2
        done = step(res.power, None, Conditions(stopped=True))
        assert done.state == S.FAULT and done.transitions == (14,)
    else:
        assert res.state == S.FAULT and res.transitions == (13, 14)


def test_fault_reset_refused_while_the_cause_is_present():
    ps = PowerState(state=S.FAULT, last_controlword=0x00)
    assert step(ps, 0x80, Conditions(fault_present=True)).state == S.FAULT
    assert step(ps, 0x80, Conditions()).state == S.SWITCH_ON_DISABLED


def test_pending_disable_operation_ramp_and_cancel():
    opts = Options(disable_operation=1)
    oe = PowerState(state=S.OPERATION_ENABLED, last_controlword=0x0F)
    ramp = step(oe, 0x07, Conditions(), opts)
    assert ramp.state == S.OPERATION_ENABLED and ramp.power.pending == S.SWITCHED_ON
    assert ramp.power.stop == Stop.SLOW_DOWN
    assert step(ramp.power, None, Conditions(stopped=True), opts).state == S.SWITCHED_ON
    cancelled = step(ramp.power, 0x0F, Conditions(), opts)
    assert cancelled.state == S.OPERATION_ENABLED and cancelled.power.pending is None
