"""CiA 402 power drive state machine: pure (state, controlword, conditions) → (state, actions).

The transitions are numbered as in CiA 402 (IEC 61800-7-201) figure "state machine":

====  =====================================  ===========================================
 #    from → to                              trigger
====  =====================================  ===========================================
 0    start → NOT READY TO SWITCH ON         power-on / reset
 1    NOT READY → SWITCH ON DISABLED         self-test done (automatic)
 2    SWITCH ON DISABLED → READY             Shutdown
 3    READY → SWITCHED ON                    Switch on (refused without DC-link voltage)
 4    SWITCHED ON → OPERATION ENABLED        Enable operation
 5    OPERATION ENABLED → SWITCHED ON        Disable operation (0x605C)
 6    SWITCHED ON → READY                    Shutdown
 7    READY → SWITCH ON DISABLED             Disable voltage / Quick stop
 8    OPERATION ENABLED → READY              Shutdown (0x605B)
 9    OPERATION ENABLED → SWITCH ON DISABLED Disable voltage
 10   SWITCHED ON → SWITCH ON DISABLED       Disable voltage / Quick stop
 11   OPERATION ENABLED → QUICK STOP ACTIVE  Quick stop (0x605A)
 12   QUICK STOP ACTIVE → SWITCH ON DISABLED stop finished (0x605A 0..4) / Disable voltage
 13   any → FAULT REACTION ACTIVE            fault detected (0x605E)
 14   FAULT REACTION ACTIVE → FAULT          reaction finished
 15   FAULT → SWITCH ON DISABLED             Fault reset (0→1 edge of bit 7), cause gone
 16   QUICK STOP ACTIVE → OPERATION ENABLED  Enable operation (0x605A 5..8 only)
====  =====================================  ===========================================

Transitions 5 and 8 with option code 1 and transitions 11/13 with a ramp do not finish at
once: the machine keeps the source state with a `pending` destination (5, 8) or stays in
QUICK STOP ACTIVE / FAULT REACTION ACTIVE until the caller reports `stopped=True`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum


class State(IntEnum):
    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


STATE_NAMES = {
    State.NOT_READY_TO_SWITCH_ON: "NOT READY TO SWITCH ON",
    State.SWITCH_ON_DISABLED: "SWITCH ON DISABLED",
    State.READY_TO_SWITCH_ON: "READY TO SWITCH ON",
    State.SWITCHED_ON: "SWITCHED ON",
    State.OPERATION_ENABLED: "OPERATION ENABLED",
    State.QUICK_STOP_ACTIVE: "QUICK STOP ACTIVE",
    State.FAULT_REACTION_ACTIVE: "FAULT REACTION ACTIVE",
    State.FAULT: "FAULT",
}

# Statusword bits 0,1,2,3,5,6 per state (bit 4 voltage enabled is added separately).
STATE_BITS = {
    State.NOT_READY_TO_SWITCH_ON: 0x0000,
    State.SWITCH_ON_DISABLED: 0x0040,
    State.READY_TO_SWITCH_ON: 0x0021,
    State.SWITCHED_ON: 0x0023,
    State.OPERATION_ENABLED: 0x0027,
    State.QUICK_STOP_ACTIVE: 0x0007,
    State.FAULT_REACTION_ACTIVE: 0x000F,
    State.FAULT: 0x0008,
}

SW_READY_TO_SWITCH_ON = 1 << 0
SW_SWITCHED_ON = 1 << 1
SW_OPERATION_ENABLED = 1 << 2
SW_FAULT = 1 << 3
SW_VOLTAGE_ENABLED = 1 << 4
SW_QUICK_STOP = 1 << 5
SW_SWITCH_ON_DISABLED = 1 << 6
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_OMS12 = 1 << 12
SW_OMS13 = 1 << 13

CW_SWITCH_ON = 1 << 0
CW_ENABLE_VOLTAGE = 1 << 1
CW_QUICK_STOP = 1 << 2  # active low
CW_ENABLE_OPERATION = 1 << 3
CW_NEW_SET_POINT = 1 << 4  # PP; HM: start homing
CW_CHANGE_SET_IMMEDIATELY = 1 << 5
CW_RELATIVE = 1 << 6
CW_FAULT_RESET = 1 << 7
CW_HALT = 1 << 8
CW_CHANGE_ON_SET_POINT = 1 << 9


class Command(IntEnum):
    """Device control commands decoded from controlword bits 7, 3, 2, 1, 0."""

    DISABLE_VOLTAGE = 0  # 0xxx xx0x
    QUICK_STOP = 1  # 0xxx x01x
    SHUTDOWN = 2  # 0xxx x110
    SWITCH_ON = 3  # 0xxx 0111 (= Disable operation)
    ENABLE_OPERATION = 4  # 0xxx 1111 (= Switch on + Enable operation)
    FAULT_RESET = 5  # 1xxx xxxx


def decode(controlword: int) -> Command:
    """Decode the device control command (CiA 402 table, masks as in Beckhoff SSC)."""
    if controlword & CW_FAULT_RESET:
        return Command.FAULT_RESET
    if not controlword & CW_ENABLE_VOLTAGE:
        return Command.DISABLE_VOLTAGE
    if not controlword & CW_QUICK_STOP:
        return Command.QUICK_STOP
    if not controlword & CW_SWITCH_ON:
        return Command.SHUTDOWN
    if not controlword & CW_ENABLE_OPERATION:
        return Command.SWITCH_ON
    return Command.ENABLE_OPERATION


class Stop(IntEnum):
    """How to stop: the meaning of option codes 0x605A..0x605E."""

    COAST = 0  # disable drive function, motor free
    SLOW_DOWN = 1  # slow-down ramp 0x6084
    QUICK_STOP = 2  # quick-stop ramp 0x6085
    CURRENT_LIMIT = 3
    VOLTAGE_LIMIT = 4


@dataclass(frozen=True, slots=True)
class Options:
    """Option codes (CiA 402 §6.5): quick stop, shutdown, disable operation, fault reaction."""

    quick_stop: int = 2  # 0x605A: 0..8
    shutdown: int = 0  # 0x605B: 0..1
    disable_operation: int = 1  # 0x605C: 0..1
    fault_reaction: int = 2  # 0x605E: 0..4


@dataclass(frozen=True, slots=True)
class Conditions:
    """What the drive reports to the machine at this evaluation."""

    fault: bool = False  # a new fault was detected (transition 13)
    fault_present: bool = False  # the cause of the latched fault is still there (blocks 15)
    stopped: bool = False  # the running stop (ramp, reaction) has reached standstill
    voltage_present: bool = True  # DC link charged: switch on (3) is permitted
    forced_coast: bool = False  # the fault forbids a ramp (encoder lost, power stage trip)


@dataclass(frozen=True, slots=True)
class PowerState:
    state: State = State.NOT_READY_TO_SWITCH_ON
    pending: State | None = None  # destination of a transition 5/8 waiting for standstill
    last_controlword: int = 0
    stop: Stop | None = None  # the stop in progress (QSA ramp, 5/8 ramp, fault reaction)


@dataclass(frozen=True, slots=True)
class Result:
    power: PowerState
    transitions: tuple[int, ...] = ()  # CiA 402 transition numbers taken, in order

    @property
    def state(self) -> State:
        return self.power.state


def _quick_stop_kind(code: int) -> Stop:
    return Stop((code - 4) if code > 4 else code)


def step(
    ps: PowerState,
    controlword: int | None,
    cond: Conditions = Conditions(),  # noqa: B008 - frozen, shared default is safe
    opts: Options = Options(),  # noqa: B008
) -> Result:
    """One evaluation of the state machine.

    `controlword` None means "no new controlword" (automatic transitions only). A controlword
    that is not a valid command in the present state causes no transition.
    """
    s = ps.state
    S = State
    prev = ps.last_controlword
    cw = prev if controlword is None else controlword
    ps = replace(ps, last_controlword=cw)
    taken: list[int] = []

    # Automatic transitions first.
    if s == S.NOT_READY_TO_SWITCH_ON:
        return Result(replace(ps, state=S.SWITCH_ON_DISABLED, pending=None, stop=None), (1,))
    if cond.fault and s not in (S.FAULT_REACTION_ACTIVE, S.FAULT):
        energized = s in (S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE)
        kind = Stop(opts.fault_reaction) if energized and not cond.forced_coast else Stop.COAST
        ps = replace(ps, state=S.FAULT_REACTION_ACTIVE, pending=None, stop=kind)
        taken.append(13)
        if kind == Stop.COAST or not energized:
            # Nothing to ramp: the reaction is complete at once (transition 14).
            ps = replace(ps, state=S.FAULT, stop=None)
            taken.append(14)
        return Result(ps, tuple(taken))
    if s == S.FAULT_REACTION_ACTIVE:
        if cond.stopped:
            return Result(replace(ps, state=S.FAULT, stop=None), (14,))
        return Result(ps)
    if s == S.FAULT:
        edge = (cw & CW_FAULT_RESET) and not (prev & CW_FAULT_RESET)
        if controlword is not None and edge and not cond.fault_present:
            return Result(replace(ps, state=S.SWITCH_ON_DISABLED, stop=None), (15,))
        return Result(ps)

    # Completion of running stops: pending 5/8 ramps and the quick stop (12).
    if cond.stopped:
        if s == S.OPERATION_ENABLED and ps.pending is not None:
            s = ps.pending
            ps = replace(ps, state=s, pending=None, stop=None)
        elif s == S.QUICK_STOP_ACTIVE and opts.quick_stop <= 4:
            s = S.SWITCH_ON_DISABLED
            ps = replace(ps, state=s, stop=None)
            taken.append(12)
        elif s == S.QUICK_STOP_ACTIVE:
            ps = replace(ps, stop=None)  # options 5..8: hold in QUICK STOP ACTIVE
    if controlword is None:
        return Result(ps, tuple(taken))

    c = decode(cw)
    C = Command
    nxt = s
    stop = ps.stop
    pending = ps.pending
    done: list[int] = []
    if s == S.SWITCH_ON_DISABLED:
        if c == C.SHUTDOWN:
            nxt, done = S.READY_TO_SWITCH_ON, [2]
    elif s == S.READY_TO_SWITCH_ON:
        if c in (C.DISABLE_VOLTAGE, C.QUICK_STOP):
            nxt, done = S.SWITCH_ON_DISABLED, [7]
        elif c == C.SWITCH_ON and cond.voltage_present:
            nxt, done = S.SWITCHED_ON, [3]
        elif c == C.ENABLE_OPERATION and cond.voltage_present:
            nxt, done = S.OPERATION_ENABLED, [3, 4]
    elif s == S.SWITCHED_ON:
        if c in (C.DISABLE_VOLTAGE, C.QUICK_STOP):
            nxt, done = S.SWITCH_ON_DISABLED, [10]
        elif c == C.SHUTDOWN:
            nxt, done = S.READY_TO_SWITCH_ON, [6]
        elif c == C.ENABLE_OPERATION:
            nxt, done = S.OPERATION_ENABLED, [4]
    elif s == S.OPERATION_ENABLED:
        if c == C.DISABLE_VOLTAGE:
            nxt, done, pending, stop = S.SWITCH_ON_DISABLED, [9], None, None
        elif c == C.QUICK_STOP:
            kind = _quick_stop_kind(opts.quick_stop)
            nxt, done, pending, stop = S.QUICK_STOP_ACTIVE, [11], None, kind
        elif c == C.SHUTDOWN:
            done = [8]
            if opts.shutdown == 1:
                pending, stop = S.READY_TO_SWITCH_ON, Stop.SLOW_DOWN
            else:
                nxt, pending, stop = S.READY_TO_SWITCH_ON, None, None
        elif c == C.SWITCH_ON:
            done = [5]
            if opts.disable_operation == 1:
                pending, stop = S.SWITCHED_ON, Stop.SLOW_DOWN
            else:
                nxt, pending, stop = S.SWITCHED_ON, None, None
        elif c == C.ENABLE_OPERATION and pending is not None:
            pending, stop = None, None  # a renewed enable cancels a 5/8 ramp
    elif s == S.QUICK_STOP_ACTIVE:
        if c == C.DISABLE_VOLTAGE:
            nxt, done, stop = S.SWITCH_ON_DISABLED, [12], None
        elif c == C.ENABLE_OPERATION and opts.quick_stop >= 5:
            nxt, done, stop = S.OPERATION_ENABLED, [16], None
    ps = replace(ps, state=nxt, pending=pending, stop=stop)
    # A quick stop always shows QUICK STOP ACTIVE first, even with option 0 (coast): the
    # caller reports `stopped` at its next evaluation, so transition 12 follows one cycle later.
    return Result(ps, tuple(taken + done))


def statusword_state_bits(state: State, voltage_present: bool) -> int:
    """Bits 0..6 of 0x6041 for a state (bit 4 = high voltage applied to the power stage)."""
    return STATE_BITS[state] | (SW_VOLTAGE_ENABLED if voltage_present else 0)


def state_from_statusword(sw: int) -> State | None:
    """Decode a statusword with the CiA 402 masks (0x4F / 0x6F)."""
    for st, bits in STATE_BITS.items():
        mask = 0x4F if st in _MASK_4F else 0x6F
        if sw & mask == bits & mask:
            return st
    return None


_MASK_4F = (
    State.NOT_READY_TO_SWITCH_ON,
    State.SWITCH_ON_DISABLED,
    State.FAULT_REACTION_ACTIVE,
    State.FAULT,
)
