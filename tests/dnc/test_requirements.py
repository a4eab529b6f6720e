"""Which machines a job may go to: what a program needs (from the upload check) against
what each machine has (its kind and configured axes). The pure rule and the scheduler's
allocation are table-tested; the library stores the needs with each revision and a job
whose program no machine of the cell can run is refused when it is queued."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
from sqlalchemy import func, select

from cnc.config import builtin_machine
from dnc import models as m
from dnc.checker import nc_checker, needed_axes
from dnc.errors import NoMachineCanRun
from dnc.jobs import Jobs, Scheduler
from dnc.library import Library
from dnc.requirements import Needs, Offer, refusal, revision_needs, runnable_on, why_none
from dnc.rules import fifo
from dnc.scheduler import Allocate, JobState, MachineView, decide

from .test_checker_axes import MACRO_ARG, PLAIN, ROTARY

T0 = datetime(2026, 11, 26, 8, 0, tzinfo=UTC)
AXES = {n: tuple(builtin_machine(n).axes) for n in ("mill3", "mill4", "mill5", "lathe2")}
KIND = {"mill3": "mill", "mill4": "mill", "mill5": "mill5", "lathe2": "lathe"}
CELL = [Offer(n, KIND[n], AXES[n]) for n in ("mill3", "mill4", "mill5", "lathe2")]

XYZ, XYZA, XYZBC = ("X", "Y", "Z"), ("X", "Y", "Z", "A"), ("X", "Y", "Z", "B", "C")


def test_the_shipped_machines_have_the_axes_the_rules_assume():
    assert AXES == {"mill3": XYZ, "mill4": XYZA, "mill5": XYZBC, "lathe2": ("X", "Z")}


@pytest.mark.parametrize(
    ("needs", "runs_on"),
    [
        (Needs(("mill",), XYZ), ["mill3", "mill4"]),
        (Needs(("mill",), XYZA), ["mill4"]),  # A words: the rotary table only
        (Needs(("mill",), ("X", "Y", "Z", "B")), []),  # no mill has a B
        (Needs(("mill5",), XYZBC), ["mill5"]),
        (Needs(("lathe",), ("X", "Z")), ["lathe2"]),
        (Needs(("mill", "mill5")), ["mill3", "mill4", "mill5"]),  # a CL source for both
        (Needs(("mill",)), ["mill3", "mill4"]),  # axes not known: the kind alone
        (Needs(("router",), XYZ), []),
        (Needs((), XYZ), []),
    ],
)
def test_which_machines_can_run_a_program(needs, runs_on):
    assert runnable_on(needs, CELL) == runs_on
    for offer in CELL:
        assert (refusal(needs, offer) is None) == (offer.name in runs_on)
        assert needs.met_by(offer.kind, offer.axes) == (offer.name in runs_on)


@pytest.mark.parametrize(
    ("needs", "machine", "reason"),
    [
        (Needs(("mill",), XYZA), "mill3", "mill3 has axes X Y Z; the program needs A"),
        (Needs(("mill",), XYZA), "lathe2", "lathe2 is a lathe; the program is for mill machines"),
        (
            Needs(("mill", "mill5")),
            "lathe2",
            "lathe2 is a lathe; the program is for mill machines or mill5 machines",
        ),
        (Needs(("mill5",), XYZBC), "mill4", "mill4 is a mill; the program is for mill5 machines"),
    ],
)
def test_a_refusal_says_what_the_machine_lacks(needs, machine, reason):
    assert refusal(needs, next(o for o in CELL if o.name == machine)) == reason


def test_a_machine_whose_axes_are_not_known_is_judged_by_its_kind():
    assert refusal(Needs(("mill",), XYZA), Offer("mill9", "mill")) is None
    assert refusal(Needs(("mill",), XYZA), Offer("lathe9", "lathe")) is not None


def test_why_none_names_every_machine():
    text = why_none(Needs(("mill",), ("X", "Y", "Z", "B")), CELL)
    assert text.startswith("no machine of the cell can run it: mill3 has axes X Y Z;")
    assert all(n in text for n in ("mill3", "mill4", "mill5", "lathe2"))
    assert why_none(Needs(("mill",)), []) == "the cell has no machines"


@pytest.mark.parametrize(
    ("args", "needs"),
    [
        (("gcode", "mill", [], ["X", "Y", "Z"]), Needs(("mill",), XYZ)),
        (("gcode", "mill", [], ["X", "Y", "Z"], [["X", "Y", "Z", "A"]]), Needs(("mill",), XYZA)),
        (("gcode", "mill", [], ["X", "Y", "Z"], [None, ["A", "Z"]]), Needs(("mill",), XYZA)),
        (("gcode", "mill", [], None), Needs(("mill",))),  # stored before axes were known
        (("gcode", "mill5", [], ["X", "Y", "Z", "C"]), Needs(("mill5",), ("X", "Y", "Z", "C"))),
        (("cl", "mill", ["mill5"], None), Needs(("mill5",))),  # the kinds it was posted for
        (("apt", "mill", ["mill", "lathe"], None), Needs(("mill", "lathe"))),
        (("apt", "mill", [], None), Needs(("mill",))),
    ],
)
def test_a_revisions_needs_from_its_stored_check(args, needs):
    assert revision_needs(*args) == needs


def test_needs_round_trip_through_their_stored_form():
    n = Needs(("mill", "mill5"), XYZA)
    assert Needs.from_data(n.as_data(), "lathe") == n
    assert Needs.from_data(None, "lathe") == Needs(("lathe",))


# ------------------------------------------------------------------ the upload check


@pytest.mark.parametrize(
    ("text", "kind", "axes"),
    [
        (ROTARY, "mill", XYZA),
        (PLAIN, "mill", XYZ),
        (MACRO_ARG, "mill", XYZ),  # G65 P9010 A1.: an argument, not the rotary table
        ("%\nO1\nG0 X0 Z5\nG1 Z-10 F0.2\nM30\n%\n", "lathe", ("X", "Z")),
        ("%\nO2\nG0 X0 Y0 Z50\nG0 B30 C90\nM30\n%\n", "mill5", XYZBC),
        ("%\nO3\nG0 X0 Y0 Z50\nG0 C90\nM30\n%\n", "mill5", ("X", "Y", "Z", "C")),
        ("%\nO4\nG92 A0\nM30\n%\n", "mill", XYZA),  # setting its G92 shift needs it too
    ],
)
def test_the_upload_check_finds_the_axes_a_program_needs(text, kind, axes):
    assert nc_checker(text, kind).axes == axes
    assert needed_axes(text, kind) == axes


def test_a_subprograms_rotary_axis_is_the_callers_need():
    sub = "%\nO9020\nG0 A90.\nM99\n%\n"
    caller = PLAIN.replace("M30", "M98 P9020\nM30")
    assert nc_checker(caller, "mill", programs={9020: sub}).axes == XYZA


# ------------------------------------------------------------- the scheduler's choice


def job(id, needs, kind="mill", qty=1):
    return JobState(id, kind, None, qty, 0, 0, T0, None, 60.0, needs=needs)


def machine(name, *, axes=None):
    """An idle machine built like the shipped machine it is named after."""
    return MachineView(name, KIND[name], "idle", 0, axes=AXES[name] if axes is None else axes)


IDLE_CELL = [machine("mill3"), machine("mill4"), machine("mill5"), machine("lathe2")]


@pytest.mark.parametrize(
    ("jobs", "allocated"),
    [
        # A words: only mill4, whichever job comes first in the queue
        ([job(1, Needs(("mill",), XYZA), qty=3)], [(1, "mill4")]),
        # a mill4 runs 3-axis programs too: FIFO gives it the older job (the rule decides,
        # the needs only say who may)
        (
            [job(1, Needs(("mill",), XYZ), qty=3), job(2, Needs(("mill",), XYZA))],
            [(1, "mill3"), (1, "mill4")],
        ),
        # a FIFO-first rotary job does not take mill3 for want of a better machine
        (
            [job(1, Needs(("mill",), XYZA), qty=3), job(2, Needs(("mill",), XYZ))],
            [(2, "mill3"), (1, "mill4")],
        ),
        # a CL source posted for mill and mill5: every machine of those kinds
        ([job(1, Needs(("mill", "mill5")), qty=5)], [(1, "mill3"), (1, "mill4"), (1, "mill5")]),
        ([job(1, Needs(("mill5",), XYZBC), kind="mill", qty=2)], [(1, "mill5")]),
        ([job(1, Needs(("mill",), ("X", "Y", "Z", "B")), qty=2)], []),  # nobody: held
        ([job(1, None, qty=5)], [(1, "mill3"), (1, "mill4")]),  # queued before: kind alone
    ],
)
def test_the_scheduler_allocates_only_to_machines_that_can_run_the_program(jobs, allocated):
    d = decide(jobs, [], IDLE_CELL, fifo, "fifo", T0)
    assert sorted((a.job_id, a.machine) for a in d.of(Allocate)) == sorted(allocated)


def test_a_machine_whose_axes_are_not_known_takes_the_job_by_kind():
    d = decide([job(1, Needs(("mill",), XYZA))], [], [machine("mill3", axes=())], fifo, "f", T0)
    assert [(a.job_id, a.machine) for a in d.of(Allocate)] == [(1, "mill3")]


def test_machines_of_one_kind_with_different_axes_are_ranked_apart():
    # mill3 and mill4 are both mills; the ranking of one must not be reused for the other
    jobs = [job(1, Needs(("mill",), XYZA)), job(2, Needs(("mill",), XYZ))]
    d = decide(jobs, [], [machine("mill3"), machine("mill4")], fifo, "fifo", T0)
    assert [(a.job_id, a.machine) for a in d.of(Allocate)] == [(2, "mill3"), (1, "mill4")]


# ------------------------------------------------------------- the library and jobs


@pytest.fixture
def lib(sessions):
    lib = Library(sessions, checker=nc_checker)
    for name in ("mill3", "mill4", "lathe2"):
        lib.register_machine(name, KIND[name], axes=AXES[name])
    return lib


def _released(lib, text, number, kind="mill"):
    _, rev = lib.create_program(number=number, name=f"p{number}", text=text, machine_kind=kind)
    assert rev.check_ok, rev.check_errors
    return lib.release(rev.id, approver="ann", comment="ok")


def _jobs(sessions) -> int:
    from dnc.db import transaction

    with transaction(sessions) as s:
        return s.scalar(select(func.count()).select_from(m.Job))


def test_revisions_store_the_axes_they_need_and_jobs_what_their_machines_must_have(lib, sessions):
    rotary, plain = _released(lib, ROTARY, 40), _released(lib, PLAIN, 41)
    assert (rotary.axes, plain.axes) == (list(XYZA), list(XYZ))
    assert lib.machine("mill4")["axes"] == list(XYZA)
    jobs = Jobs(sessions)
    a = jobs.create(revision_id=rotary.id, quantity=2)
    b = jobs.create(revision_id=plain.id, quantity=2)
    assert a.needs == {"kinds": ["mill"], "axes": list(XYZA)}
    assert b.needs == {"kinds": ["mill"], "axes": list(XYZ)}
    views = [machine("mill3"), machine("mill4"), machine("lathe2")]
    d = Scheduler(sessions, lambda: views).tick()
    allocated = sorted((x.job_id, x.machine) for x in d.of(Allocate))
    assert allocated == [(a.id, "mill4"), (b.id, "mill3")]
    assert [x["machine"] for x in jobs.allocations(a.id)] == ["mill4"]


def test_a_job_no_machine_of_the_cell_can_run_is_refused_with_each_machines_reason(lib, sessions):
    lib.register_machine("mill4", "mill", axes=XYZ)  # the rotary table taken off
    rotary = _released(lib, ROTARY, 40)
    with pytest.raises(NoMachineCanRun) as err:
        Jobs(sessions).create(revision_id=rotary.id, quantity=1)
    detail = err.value.detail
    assert detail["pointer"] == "#/revision_id"
    assert detail["needs"] == {"kinds": ["mill"], "axes": list(XYZA)}
    assert detail["machines"] == {
        "lathe2": "lathe2 is a lathe; the program is for mill machines",
        "mill3": "mill3 has axes X Y Z; the program needs A",
        "mill4": "mill4 has axes X Y Z; the program needs A",
    }
    assert f"revision {rotary.id}: no machine of the cell can run it" in err.value.message
    assert _jobs(sessions) == 0


def test_a_called_subprograms_rotary_axis_refuses_the_job_on_a_cell_of_mill3s(sessions):
    lib = Library(sessions, checker=nc_checker)
    lib.register_machine("mill3", "mill", axes=XYZ)
    sub = _released(lib, "%\nO9020\nG0 Z50.\nM99\n%\n", 9020)
    caller = _released(lib, PLAIN.replace("M30", "M98 P9020\nM30"), 41)
    assert caller.axes == list(XYZ)
    # a new revision of the subprogram turns A: the caller's job brings it along
    turning = lib.add_revision(sub.program_id, "%\nO9020\nG0 A90.\nM99\n%\n")
    lib.release(turning.id, approver="ann", comment="ok")
    with pytest.raises(NoMachineCanRun, match="mill3 has axes X Y Z; the program needs A"):
        Jobs(sessions).create(revision_id=caller.id, quantity=1)


def test_a_cell_with_no_machine_registered_does_not_judge(sessions):
    lib = Library(sessions, checker=nc_checker)
    rotary = _released(lib, ROTARY, 40)
    job = Jobs(sessions).create(revision_id=rotary.id, quantity=1)
    assert job.needs == {"kinds": ["mill"], "axes": list(XYZA)}
