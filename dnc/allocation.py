"""The allocation state machine: one part of a job on one machine, from dispatch to its end.

Pure: an allocation and one look at its machine in, the next state out (no I/O, no clock).
The scheduler tick (`dnc.scheduler.decide`) steps every active allocation once per tick.

    dispatched --(machine seen in cycle on the program)--> running
    dispatched | running --(part counter advanced after the start)--> completed   (1 part)
    dispatched | running --(the run ended or can no longer start without a part)--> interrupted
    interrupted --(the job's next allocation takes the part)--> rerouted
    interrupted --(the job is closed: nothing to reroute to)--> failed

`completed`, `rerouted` and `failed` are final. A part is counted only from the machine's own
part counter (M30/M2 counted by the NC), by the one step that leaves the active states, so it
is counted exactly once. What ends a run without a part: a reset, an alarm that stopped the
cycle, an emergency stop, an operator's program change, a restart of the machine's control
(its part counter goes back) and contact lost for longer than the cell's time-out. Alarms and
warnings while the machine keeps cutting (`lube_level_low`) do not stop the part: they are
noted on the allocation.

The dispatch that carries the program decides what an event means. While the program has not
been started (`pending`, `transferring`, `verifying`) interrupting also cancels the dispatch,
so the transfer worker can never start it afterwards. While the worker is pressing cycle
start (`starting`) nothing interrupts: the start's outcome is awaited, except that a part of
our program counted past the counter read just before the start completes the allocation (the
start was taken; its worker may have died with its host). From `started` (or a
start that failed: the machine may still have taken it) the machine's state is the truth.
"""

from __future__ import annotations

from dataclasses import dataclass

DISPATCHED, RUNNING, COMPLETED, INTERRUPTED, REROUTED, FAILED = (
    "dispatched",
    "running",
    "completed",
    "interrupted",
    "rerouted",
    "failed",
)
ACTIVE = (DISPATCHED, RUNNING)
FINAL = (COMPLETED, REROUTED, FAILED)
STATES = (*ACTIVE, INTERRUPTED, *FINAL)

# The dispatch's progress as the allocation needs it.
NOT_STARTED = "not_started"  # pending, transferring, verifying: can still be called off
STARTING = "starting"  # the worker is pressing cycle start: wait for its outcome
STARTED = "started"  # cycle start seen taken
START_FAILED = "start_failed"  # failed while cycle start was pressed: it may have run
# failed without any cycle start (the transfer failed, or the NC refused the start): no part
# the machine counts afterwards is this allocation's
NEVER_STARTED = "never_started"
DISPATCH_PHASES = (NOT_STARTED, STARTING, STARTED, START_FAILED, NEVER_STARTED)

DEFAULT_LOST_CONTACT_S = 30.0


@dataclass(frozen=True, slots=True)
class Look:
    """One look at the allocation's machine, from the monitoring model."""

    connected: bool = True
    offline_s: float = 0.0  # how long contact has been lost (0 while connected)
    in_cycle: bool = False  # executing a program (ACTIVE, FEED_HOLD, single block, M0/M1)
    program: str | None = None  # active or selected program (O1234); None = not reported
    part_count: int = 0
    alarm: str | None = None  # a FAULT-level alarm active on the machine (its text, or "")
    estop: bool = False
    warnings: tuple[str, ...] = ()  # conditions below FAULT (recorded only)


@dataclass(frozen=True, slots=True)
class Alloc:
    state: str
    machine: str
    # the machine's part counter when the allocation was made, and from its confirmed start
    # on, the counter the machine showed just before cycle start was pressed
    parts_at_start: int
    dispatch: str = NOT_STARTED  # one of DISPATCH_PHASES
    program: str | None = None  # the program this allocation runs (O1234)
    job_open: bool = True  # False once the job is cancelled


@dataclass(frozen=True, slots=True)
class Step:
    state: str
    parts: int = 0  # parts this step counts for the job (0 or 1)
    reason: str = ""
    cancel_dispatch: bool = False  # the program must never be started: call the dispatch off
    note: str = ""  # recorded on the allocation, not interrupting


def step(a: Alloc, look: Look, *, lost_contact_s: float = DEFAULT_LOST_CONTACT_S) -> Step:
    """The next state of an active allocation after one look at its machine."""
    if a.state not in ACTIVE:
        return Step(a.state)
    m = a.machine
    not_started = a.dispatch == NOT_STARTED

    def interrupt(reason: str) -> Step:
        if a.dispatch == STARTING:
            # the worker may be pressing cycle start this moment: its outcome decides
            return Step(a.state, note=f"{reason}; waiting for the cycle start under way")
        return Step(INTERRUPTED, reason=reason, cancel_dispatch=not_started)

    if not look.connected:
        if look.offline_s >= lost_contact_s:
            return interrupt(
                f"contact with {m} lost for {look.offline_s:.0f} s "
                f"(time-out {lost_contact_s:g} s): machine taken as lost"
            )
        # Lost contact is not yet a failure: the machine keeps running the program in its
        # memory and its part counter is read again when it answers.
        return Step(a.state)
    if look.part_count < a.parts_at_start:
        return interrupt(
            f"part counter of {m} went back from {a.parts_at_start} to {look.part_count}: "
            "the machine's control was restarted"
        )
    if look.part_count > a.parts_at_start and (
        a.dispatch in (STARTED, START_FAILED) or (a.dispatch == STARTING and _our_program(a, look))
    ):
        # During `starting` the baseline is the counter read just before the start was
        # claimed, so a part counted past it with our program selected is the start taken.
        # Waiting for the start's outcome instead would wait on a worker that may be gone (a
        # host killed pressing cycle start leaves `starting` until the next host recovers).
        extra = look.part_count - a.parts_at_start - 1
        return Step(
            COMPLETED,
            parts=1,
            reason=f"part counter of {m} advanced to {look.part_count}",
            note=f"{extra} more part(s) counted by {m} belong to no allocation" if extra else "",
        )
    # Parts counted before the start are not this allocation's (an operator's own part):
    # the worker writes the counter it saw just before pressing cycle start as the new
    # `parts_at_start` when the start is confirmed, so they are never mistaken for it.
    if not a.job_open and not_started:
        return interrupt("job cancelled before its program was started")
    ours = look.program is None or a.program is None or look.program == a.program
    if look.in_cycle:
        if not ours:
            if not_started:
                return Step(a.state)  # something else still running: our start waits
            return interrupt(f"operator started {look.program} on {m} in place of {a.program}")
        if not_started:
            # our program is selected from an earlier part but not yet loaded again: wait
            return Step(a.state)
        alarm = (
            [f"alarm while cutting on: {look.alarm or 'FAULT'}"] if look.alarm is not None else []
        )
        notes = alarm + list(look.warnings)
        return Step(RUNNING, note="; ".join(notes))
    # Not in cycle, counter unchanged.
    if look.estop:
        why = f"emergency stop on {m}"
    elif look.alarm is not None:
        why = f"machine {m} raised an alarm" + (f": {look.alarm}" if look.alarm else "")
    elif not_started or a.dispatch == STARTING:
        return Step(a.state, note="; ".join(look.warnings))
    elif a.dispatch == NEVER_STARTED or (a.dispatch == START_FAILED and a.state == DISPATCHED):
        why = f"dispatch to {m} failed"
    elif not ours and look.program:
        why = f"operator changed the program on {m} to {look.program}"
    else:
        # READY with the program gone from selection is what a restarted control shows
        why = f"cycle on {m} ended without a part (reset, abort or restart at the machine)"
    return interrupt(why)


def _our_program(a: Alloc, look: Look) -> bool:
    """The machine reports our program as its own (not merely "not reported")."""
    return a.program is not None and look.program == a.program


def settle(a: Alloc, *, rerouted_to: int | None) -> Step:
    """An interrupted allocation's end: rerouted when its part went to a new allocation,
    failed when the job closed first (cancelled: nothing to reroute to)."""
    if a.state != INTERRUPTED:
        return Step(a.state)
    if rerouted_to is not None:
        return Step(REROUTED, reason=f"part rerouted to allocation {rerouted_to}")
    if not a.job_open:
        return Step(FAILED, reason="job closed: part not rerouted")
    return Step(INTERRUPTED)


def dispatch_phase(dispatch_state: str | None, error: str | None = None) -> str:
    """The dispatch's state (dnc.dispatch / transfer_worker) as an allocation sees it.

    A failed dispatch may have started its cycle only if it failed in the start step
    (`start:` errors: the host died pressing cycle start, or the start was not seen in
    time); a transfer that failed, or a start the NC refused (`start refused:`), never ran.
    """
    if dispatch_state in (None, "pending", "transferring", "verifying"):
        return NOT_STARTED
    if dispatch_state == "starting":
        return STARTING
    if dispatch_state == "done":
        return STARTED
    if dispatch_state == "failed" and error is not None and not error.startswith("start:"):
        return NEVER_STARTED
    return START_FAILED
