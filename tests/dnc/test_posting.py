"""APT and CL revisions: checked on upload, posted at dispatch into derived revisions
(dnc/posting.py), on SQLite and PostgreSQL."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from cam.apt import process
from cam.cl import write_cl
from cnc.config import builtin_machine
from dnc import models as m
from dnc.db import transaction
from dnc.dispatch import Dispatches, DispatchRequest, create_dispatches
from dnc.errors import InvalidUpload, WorkflowError
from dnc.library import Library
from dnc.posting import PostRefused, kind_of_upload
from dnc.tape import sha256_of
from dnc.transfer_worker import TransferWorker
from tests.cam.test_post import SEED15

from .conftest import fake_checker

# mill3's shipped G54 (-300, -200, -300) puts seed 15's Y8 in (203.2 mm) past Y's travel
# (max 0): this setup's part zero leaves room for it
G54_ROOM = [-300.0, -300.0, -300.0]
FIVE_AXIS_CL = """PARTNO TILT 77
UNITS/MM
MULTAX/ON
LOADTL/1
SPINDL/3000,CLW
RAPID
GOTO/0,0,50,0,0,1
FEDRAT/500,MMPM
GOTO/10,0,20,0,0.6,0.8
GOTO/20,0,20,0,0.6,0.8
FINI
"""


def mill_with_room():
    cfg = builtin_machine("mill3")
    data = cfg.machine_data.model_copy(update={"work_offsets": {"G54": G54_ROOM}})
    return cfg.model_copy(update={"machine_data": data})


def configs(name: str, kind: str):
    """The cell's machine configurations as the host knows them."""
    return mill_with_room() if name in ("mill1", "mill2") else None


@pytest.fixture
def lib(sessions):
    lib = Library(sessions, checker=fake_checker, machine_configs=configs)
    for name, kind in (("mill1", "mill"), ("mill2", "mill"), ("lathe1", "lathe")):
        lib.register_machine(name, kind)
    lib.register_machine("five1", "mill5")
    return lib


def released(lib, text, *, kind="apt", number=15, post_kinds=None):
    _, rev = lib.create_program(
        number=number, name="seed", text=text, kind=kind, post_kinds=post_kinds
    )
    assert rev.check_ok, rev.check_errors
    return lib.release(rev.id, approver="ann", comment="ok")


def count(sessions, model) -> int:
    with transaction(sessions) as s:
        return s.scalar(select(func.count()).select_from(model))


# ----------------------------------------------------------------------------- upload


def test_upload_of_each_kind(lib):
    _, g = lib.create_program(number=1, name="g", text="%\nO0001\nG0 X0\nM30\n%\n")
    _, a = lib.create_program(number=2, name="a", text=SEED15, kind="apt")
    cl = "".join(_cl_lines(SEED15))
    _, c = lib.create_program(number=3, name="c", text=cl, kind="cl", post_kinds=["MILL"])
    assert (g.kind, g.post_kinds) == ("gcode", [])
    # MACHIN/MILL,1 names the kind the APT program is for
    assert (a.kind, a.post_kinds, a.check_ok) == ("apt", ["mill"], True)
    assert (c.kind, c.post_kinds, c.check_ok) == ("cl", ["mill"], True)
    assert lib.revision_text(a.id) == SEED15  # the source is stored, not a post of it


def _cl_lines(apt: str) -> list[str]:
    import io

    out = io.StringIO()
    write_cl(process(apt, "seed15.apt"), out)
    return [out.getvalue()]


def test_a_source_without_machin_is_meant_for_every_kind_in_the_cell(lib):
    _, rev = lib.create_program(
        number=4, name="any", text=SEED15.replace("MACHIN/MILL,1\n", ""), kind="apt"
    )
    assert rev.post_kinds == ["lathe", "mill", "mill5"]
    # the trial post for the lathe fails: a check error, so the revision cannot be released
    assert not rev.check_ok
    [err] = rev.check_errors
    assert (err["line"], err["machine_kind"]) == (6, "lathe")
    assert "no Y axis" in err["message"]
    with pytest.raises(WorkflowError):
        lib.release(rev.id, approver="ann", comment="ok")


@pytest.mark.parametrize(
    "kind, text, where, why",
    [
        ("apt", "P1 = POINT/1,2\nGOTO/P2\n", (2, 6), "undefined name 'P2'"),
        ("apt", "EXAMPLE = POINT/1,2\n", (1, 1), "EXAMPLE"),
        ("cl", "GOTO/1,2,3\nGOTO/1,2,\n", (2, 10), "empty argument"),
        ("cl", "GOTO/1,2,3,0,0,2\n", (1, 1), "is not a unit vector"),
    ],
)
def test_a_malformed_source_is_refused_with_line_and_column(lib, sessions, kind, text, where, why):
    with pytest.raises(InvalidUpload) as err:
        lib.create_program(number=5, name="bad", text=text, kind=kind)
    detail = err.value.detail
    assert (detail["line"], detail["column"]) == where, err.value.message
    assert why in err.value.message and detail["pointer"] == "#/text"
    assert count(sessions, m.Program) == count(sessions, m.Revision) == 0  # nothing stored


def test_kind_and_post_kinds_are_checked(lib):
    with pytest.raises(InvalidUpload, match="kind must be one of gcode, apt, cl"):
        lib.create_program(number=6, name="x", text=SEED15, kind="step")
    with pytest.raises(InvalidUpload, match="no post-processor for machine kind 'router'"):
        lib.create_program(number=6, name="x", text=SEED15, kind="apt", post_kinds=["router"])
    with pytest.raises(InvalidUpload, match="post_kinds is for APT and CL"):
        lib.create_program(number=6, name="x", text="G0 X0\n", post_kinds=["mill"])


def test_kind_of_upload_by_field_then_suffix():
    assert kind_of_upload(None, "PLATE.APT") == "apt"
    assert kind_of_upload(None, "part.cls") == "cl"
    assert kind_of_upload(None, "O1001.nc") == "gcode"
    assert kind_of_upload("cl", "part.apt") == "cl"


# --------------------------------------------------------------------------- dispatch


def test_dispatch_posts_into_a_derived_revision_reused_by_hash(lib, sessions):
    rev = released(lib, SEED15.replace("MACHIN/MILL,1", "MACHIN/MILL5"), post_kinds=None)
    assert rev.post_kinds == ["mill5"]
    src = released(
        lib, SEED15.replace("MACHIN/MILL,1\n", ""), number=16, post_kinds=["mill", "mill5"]
    )
    d = Dispatches(sessions, machine_configs=configs)
    first, _ = d.request(key="a", revision_id=src.id, machine="mill1")
    again, _ = d.request(key="b", revision_id=src.id, machine="mill1")
    other_mill, _ = d.request(key="c", revision_id=src.id, machine="mill2")
    five, _ = d.request(key="d", revision_id=src.id, machine="five1")
    assert first.derived_id == again.derived_id == other_mill.derived_id != five.derived_id
    derived = {x["id"]: x for x in lib.derived_revisions(src.id)}
    assert len(derived) == 2
    mill, mill5 = derived[first.derived_id], derived[five.derived_id]
    text = lib.derived_text(mill["id"])
    assert mill["sha256"] == sha256_of(text) and mill["lines"] == len(text.splitlines())
    assert (mill["post_name"], mill["post_version"], mill["tolerance_mm"]) == (
        "fanuc-mill",
        "1.0",
        None,
    )
    assert (mill5["post_name"], mill5["tolerance_mm"], mill5["machine_kind"]) == (
        "fanuc-mill5",
        0.01,
        "mill5",
    )
    # the library's O number, the seed's program: mill and mill5 each get their own
    assert text.splitlines()[1:3] == ["O0016 (TEST1)", "G20 G90 G94"]
    assert "G00 X2. Y3. Z4. B0. C0." in lib.derived_text(mill5["id"])
    assert "B0." not in text
    posted = [
        a
        for a in lib.audit(entity="revision", entity_id=src.id)
        if a["action"] == "revision.posted"
    ]
    assert [a["detail"]["derived_id"] for a in posted] == sorted(derived)


def test_preview_posts_without_storing(lib, sessions):
    src = released(lib, SEED15)
    preview = lib.posted_preview(src.id, "mill1")
    assert preview.text.startswith("%\nO0015 (TEST1)\nG20 G90 G94\nT1 M06\n")
    assert preview.sha256 == sha256_of(preview.text) and preview.post_name == "fanuc-mill"
    assert count(sessions, m.DerivedRevision) == 0
    with pytest.raises(PostRefused, match="no Y axis.*meant for mill machines; lathe1 is a lathe"):
        lib.posted_preview(src.id, "lathe1")
    with pytest.raises(WorkflowError, match="meant for mill machines; five1 is a mill5"):
        lib.posted_preview(src.id, "five1")  # it would post, but MACHIN/MILL says mill only
    with pytest.raises(InvalidUpload, match="is G-code: it is sent as it is"):
        lib.posted_preview(
            released(lib, "%\nO0001\nG0 X0\n%\n", kind="gcode", number=1).id, "mill1"
        )


def test_five_axis_cl_to_a_three_axis_machine_is_refused_with_its_line(lib, sessions):
    src = released(lib, FIVE_AXIS_CL, kind="cl", number=77, post_kinds=["mill5"])
    with pytest.raises(PostRefused) as err:
        Dispatches(sessions, machine_configs=configs).request(
            key="k", revision_id=src.id, machine="mill1"
        )
    assert err.value.detail["line"] == 9 and err.value.detail["machine"] == "mill1"
    assert "5-axis CL data (tool axis 0, 0.6, 0.8) cannot be posted" in err.value.message
    assert count(sessions, m.Dispatch) == count(sessions, m.DerivedRevision) == 0
    ok, _ = Dispatches(sessions).request(key="k5", revision_id=src.id, machine="five1")
    assert "B" in lib.derived_text(ok.derived_id)


def test_travel_beyond_the_machine_after_posting_is_refused(lib, sessions):
    src = released(lib, SEED15)
    # lathe-less check with the machine's own G54: mill3 as shipped has no room for Y8 in
    d = Dispatches(sessions, machine_configs=lambda name, kind: None)
    with pytest.raises(PostRefused) as err:
        d.request(key="k", revision_id=src.id, machine="mill1")
    assert err.value.detail["line"] == 11  # GOTO/4,8,7 in the APT source
    assert "posted block 8 (G01 X4. Y8. Z7. F10.)" in err.value.message
    assert "Y" in err.value.detail["reason"]
    assert count(sessions, m.Dispatch) == count(sessions, m.DerivedRevision) == 0


def test_a_dispatch_the_scheduler_made_is_posted_by_the_worker(lib, sessions):
    src = released(lib, SEED15)
    bad = released(lib, FIVE_AXIS_CL, kind="cl", number=78, post_kinds=["mill5"])
    with transaction(sessions) as s:
        [(ok_id, _), (bad_id, _)] = create_dispatches(
            s,
            [DispatchRequest("j1", src.id, "mill1"), DispatchRequest("j2", bad.id, "mill1")],
            requested_by="scheduler",
            now=lib._now(),
        )
    worker = TransferWorker(sessions, machine_configs=configs)
    # no DNC address: the transfer fails after the post, which is stored and kept
    assert worker.run(ok_id) in ("pending", "failed")
    ok = Dispatches(sessions).get(ok_id)
    assert ok.derived_id is not None and ok.error.startswith("connect")
    assert worker.run(bad_id) == "failed"
    failed = Dispatches(sessions).get(bad_id)
    assert failed.derived_id is None and failed.error.startswith("post: ")
    assert ":9:" in failed.error and "cannot be posted to a 3-axis machine" in failed.error


def test_concurrent_dispatches_of_one_source_share_its_derived_revision(lib, sessions, monkeypatch):
    """Two dispatches posting the same source for the same kind at once: both are made, with
    one derived revision (the second to store it meets the unique key and runs again)."""
    import threading

    import dnc.dispatch

    src = released(lib, SEED15)
    both_posted = threading.Barrier(2, timeout=30)
    real = dnc.dispatch.posted_for

    calls = []

    def post_then_meet(*args):
        out = real(*args)
        calls.append(args)
        if len(calls) <= 2:  # neither stores its derived revision before both have posted
            both_posted.wait()
        return out

    monkeypatch.setattr(dnc.dispatch, "posted_for", post_then_meet)
    d = Dispatches(sessions, machine_configs=configs)
    made: dict = {}

    def request(key: str, machine: str) -> None:
        try:
            made[key] = d.request(key=key, revision_id=src.id, machine=machine)[0]
        except Exception as exc:  # reported below
            made[key] = exc

    threads = [threading.Thread(target=request, args=a) for a in (("a", "mill1"), ("b", "mill2"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert all(not isinstance(v, Exception) for v in made.values()), made
    assert made["a"].derived_id == made["b"].derived_id is not None
    assert count(sessions, m.DerivedRevision) == 1 and count(sessions, m.Dispatch) == 2
    assert len(calls) in (2, 3)  # 3: the second to store ran its request again
