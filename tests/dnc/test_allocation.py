"""The allocation state machine (dnc/allocation.py), one table row per state x machine event."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from dnc.allocation import (
    ACTIVE,
    COMPLETED,
    DISPATCH_PHASES,
    DISPATCHED,
    FAILED,
    FINAL,
    INTERRUPTED,
    NEVER_STARTED,
    NOT_STARTED,
    REROUTED,
    RUNNING,
    START_FAILED,
    STARTED,
    STARTING,
    Alloc,
    Look,
    dispatch_phase,
    settle,
    step,
)

P = "O1001"
AT = 5  # the machine's part counter when the allocation was made


def alloc(state=RUNNING, dispatch=STARTED, job_open=True, program=P):
    return Alloc(state, "mill1", AT, dispatch, program, job_open)


def look(**kw):
    base = dict(connected=True, in_cycle=False, program=P, part_count=AT)
    return Look(**(base | kw))


CUTTING = dict(in_cycle=True)
# (name, allocation, look, next state, parts counted, dispatch called off, reason contains)
# fmt: off
TABLE = [
    # -- cycle end with the part counted by the machine (M30/M2)
    ("cycle end", alloc(), look(part_count=AT + 1), COMPLETED, 1, False, "advanced to 6"),
    ("cycle end seen first", alloc(DISPATCHED), look(part_count=AT + 1), COMPLETED, 1, False, ""),
    ("cycle end after failed start", alloc(DISPATCHED, START_FAILED), look(part_count=6), COMPLETED, 1, False, ""),
    ("two parts counted: one is ours", alloc(), look(part_count=AT + 2), COMPLETED, 1, False, ""),
    ("part counted during the start (host died pressing it)", alloc(DISPATCHED, STARTING), look(part_count=6), COMPLETED, 1, False, "advanced to 6"),
    ("another program's part during the start: wait", alloc(DISPATCHED, STARTING), look(part_count=6, program="O9"), DISPATCHED, 0, False, ""),
    ("counter moved during start, program not reported: wait", alloc(DISPATCHED, STARTING), look(part_count=6, program=None), DISPATCHED, 0, False, ""),
    ("operator's part before our start", alloc(DISPATCHED, NOT_STARTED), look(part_count=6), DISPATCHED, 0, False, ""),
    # -- running on
    ("seen cutting", alloc(DISPATCHED), look(**CUTTING), RUNNING, 0, False, ""),
    ("cutting on", alloc(), look(**CUTTING), RUNNING, 0, False, ""),
    ("failed start was taken", alloc(DISPATCHED, START_FAILED), look(**CUTTING), RUNNING, 0, False, ""),
    ("FAULT while cutting on (lube_level_low)", alloc(), look(alarm="plc_cond FAULT lube_level_low", **CUTTING), RUNNING, 0, False, ""),
    ("warning while cutting", alloc(), look(warnings=("servo WARNING hot",), **CUTTING), RUNNING, 0, False, ""),
    ("feed hold with alarm is still the cycle", alloc(), look(alarm="x", **CUTTING), RUNNING, 0, False, ""),
    ("waiting for transfer", alloc(DISPATCHED, NOT_STARTED), look(), DISPATCHED, 0, False, ""),
    ("another program ends before our start", alloc(DISPATCHED, NOT_STARTED), look(program="O2", **CUTTING), DISPATCHED, 0, False, ""),
    ("our program still cutting an earlier part", alloc(DISPATCHED, NOT_STARTED), look(**CUTTING), DISPATCHED, 0, False, ""),
    ("machine reports no program while cutting", alloc(), look(program=None, **CUTTING), RUNNING, 0, False, ""),
    ("the start under way", alloc(DISPATCHED, STARTING), look(), DISPATCHED, 0, False, ""),
    # -- reset of a cutting machine: READY, idle, no part
    ("reset", alloc(), look(), INTERRUPTED, 0, False, "ended without a part"),
    ("reset before a tick saw the cycle", alloc(DISPATCHED, STARTED), look(), INTERRUPTED, 0, False, "ended without a part"),
    # -- alarms of any level
    ("stopping alarm", alloc(), look(alarm="servo FAULT 2101 following error"), INTERRUPTED, 0, False, "raised an alarm: servo FAULT"),
    ("alarm without text", alloc(), look(alarm=""), INTERRUPTED, 0, False, "machine mill1 raised an alarm"),
    ("alarm before the start", alloc(DISPATCHED, NOT_STARTED), look(alarm="x"), INTERRUPTED, 0, True, "raised an alarm"),
    ("alarm while the start is under way", alloc(DISPATCHED, STARTING), look(alarm="x"), DISPATCHED, 0, False, ""),
    ("warning on an idle machine", alloc(DISPATCHED, NOT_STARTED), look(warnings=("w",)), DISPATCHED, 0, False, ""),
    ("warning after the cycle stopped", alloc(), look(warnings=("w",)), INTERRUPTED, 0, False, "without a part"),
    # -- emergency stop
    ("E-stop", alloc(), look(estop=True), INTERRUPTED, 0, False, "emergency stop on mill1"),
    ("E-stop before the start", alloc(DISPATCHED, NOT_STARTED), look(estop=True), INTERRUPTED, 0, True, "emergency stop"),
    # -- program change by an operator
    ("operator started another program", alloc(), look(program="O2002", **CUTTING), INTERRUPTED, 0, False, "operator started O2002"),
    ("operator selected another program", alloc(), look(program="O2002"), INTERRUPTED, 0, False, "changed the program on mill1 to O2002"),
    # -- restart of the machine's control: its counter starts again
    ("control restarted", alloc(), look(part_count=0, program=""), INTERRUPTED, 0, False, "went back from 5 to 0"),
    ("control restarted before the start", alloc(DISPATCHED, NOT_STARTED), look(part_count=0), INTERRUPTED, 0, True, "restarted"),
    ("control restarted during the start", alloc(DISPATCHED, STARTING), look(part_count=0), DISPATCHED, 0, False, ""),
    # -- contact lost
    ("contact lost briefly", alloc(), look(connected=False, offline_s=29.0), RUNNING, 0, False, ""),
    ("contact lost past the time-out", alloc(), look(connected=False, offline_s=30.0), INTERRUPTED, 0, False, "lost for 30 s"),
    ("lost before the start", alloc(DISPATCHED, NOT_STARTED), look(connected=False, offline_s=99), INTERRUPTED, 0, True, "lost"),
    ("back with its part", alloc(), look(part_count=AT + 1), COMPLETED, 1, False, ""),
    # -- the dispatch
    ("dispatch failed", alloc(DISPATCHED, START_FAILED), look(), INTERRUPTED, 0, False, "dispatch to mill1 failed"),
    ("dispatch failed after the cycle ran", alloc(RUNNING, START_FAILED), look(), INTERRUPTED, 0, False, "without a part"),
    # -- the job cancelled
    ("cancelled before the start", alloc(DISPATCHED, NOT_STARTED, job_open=False), look(), INTERRUPTED, 0, True, "job cancelled"),
    ("cancelled while cutting: the part finishes", alloc(job_open=False), look(**CUTTING), RUNNING, 0, False, ""),
    ("cancelled, part made", alloc(job_open=False), look(part_count=6), COMPLETED, 1, False, ""),
    ("cancelled during the start", alloc(DISPATCHED, STARTING, job_open=False), look(), DISPATCHED, 0, False, ""),
]
# fmt: on


@pytest.mark.parametrize(
    "a, seen, state, parts, cancel, reason", [row[1:] for row in TABLE], ids=[r[0] for r in TABLE]
)
def test_transition(a, seen, state, parts, cancel, reason):
    got = step(a, seen, lost_contact_s=30.0)
    assert (got.state, got.parts, got.cancel_dispatch) == (state, parts, cancel)
    assert reason in got.reason


def test_alarms_while_cutting_are_noted_not_interrupting():
    got = step(alloc(), look(alarm="lube_level_low", warnings=("w1",), in_cycle=True))
    assert got.state == RUNNING and got.note == "alarm while cutting on: lube_level_low; w1"
    assert step(alloc(), look(in_cycle=True)).note == ""
    assert "waiting for the cycle start" in step(alloc(DISPATCHED, STARTING), look(alarm="x")).note
    assert "2 more part(s)" in step(alloc(), look(part_count=AT + 3)).note


def test_final_and_interrupted_states_do_not_step():
    for state in (INTERRUPTED, *FINAL):
        assert step(alloc(state), look(part_count=AT + 1)).state == state


def test_interrupted_ends_rerouted_or_failed():
    down = alloc(INTERRUPTED)
    assert settle(down, rerouted_to=None).state == INTERRUPTED  # its part waits for a machine
    assert settle(down, rerouted_to=42) == settle(down, rerouted_to=42)
    got = settle(down, rerouted_to=42)
    assert (got.state, got.reason) == (REROUTED, "part rerouted to allocation 42")
    got = settle(alloc(INTERRUPTED, job_open=False), rerouted_to=None)
    assert (got.state, got.reason) == (FAILED, "job closed: part not rerouted")
    assert settle(alloc(RUNNING), rerouted_to=1).state == RUNNING


EVENTS = {
    "cycle end": look(part_count=AT + 1),
    "reset": look(),
    "alarm": look(alarm="x"),
    "warning": look(warnings=("w",)),
    "E-stop": look(estop=True),
    "program change": look(program="O9"),
    "restart": look(part_count=0, program=""),
    "lost": look(connected=False, offline_s=1e9),
}


@pytest.mark.parametrize(
    "state, phase, open_", list(itertools.product(ACTIVE, DISPATCH_PHASES, (True, False)))
)
def test_every_event_leads_to_an_end(state, phase, open_):
    """From every active state and dispatch phase, each machine event either ends the
    allocation or leaves it where only the start's outcome (`starting`) or a program not yet
    started can move it on; once the start is settled the same event ends it."""
    a = Alloc(state, "mill1", AT, phase, P, open_)
    for name, seen in EVENTS.items():
        got = step(a, seen)
        if got.state in ACTIVE:
            assert phase in (STARTING, NOT_STARTED), (name, got)
            settled = Alloc(got.state, "mill1", AT, STARTED, P, open_)
            assert step(settled, seen).state in (COMPLETED, INTERRUPTED), name
        else:
            assert got.state in (COMPLETED, INTERRUPTED), (name, got)
            assert got.parts == (1 if got.state == COMPLETED else 0)
            if got.state == INTERRUPTED:
                end = settle(Alloc(INTERRUPTED, "mill1", AT, phase, P, False), rerouted_to=None)
                assert end.state == FAILED


@pytest.mark.parametrize(
    "state, phase",
    [
        (None, NOT_STARTED),
        ("pending", NOT_STARTED),
        ("transferring", NOT_STARTED),
        ("verifying", NOT_STARTED),
        ("starting", STARTING),
        ("done", STARTED),
        ("failed", START_FAILED),
    ],
)
def test_dispatch_phase(state, phase):
    assert dispatch_phase(state) == phase


@pytest.mark.parametrize(
    "error, phase",
    [
        # the start step failed: the host died pressing cycle start, or running was not seen
        ("start: cycle start failed: running not seen", START_FAILED),
        (None, START_FAILED),  # no reason recorded: the machine may have taken the start
        ("start refused: cycle start failed: axes not referenced", NEVER_STARTED),
        ("transfer: connection reset by peer", NEVER_STARTED),
        ("verify: sha256 differs", NEVER_STARTED),
    ],
)
def test_failed_dispatch_phase_from_its_error(error, phase):
    assert dispatch_phase("failed", error) == phase
    # an error left over from an earlier attempt does not change a live dispatch's phase
    assert dispatch_phase("done", error) == STARTED
    assert dispatch_phase("transferring", error) == NOT_STARTED


# (allocation, look, reason, note) word for word: what the operator reads on the allocation
# fmt: off
WORDING = [
    (alloc(), look(part_count=AT + 1),
     "part counter of mill1 advanced to 6", ""),
    (alloc(), look(part_count=AT + 3),
     "part counter of mill1 advanced to 8", "2 more part(s) counted by mill1 belong to no allocation"),
    (alloc(), look(part_count=0, program=""),
     "part counter of mill1 went back from 5 to 0: the machine's control was restarted", ""),
    (alloc(DISPATCHED, NOT_STARTED, job_open=False), look(),
     "job cancelled before its program was started", ""),
    (alloc(), look(alarm=""),
     "machine mill1 raised an alarm", ""),
    (alloc(), look(alarm="servo FAULT 2101"),
     "machine mill1 raised an alarm: servo FAULT 2101", ""),
    (alloc(), look(alarm="", **CUTTING),
     "", "alarm while cutting on: FAULT"),
    (alloc(DISPATCHED, NOT_STARTED), look(warnings=("lube low", "door open")),
     "", "lube low; door open"),
    (alloc(DISPATCHED, STARTING), look(),
     "", ""),
]
# fmt: on


@pytest.mark.parametrize("a, seen, reason, note", WORDING)
def test_reason_and_note_wording(a, seen, reason, note):
    got = step(a, seen)
    assert (got.reason, got.note) == (reason, note)


# -- random event sequences against the pure core ---------------------------------------------

LOOKS = st.builds(
    Look,
    connected=st.booleans(),
    offline_s=st.sampled_from([0.0, 10.0, 29.9, 30.0, 1e6]),
    in_cycle=st.booleans(),
    program=st.sampled_from([P, "O2002", "", None]),
    part_count=st.integers(AT - 2, AT + 3),
    alarm=st.sampled_from([None, "", "servo FAULT 2101"]),
    estop=st.booleans(),
    warnings=st.sampled_from([(), ("w",)]),
)


@given(
    looks=st.lists(st.tuples(LOOKS, st.sampled_from(DISPATCH_PHASES)), max_size=30),
    job_open=st.booleans(),
)
def test_random_event_sequences_end_once_and_count_at_most_one_part(looks, job_open):
    """Any sequence of looks (and dispatch phases as the worker moves on): an allocation
    leaves the active states at most once, counts at most one part, never counts one without
    a start (pressed, or under way with our program's part counted), and from wherever it stands a settled machine (start confirmed, READY and idle)
    ends it."""
    a = Alloc(DISPATCHED, "mill1", AT, NOT_STARTED, P, job_open)
    parts = 0
    for seen, phase in looks:
        a = Alloc(a.state, a.machine, a.parts_at_start, phase, a.program, a.job_open)
        got = step(a, seen)
        assert got.parts in (0, 1)
        if got.parts:
            # a start under way counts only a part of our own program past its baseline
            taken = phase in (STARTED, START_FAILED) or (phase == STARTING and seen.program == P)
            assert taken and got.state == COMPLETED
        if got.cancel_dispatch:
            assert phase == NOT_STARTED and got.state == INTERRUPTED
        parts += got.parts
        if a.state in ACTIVE:
            a = Alloc(got.state, a.machine, a.parts_at_start, phase, a.program, a.job_open)
        else:
            assert got.state == a.state  # a final or interrupted allocation stays put
    assert parts <= 1
    if a.state in ACTIVE:
        settled = Alloc(a.state, a.machine, a.parts_at_start, STARTED, a.program, a.job_open)
        assert step(settled, look()).state == INTERRUPTED
        assert step(settled, look(part_count=AT + 1)).state == COMPLETED
