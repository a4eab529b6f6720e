"""Dispatch execution against a real machine DNC port, directly and through a fault-injecting line."""

from __future__ import annotations

import threading
from datetime import UTC, datetime, timedelta

import pytest

from dnc.dispatch import Dispatches
from dnc.transfer import canonical_text
from dnc.transfer_worker import RetryPolicy, TransferWorker
from tests.cnc.dnc_helpers import Machine

from .faultport import Fault, FaultPort

# ~50 KB: far more than the sockets can hold in flight, so XOFF always comes in time.
MOVES = "".join(f"G1 X{i % 50} Y{i % 7} F300\n" for i in range(2500))
PROG = "%\nO1234 (PLATE)\nG21 G90\nG0 X10 Y10\n" + MOVES + "M30\n%\n"


class Clock:
    def __init__(self):
        self.t = datetime(2026, 11, 21, 8, 0, tzinfo=UTC)

    def __call__(self):
        return self.t

    def advance(self, seconds):
        self.t += timedelta(seconds=seconds)


@pytest.fixture
def machine():
    m = Machine(capacity=128 * 1024)
    yield m
    m.close()


@pytest.fixture
def released(library):
    _, rev = library.create_program(number=1234, name="plate", text=PROG)
    library.release(rev.id, approver="ann", comment="ok")
    return rev.id


def register(library, port, **profile):
    library.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{port}", dnc_profile=profile)


def dispatch(sessions, released, key="k1", **kw):
    info, _ = Dispatches(sessions).request(key=key, revision_id=released, machine="mill1", **kw)
    return info.id


def test_memory_dispatch_is_transferred_and_verified(library, sessions, machine, released):
    register(library, machine.port.bound_port)
    did = dispatch(sessions, released)
    worker = TransferWorker(sessions)
    assert worker.run_once() == [did]
    d = Dispatches(sessions).get(did)
    assert (d.state, d.verified, d.attempts, d.error) == ("done", True, 1, None)
    assert d.bytes_sent > len(PROG)
    assert machine.memory.get(1234) == canonical_text(PROG)
    states = [a["detail"]["attempts"] for a in library.audit(entity="dispatch", entity_id=did)]
    assert len(states) == 4  # requested, transferring, verifying, done


@pytest.mark.parametrize(
    "fault, error",
    [
        (Fault("drop", at=30), "cut_off"),
        (Fault("corrupt", at=40), "verify"),
        (Fault("xoff_hold", at=20, hold_s=1.0), "xoff_timeout"),
    ],
)
def test_line_faults_are_retried_with_backoff_and_then_succeed(
    library, sessions, machine, released, fault, error
):
    line = FaultPort(machine.port.bound_port, [fault])
    try:
        register(library, line.port, xoff_timeout_s=0.3, timeout_s=2)
        clock = Clock()
        worker = TransferWorker(sessions, now=clock, retry=RetryPolicy(base_s=2))
        did = dispatch(sessions, released)
        worker.run_once()
        first = Dispatches(sessions).get(did)
        assert first.state == "pending" and first.error.startswith(error)
        assert "attempt 1 of 5; retry at 2026-11-21T08:00:02" in first.error
        assert worker.run_once() == []  # not due yet
        clock.advance(2)
        worker.run_once()
        final = Dispatches(sessions).get(did)
        assert (final.state, final.verified, final.attempts) == ("done", True, 2)
        assert machine.memory.get(1234) == canonical_text(PROG)
    finally:
        line.close()


def test_xoff_storm_is_ridden_out(library, sessions, machine, released):
    line = FaultPort(machine.port.bound_port, [Fault("xoff_storm", at=10)])
    try:
        register(library, line.port)
        did = dispatch(sessions, released)
        TransferWorker(sessions).run_once()
        assert Dispatches(sessions).get(did).state == "done"
    finally:
        line.close()


def test_parity_error_on_the_line_is_retried(library, sessions, released):
    m = Machine(capacity=128 * 1024, parity=True)
    line = FaultPort(m.port.bound_port, [Fault("corrupt", at=25)])
    try:
        register(library, line.port, parity=True)
        clock = Clock()
        worker = TransferWorker(sessions, now=clock)
        did = dispatch(sessions, released)
        worker.run_once()
        first = Dispatches(sessions).get(did)
        assert first.state == "pending" and "machine alarm 2001: parity error" in first.error
        assert m.alarms[0][0] == 2001 and 1234 not in m.memory
        clock.advance(1)
        worker.run_once()
        assert Dispatches(sessions).get(did).state == "done"
    finally:
        line.close()
        m.close()


def test_attempts_run_out_and_the_dispatch_fails_with_its_reason(
    library, sessions, machine, released
):
    line = FaultPort(machine.port.bound_port, [Fault("drop", at=5)] * 3)
    try:
        register(library, line.port)
        clock = Clock()
        worker = TransferWorker(sessions, now=clock, retry=RetryPolicy(max_attempts=3, base_s=1))
        did = dispatch(sessions, released)
        for _ in range(3):
            worker.run_once()
            clock.advance(60)
        d = Dispatches(sessions).get(did)
        assert d.state == "failed" and d.attempts == 3 and d.error.startswith("cut_off")
        assert worker.run_once() == []
    finally:
        line.close()


def test_memory_full_is_not_retried(library, sessions, released):
    m = Machine(capacity=64)
    try:
        register(library, m.port.bound_port)
        did = dispatch(sessions, released)
        TransferWorker(sessions).run_once()
        d = Dispatches(sessions).get(did)
        assert d.state == "failed" and "alarm 2002" in d.error and d.attempts == 1
    finally:
        m.close()


def test_machine_without_address_fails_clearly(library, sessions, released):
    library.register_machine("mill1", "mill")
    did = dispatch(sessions, released)
    TransferWorker(sessions, retry=RetryPolicy(max_attempts=1)).run_once()
    assert "machine has no DNC address" in Dispatches(sessions).get(did).error


def test_a_text_that_cannot_be_read_ends_in_a_recorded_retry_not_in_transferring(
    library, sessions, machine, released, monkeypatch
):
    """The text is read after the claim committed: a database error there is a failure of
    this attempt (retried later), never a dispatch left in `transferring`."""
    register(library, machine.port.bound_port)
    clock = Clock()
    worker = TransferWorker(sessions, now=clock, retry=RetryPolicy(max_attempts=3, base_s=1))
    did = dispatch(sessions, released)

    def database_down(sha):
        raise RuntimeError("connection pool exhausted")

    monkeypatch.setattr(worker, "_text", database_down)
    worker.run_once()
    d = Dispatches(sessions).get(did)
    assert d.state == "pending" and d.attempts == 1, (d.state, d.error)
    assert d.error.startswith("read") and "connection pool exhausted" in d.error
    monkeypatch.undo()
    clock.advance(60)
    worker.run_once()
    assert Dispatches(sessions).get(did).state == "done"


def test_start_goes_through_the_starter_after_verification(library, sessions, machine, released):
    register(library, machine.port.bound_port)
    started = []
    did = dispatch(sessions, released, start=True)
    TransferWorker(sessions, starter=lambda name, number: started.append((name, number))).run_once()
    assert started == [("mill1", 1234)]
    assert Dispatches(sessions).get(did).state == "done"


def test_start_without_a_starter_is_refused_not_ignored(library, sessions, machine, released):
    register(library, machine.port.bound_port)
    did = dispatch(sessions, released, start=True)
    TransferWorker(sessions).run_once()
    d = Dispatches(sessions).get(did)
    assert d.state == "failed" and "no cycle-start path" in d.error


def test_restart_requeues_transfers_but_never_restarts_a_start(
    library, sessions, machine, released, engine
):
    register(library, machine.port.bound_port)
    a = dispatch(sessions, released, key="a")
    b = dispatch(sessions, released, key="b", start=True)
    with engine.begin() as conn:  # the host was killed mid-transfer and mid-start
        conn.exec_driver_sql(f"UPDATE dispatches SET state='transferring' WHERE id={a}")
        conn.exec_driver_sql(f"UPDATE dispatches SET state='starting' WHERE id={b}")
    started = []
    worker = TransferWorker(sessions, starter=lambda *args: started.append(args))
    worker.run_once()
    assert Dispatches(sessions).get(a).state == "done"
    failed = Dispatches(sessions).get(b)
    assert failed.state == "failed" and "never started twice" in failed.error
    assert started == []


def test_drip_feed_dispatch_streams_to_the_nc(library, sessions, released):
    m = Machine(capacity=64, drip_capacity=512)  # the program does not fit in memory
    taken, stop = [], threading.Event()

    def nc():
        while not stop.is_set():
            if m.drip_buffers:
                block = m.drip_buffers[0].take()
                if block is None:
                    return
                if block is not False:
                    taken.append(block)
                    continue
            stop.wait(0.001)

    t = threading.Thread(target=nc)
    t.start()
    try:
        register(library, m.port.bound_port)
        did = dispatch(sessions, released, mode="drip_feed")
        TransferWorker(sessions).run_once()
        t.join(10)
        d = Dispatches(sessions).get(did)
        assert (d.state, d.verified) == ("done", None)
        assert taken == canonical_text(PROG).splitlines()[1:-1]
    finally:
        stop.set()
        t.join()
        m.close()


def test_a_value_many_dispatches_need_at_once_is_worked_out_once():
    from dnc.transfer_worker import _Memo

    memo, calls, results = _Memo(2), [], []
    gate = threading.Barrier(8)

    def compute():
        calls.append(1)
        return "sha"

    def ask():
        gate.wait()
        results.append(memo.get("rev", compute))

    threads = [threading.Thread(target=ask) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert results == ["sha"] * 8 and len(calls) == 1

    def broken():
        raise RuntimeError("database down")

    with pytest.raises(RuntimeError):
        memo.get("other", broken)
    assert memo.get("other", lambda: "ok") == "ok"  # a failure is not remembered
    weighed = _Memo(10, weight=len)
    with pytest.raises(TypeError):
        weighed.get("none", lambda: None)  # len(None): refused before it is stored
    assert weighed.get("none", lambda: "text") == "text"
    memo.get("third", lambda: "x")
    assert memo.get("rev", lambda: "again") == "again"  # the oldest went past the limit


def test_a_text_the_tape_cannot_carry_fails_the_dispatch_with_where_not_transferring(
    library, sessions, machine, released, monkeypatch
):
    """A revision stored before uploads were held to the ISO character set (issue 14, item
    9: a UnicodeEncodeError in the worker left the dispatch in `transferring` for ever): the
    attempt fails, recorded with the character and its line, and is not retried."""
    register(library, machine.port.bound_port)
    worker = TransferWorker(sessions, retry=RetryPolicy(max_attempts=3, base_s=1))
    did = dispatch(sessions, released)
    monkeypatch.setattr(worker, "_text", lambda sha: "%\nO1234\n(PLATTE F\u00dcR A)\nM30\n%\n")
    worker.run_once()
    d = Dispatches(sessions).get(did)
    assert (d.state, d.attempts, d.bytes_sent) == ("failed", 1, 0), (d.state, d.error)
    assert d.error.startswith("encode: character '\u00dc' (U+00DC) at line 3, column 10")
    assert 1234 not in machine.memory


def test_an_unexpected_error_in_an_attempt_is_recorded_not_left_transferring(
    library, sessions, machine, released
):
    def broken_client(host, port, profile):
        raise ValueError("a bug in the client factory")

    register(library, machine.port.bound_port)
    worker = TransferWorker(
        sessions, client_factory=broken_client, retry=RetryPolicy(max_attempts=3)
    )
    did = dispatch(sessions, released)
    worker.run_once()
    d = Dispatches(sessions).get(did)
    assert d.state == "failed", (d.state, d.error)
    assert d.error == "internal: ValueError: a bug in the client factory"
