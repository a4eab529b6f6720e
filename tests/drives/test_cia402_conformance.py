"""CiA 402 power state machine conformance table, run through the Drive402 application.

Each case: bring a drive into a state, apply one stimulus (a controlword, a fault, an option
code variant), and check the state right away, the state after one 2 ms IPO cycle, the
statusword, 0x603F and the EMCY requests queued.
"""

from __future__ import annotations

import pytest

from drives.application import EmcyRequest
from drives.cia402 import Drive402, State

S = State
T = 0.002
BASE = 0x0210  # bit 4 voltage enabled + bit 9 remote (mode 0: no mode-specific bits)
SW = {
    S.NOT_READY_TO_SWITCH_ON: 0x0000,
    S.SWITCH_ON_DISABLED: 0x0040,
    S.READY_TO_SWITCH_ON: 0x0021,
    S.SWITCHED_ON: 0x0023,
    S.OPERATION_ENABLED: 0x0027,
    S.QUICK_STOP_ACTIVE: 0x0007,
    S.FAULT_REACTION_ACTIVE: 0x000F,
    S.FAULT: 0x0008,
}


def make(state: State, *, reset_bit: bool = False, **objects: int) -> Drive402:
    """A drive at standstill in `state`; reset_bit leaves controlword bit 7 set (held)."""
    od = {0x6060: 0, 0x605A: 6, 0x6007: 1}
    od.update({int(k[1:], 16): v for k, v in objects.items()})
    d = Drive402(objects=od)
    if state == S.NOT_READY_TO_SWITCH_ON:
        return d
    d.advance(T)
    path = {
        S.SWITCH_ON_DISABLED: [],
        S.READY_TO_SWITCH_ON: [0x06],
        S.SWITCHED_ON: [0x06, 0x07],
        S.OPERATION_ENABLED: [0x06, 0x0F],
        S.QUICK_STOP_ACTIVE: [0x06, 0x0F, 0x02],
        S.FAULT_REACTION_ACTIVE: [0x06, 0x0F],
        S.FAULT: [0x06, 0x0F],
    }[state]
    for cw in path:
        d.write_object(0x6040, 0, cw)
        d.advance(T)
    if state in (S.FAULT_REACTION_ACTIVE, S.FAULT):
        if reset_bit:
            d.write_object(0x6040, 0, 0x80)
        d.on_communication_fault(0x8130)
        if state == S.FAULT:
            d.advance(T)
    elif reset_bit:
        d.write_object(0x6040, 0, 0x80)
    assert d.state == state
    d.take_emcy()
    return d


# (name, controlword, reset bit held before)
COMMANDS = [
    ("shutdown", 0x0006, False),
    ("shutdown+bit3", 0x000E, False),
    ("switch_on/disable_operation", 0x0007, False),
    ("switch_on+enable/enable_operation", 0x000F, False),
    ("disable_voltage", 0x0000, False),
    ("disable_voltage+bits0,2,3", 0x000D, False),
    ("quick_stop", 0x0002, False),
    ("quick_stop+bits0,3", 0x000B, False),
    ("fault_reset_edge", 0x0080, False),
    ("fault_reset_edge+enable", 0x008F, False),
    ("fault_reset_held", 0x0080, True),
]

NR, SOD, RTSO, SO, OE, QSA, FRA, F = (
    S.NOT_READY_TO_SWITCH_ON,
    S.SWITCH_ON_DISABLED,
    S.READY_TO_SWITCH_ON,
    S.SWITCHED_ON,
    S.OPERATION_ENABLED,
    S.QUICK_STOP_ACTIVE,
    S.FAULT_REACTION_ACTIVE,
    S.FAULT,
)

# state -> command name -> (state right after the write, state after one IPO cycle)
EXPECT: dict[State, dict[str, tuple[State, State]]] = {
    NR: {name: (SOD, SOD) for name, _, _ in COMMANDS},
    SOD: {
        "shutdown": (RTSO, RTSO),
        "shutdown+bit3": (RTSO, RTSO),
    },
    RTSO: {
        "switch_on/disable_operation": (SO, SO),
        "switch_on+enable/enable_operation": (OE, OE),
        "disable_voltage": (SOD, SOD),
        "disable_voltage+bits0,2,3": (SOD, SOD),
        "quick_stop": (SOD, SOD),
        "quick_stop+bits0,3": (SOD, SOD),
    },
    SO: {
        "shutdown": (RTSO, RTSO),
        "shutdown+bit3": (RTSO, RTSO),
        "switch_on+enable/enable_operation": (OE, OE),
        "disable_voltage": (SOD, SOD),
        "disable_voltage+bits0,2,3": (SOD, SOD),
        "quick_stop": (SOD, SOD),
        "quick_stop+bits0,3": (SOD, SOD),
    },
    OE: {
        "shutdown": (RTSO, RTSO),  # 0x605B = 0
        "shutdown+bit3": (RTSO, RTSO),
        "switch_on/disable_operation": (OE, SO),  # 0x605C = 1: slow-down ramp first
        "disable_voltage": (SOD, SOD),
        "disable_voltage+bits0,2,3": (SOD, SOD),
        "quick_stop": (QSA, QSA),  # 0x605A = 6: stay in QSA
        "quick_stop+bits0,3": (QSA, QSA),
    },
    QSA: {
        "switch_on+enable/enable_operation": (OE, OE),  # transition 16 (option 5..8)
        "disable_voltage": (SOD, SOD),
        "disable_voltage+bits0,2,3": (SOD, SOD),
    },
    FRA: {name: (FRA, F) for name, _, _ in COMMANDS},
    F: {
        "fault_reset_edge": (SOD, SOD),
        "fault_reset_edge+enable": (SOD, SOD),
    },
}


def _cases():
    for st in S:
        for name, cw, held in COMMANDS:
            now, later = EXPECT[st].get(name, (st, st))
            yield pytest.param(st, cw, held, now, later, id=f"{st.name}-{name}")


def _statusword(state: State, stopped_qsa: bool) -> int:
    sw = SW[state] | BASE
    if state == S.QUICK_STOP_ACTIVE and stopped_qsa:
        sw |= 0x0400  # target reached: the quick stop has come to standstill
    return sw


@pytest.mark.parametrize(("start", "cw", "held", "now", "later"), list(_cases()))
def test_controlword_table(start, cw, held, now, later):
    d = make(start, reset_bit=held)
    fault_before = d.error_code
    d.write_object(0x6040, 0, cw)
    d.on_sync()
    assert d.state == now
    fresh_qsa = start != S.QUICK_STOP_ACTIVE
    assert d.read_object(0x6041, 0) == _statusword(now, not fresh_qsa)
    emcy = d.take_emcy()
    if start == S.FAULT and now == S.SWITCH_ON_DISABLED:
        assert emcy == [EmcyRequest(0x0000, 0)]
        assert d.read_object(0x603F, 0) == 0
    else:
        assert emcy == []
        assert d.read_object(0x603F, 0) == fault_before
    d.advance(T)
    assert d.state == later
    assert d.read_object(0x6041, 0) & 0x6F == SW[later] & 0x6F


FAULT_FROM = [NR, SOD, RTSO, SO, OE, QSA, FRA, F]


@pytest.mark.parametrize("start", FAULT_FROM, ids=[s.name for s in FAULT_FROM])
def test_fault_transition_13_encoder_from_every_state(start):
    d = make(start)
    latched_before = d.error_code
    d.inject("encoder_break")
    d.advance(T)
    if start in (FRA, F):
        assert d.state == F
        assert d.error_code == latched_before == 0x8130  # first fault stays in 0x603F
        assert d.take_emcy() == []
    else:
        assert d.state == F  # forced coast: 13 and 14 at once
        assert d.read_object(0x603F, 0) == 0x7305
        assert d.take_emcy() == [EmcyRequest(0x7305, 0x21)]
        assert d.read_object(0x6041, 0) == 0x0008 | BASE
    # the cause is still present: a reset edge is refused
    d.write_object(0x6040, 0, 0x00)
    d.write_object(0x6040, 0, 0x80)
    assert d.state == F
    d.clear_injection("encoder_break")
    d.write_object(0x6040, 0, 0x00)
    d.write_object(0x6040, 0, 0x80)
    assert d.state == SOD
    assert d.take_emcy()[-1] == EmcyRequest(0x0000, 0)


@pytest.mark.parametrize("start", [SOD, RTSO, SO, OE, QSA], ids=lambda s: s.name)
def test_fault_transition_13_communication_fault(start):
    d = make(start)
    d.on_communication_fault(0x8130)
    energized = start in (OE, QSA)
    assert d.state == (FRA if energized else F)
    assert d.read_object(0x603F, 0) == 0x8130
    assert d.error_register == 0x11
    assert d.take_emcy() == []  # the CiA 301 layer sends the 0x8130 EMCY itself
    d.advance(T)
    assert d.state == F


@pytest.mark.parametrize("option", range(9))
def test_quick_stop_option_code_605A(option):
    d = make(OE, x605A=option)
    d.write_object(0x6040, 0, 0x02)
    assert d.state == QSA
    assert d.read_object(0x6041, 0) == 0x0007 | BASE
    d.advance(T)
    if option <= 4:
        assert d.state == SOD
        d.write_object(0x6040, 0, 0x0F)
        assert d.state == SOD  # enable from SOD is not a valid command
    else:
        assert d.state == QSA
        assert d.read_object(0x6041, 0) == 0x0007 | BASE | 0x0400
        d.write_object(0x6040, 0, 0x0F)
        assert d.state == OE  # transition 16
    assert d.take_emcy() == []


@pytest.mark.parametrize("option", range(5))
def test_fault_reaction_option_code_605E(option):
    d = make(OE, x605E=option)
    d.on_communication_fault(0x8130)
    assert d.state == (F if option == 0 else FRA)
    d.advance(T)
    assert d.state == F
    assert d.read_object(0x6041, 0) == 0x0008 | BASE


@pytest.mark.parametrize(("option", "now"), [(0, RTSO), (1, OE)])
def test_shutdown_option_code_605B(option, now):
    d = make(OE, x605B=option)
    d.write_object(0x6040, 0, 0x06)
    assert d.state == now
    d.advance(T)
    assert d.state == RTSO


@pytest.mark.parametrize(("option", "now"), [(0, SO), (1, OE)])
def test_disable_operation_option_code_605C(option, now):
    d = make(OE, x605C=option)
    d.write_object(0x6040, 0, 0x07)
    assert d.state == now
    d.advance(T)
    assert d.state == SO


@pytest.mark.parametrize(
    ("option", "now", "later"), [(0, OE, OE), (1, FRA, F), (2, SOD, SOD), (3, QSA, SOD)]
)
def test_abort_connection_option_code_6007(option, now, later):
    d = make(OE, x6007=option, x605A=2)
    d.on_communication_fault(0x8130)
    assert d.state == now
    assert d.read_object(0x603F, 0) == (0x8130 if option == 1 else 0)
    d.advance(T)
    assert d.state == later
    # the master's enable word held in the RPDO does not re-enable from SOD
    d.write_object(0x6040, 0, 0x0F)
    assert d.state == (OE if option == 0 else later)


@pytest.mark.parametrize("cw", [0x07, 0x0F])
def test_switch_on_refused_without_dc_link_voltage(cw):
    d = make(RTSO)
    d.inject("supply_loss")
    d.plant.vdc = 100.0  # link discharged
    d.write_object(0x6040, 0, cw)
    assert d.state == RTSO
    assert d.read_object(0x6041, 0) == 0x0021 | 0x0200  # bit 4 voltage enabled clear


def test_fault_reset_requires_edge_after_bit_held_through_fault():
    d = make(F, reset_bit=True)
    d.write_object(0x6040, 0, 0x80)
    assert d.state == F
    d.write_object(0x6040, 0, 0x00)
    d.write_object(0x6040, 0, 0x80)
    assert d.state == SOD


def test_full_enable_sequence_like_basenode402():
    d = make(SOD)
    seen = []
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        seen.append(d.read_object(0x6041, 0))
        d.advance(T)
    assert seen == [0x0231, 0x0233, 0x0237]


@pytest.mark.parametrize("option", [1, 2, 3, 4])
def test_halt_option_code_605D_stops_without_leaving_operation_enabled(option):
    d = make(OE, x605D=option, x6060=3)
    d.write_object(0x60FF, 0, 50_000)  # profile velocity, 50 mm/s
    for _ in range(100):
        d.advance(T)
    d.write_object(0x6040, 0, 0x010F)  # halt
    for _ in range(100):
        d.advance(T)
    assert d.state == OE
    sw = d.read_object(0x6041, 0)
    assert sw & 0x6F == 0x27
    assert sw & 0x0400  # target reached: halted at standstill
    assert abs(d.read_object(0x606C, 0)) < 1_000
    assert d.take_emcy() == []
    d.write_object(0x6040, 0, 0x000F)  # release: PV runs up again
    for _ in range(100):
        d.advance(T)
    assert d.read_object(0x606C, 0) == pytest.approx(50_000, rel=0.02)


@pytest.mark.parametrize("state", list(S), ids=lambda s: s.name)
def test_statusword_and_0x603F_of_each_state_at_rest(state):
    d = make(state)
    expected = SW[state] | BASE | (0x0400 if state == S.QUICK_STOP_ACTIVE else 0)
    assert d.read_object(0x6041, 0) == expected
    assert d.read_object(0x603F, 0) == (0x8130 if state in (FRA, F) else 0)
    assert d.error_register == (0x11 if state in (FRA, F) else 0)


def test_repeated_switch_on_succeeds_once_the_dc_link_is_charged():
    d = make(RTSO)
    d.inject("supply_loss")
    d.plant.vdc = 100.0
    d.write_object(0x6040, 0, 0x07)
    assert d.state == RTSO
    d.clear_injection("supply_loss")
    d.advance(T)  # the rectifier recharges the link
    d.write_object(0x6040, 0, 0x07)  # the master repeats the same word (cyclic RPDO)
    assert d.state == SO
