"""Upload from a machine, remote requests answered with the released revision, drip resume."""

from __future__ import annotations

import time

import pytest

from dnc.errors import DncError, NotFound
from dnc.machine_link import RemoteRequests, blocks_from, client_for, upload_from_machine
from dnc.transfer import canonical_text
from tests.cnc.dnc_helpers import Machine

PROG = "%\nO1234 (PLATE)\nN10 G21 G90\nN20 G0 X10 Y10\nN30 G1 X50 F300\nN40 M30\n%\n"


@pytest.fixture
def machine(library):
    m = Machine(capacity=8192)
    library.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{m.port.bound_port}")
    yield m
    m.close()


def test_upload_lands_as_a_candidate_revision(library, machine):
    prog, r1 = library.create_program(number=1234, name="plate", text=PROG)
    library.release(r1.id, approver="ann", comment="ok")
    edited = PROG.replace("X50", "X55")
    with client_for(library, "mill1") as c:
        c.send_program(edited)  # the operator edited the program at the control
    cand = upload_from_machine(library, "mill1", 1234)
    assert (cand.program_id, cand.seq, cand.status) == (prog.id, 2, "draft")
    assert library.revision_text(cand.id) == canonical_text(edited)
    assert library.get_revision(r1.id).status == "released"


def test_remote_request_is_answered_with_the_released_revision(library, machine):
    _, r1 = library.create_program(number=1234, name="plate", text=PROG)
    library.release(r1.id, approver="ann", comment="ok")
    library.add_revision(r1.program_id, PROG.replace("X50", "X99"))  # a newer draft: not sent
    listener = RemoteRequests(library, "mill1").start()
    try:
        deadline = time.monotonic() + 5
        while machine.port.remote_request(1234) == 0 and time.monotonic() < deadline:
            time.sleep(0.01)  # until the host's LISTEN is registered
        machine.port.remote_request(777)  # nothing released under that number
        while (1234 not in machine.memory or not listener.refused) and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        listener.stop()
    assert machine.memory.get(1234) == canonical_text(PROG)
    assert list(listener.refused) == [(777, "no released revision of O0777 for mill")]
    actions = [a["action"] for a in library.audit(entity="machine")]
    assert "remote_request.served" in actions and "remote_request.refused" in actions


def test_a_long_running_listener_keeps_only_the_last_requests(library, monkeypatch):
    """One entry per remote request for weeks would grow without bound: the listener keeps
    the last REMOTE_REQUESTS_KEPT served and refused (the audit log has them all) and counts."""
    monkeypatch.setattr("dnc.machine_link.REMOTE_REQUESTS_KEPT", 3, raising=False)
    _, r1 = library.create_program(number=1234, name="plate", text=PROG)
    library.release(r1.id, approver="ann", comment="ok")
    library.register_machine("mill2", "mill")
    listener = RemoteRequests(library, "mill2")  # answered directly: no thread, no port
    for number in (1234, 700, 1234, 701, 1234, 702, 1234, 703, 1234):
        listener.answer(number)
    assert list(listener.served) == [1234, 1234, 1234]
    assert [n for n, _ in listener.refused] == [701, 702, 703]
    assert (listener.served_count, listener.refused_count) == (5, 4)


def test_machine_without_address_is_refused(library):
    library.register_machine("mill2", "mill")
    with pytest.raises(NotFound, match="no DNC address"):
        client_for(library, "mill2")


BLOCKS = ["O1234", "N10 G21", "N20 G0 X1", "N30 G1 X2 F100", "N40 M30"]


@pytest.mark.parametrize(
    "kw, expected",
    [
        (dict(block=30), ["O1234", "N30 G1 X2 F100", "N40 M30"]),
        (dict(line=3), ["O1234", "N20 G0 X1", "N30 G1 X2 F100", "N40 M30"]),
        (dict(block=10), BLOCKS),
    ],
)
def test_drip_feed_resumes_from_a_block_or_line(kw, expected):
    assert list(blocks_from(BLOCKS, **kw)) == expected


def test_resume_point_must_exist():
    with pytest.raises(DncError, match="block N99 is not in the program"):
        list(blocks_from(BLOCKS, block=99))
    with pytest.raises(ValueError):
        list(blocks_from(BLOCKS))
