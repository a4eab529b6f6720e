"""Property test: random sequences of library operations keep the workflow's invariants."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dnc.db import make_engine, migrate, session_factory
from dnc.errors import DncError
from dnc.library import Library

from .conftest import fake_checker

OPS = st.lists(
    st.tuples(
        st.sampled_from(["add", "add_bad", "release", "obsolete"]),
        st.integers(0, 2),  # program
        st.integers(0, 9),  # revision pick
    ),
    max_size=25,
)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(ops=OPS)
def test_workflow_invariants(tmp_path_factory, ops):
    eng = make_engine(f"sqlite:///{tmp_path_factory.mktemp('wf') / 'wf.db'}")
    migrate(eng)
    lib = Library(session_factory(eng), checker=fake_checker)
    progs = [
        lib.create_program(number=n + 1, name=f"p{n}", text=f"O{n + 1}\nG0 X0\n")[0].id
        for n in range(3)
    ]
    history: dict[int, list[str]] = {}
    for op, p, pick in ops:
        revs = lib.revisions(progs[p])
        rev = revs[pick % len(revs)]
        try:
            if op == "add":
                lib.add_revision(progs[p], f"O{p + 1}\nG0 X{pick}\n")
            elif op == "add_bad":
                lib.add_revision(progs[p], f"O{p + 1}\nBAD X{pick}\n")
            elif op == "release":
                lib.release(rev.id, approver="a", comment="c")
            else:
                lib.obsolete(rev.id, approver="a", comment="c")
        except DncError:
            pass
        for pid in progs:
            states = lib.revisions(pid)
            assert sum(r.status == "released" for r in states) <= 1
            for r in states:
                if r.status == "released":
                    assert r.check_ok and r.approval_comment
                seen = history.setdefault(r.id, [])
                if seen and seen[-1] == "obsolete":
                    assert r.status == "obsolete"  # obsolete never comes back
                if seen and seen[-1] == "released":
                    assert r.status in ("released", "obsolete")
                seen.append(r.status)
    eng.dispose()
