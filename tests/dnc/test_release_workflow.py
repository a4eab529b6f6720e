"""Property test: random sequences of library operations against a model of the release workflow.

The model says, for every step, whether the library must do it or refuse it and why: a
release needs an approval comment, a draft and a passed NC check; releasing supersedes the
program's released revision (it becomes obsolete); an obsolete revision never comes back.
Every step the model accepts must happen (a library that refused every release would fail
here, not pass), and every refusal must be a WorkflowError naming the model's reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from dnc.db import make_engine, migrate, session_factory
from dnc.errors import WorkflowError
from dnc.library import Library

from .conftest import fake_checker

OPS = st.lists(
    st.tuples(
        # release_blank / obsolete_blank: the same step with an approval comment of spaces;
        # adds and releases drawn more often, so that most sequences release something
        st.sampled_from(
            ["add", "add", "add_bad", "release", "release", "release"]
            + ["release_blank", "obsolete", "obsolete_blank"]
        ),
        st.integers(0, 2),  # program
        st.integers(0, 9),  # revision pick
    ),
    max_size=25,
)


@dataclass
class ModelRevision:
    id: int
    seq: int
    status: str  # draft | released | obsolete
    check_ok: bool
    approval_comment: str | None = None


def expected_refusal(op: str, rev: ModelRevision) -> str | None:
    """The reason the library must give for refusing `op` on `rev`, or None: it must do it."""
    if op.endswith("_blank"):
        return "needs an approval comment"
    if op.startswith("release"):
        if rev.status != "draft":
            return f"is {rev.status}; only a draft can be released"
        if not rev.check_ok:
            return "failed the NC check"
        return None
    if rev.status == "obsolete":
        return "already obsolete"
    return None


def apply_to_model(op: str, rev: ModelRevision, program: list[ModelRevision]) -> None:
    """What a step the model accepted changes: release supersedes the released revision."""
    if op == "release":
        for other in program:
            if other.status == "released":
                other.status = "obsolete"
                other.approval_comment = f"superseded by rev {rev.seq}"
        rev.status, rev.approval_comment = "released", "c"
    else:
        rev.status, rev.approval_comment = "obsolete", "c"


# The examples pin what random draws might miss: a good draft released, a second release
# superseding the first, each refusal reason once.
@example(ops=[("add", 0, 0), ("release", 0, 1)])
@example(ops=[("release", 1, 0), ("add", 1, 0), ("release", 1, 1), ("release", 1, 0)])
@example(ops=[("add_bad", 2, 0), ("release", 2, 1), ("obsolete", 2, 1), ("obsolete", 2, 1)])
@example(ops=[("release_blank", 0, 0), ("obsolete_blank", 0, 0), ("obsolete", 0, 0)])
@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(ops=OPS)
def test_workflow_follows_the_model(tmp_path_factory, ops):
    eng = make_engine(f"sqlite:///{tmp_path_factory.mktemp('wf') / 'wf.db'}")
    migrate(eng)
    lib = Library(session_factory(eng), checker=fake_checker)
    progs: list[int] = []
    model: list[list[ModelRevision]] = []
    for n in range(3):
        prog, rev = lib.create_program(number=n + 1, name=f"p{n}", text=f"O{n + 1}\nG0 X0\n")
        progs.append(prog.id)
        model.append([ModelRevision(rev.id, rev.seq, "draft", True)])
    released = refused = 0
    for step, (op, p, pick) in enumerate(ops):
        where = f"step {step} {op} of program {p}"
        if op in ("add", "add_bad"):
            word = "G0" if op == "add" else "BAD"
            rev = lib.add_revision(progs[p], f"O{p + 1}\n{word} X{pick}\n")  # never refused
            assert (rev.status, rev.check_ok) == ("draft", op == "add"), where
            model[p].append(ModelRevision(rev.id, rev.seq, "draft", op == "add"))
        else:
            target = model[p][pick % len(model[p])]
            reason = expected_refusal(op, target)
            comment = "   " if op.endswith("_blank") else "c"
            call = lib.release if op.startswith("release") else lib.obsolete
            if reason is None:
                got = call(target.id, approver="a", comment=comment)
                apply_to_model(op.removesuffix("_blank"), target, model[p])
                assert (got.id, got.status) == (target.id, target.status), where
                released += op == "release"
            else:
                with pytest.raises(WorkflowError) as refusal:
                    call(target.id, approver="a", comment=comment)
                assert reason in str(refusal.value), f"{where}: {refusal.value}"
                refused += 1
        for pid, expected in zip(progs, model, strict=True):
            got_revs = lib.revisions(pid)
            state = [(r.id, r.seq, r.status, r.check_ok, r.approval_comment) for r in got_revs]
            want = [(r.id, r.seq, r.status, r.check_ok, r.approval_comment) for r in expected]
            assert state == want, f"after {where}"
            assert sum(r.status == "released" for r in got_revs) <= 1, f"after {where}"
    # every release the model accepted is in the audit log, under the revision it released
    for program in model:
        for r in program:
            actions = [a["action"] for a in lib.audit(entity="revision", entity_id=r.id)]
            assert actions[0] == "revision.create"
            if r.status == "released":
                assert actions[-1] == "revision.release", (r, actions)
    event(f"releases done: {'some' if released else 'none'}")
    event(f"refusals: {'some' if refused else 'none'}")
    eng.dispose()
