"""The scan's realtime aids: the scan gate (deadline announced, cooperating threads step aside
until the scan passed), SCHED_FIFO promotion with its refusal path, and their wiring into the
runner and the Modbus face. No test sleeps or asserts a duration; thread hand-offs are polled
to generous deadlines."""

from __future__ import annotations

import asyncio
import math
import socket
import struct
import threading
import time

import pytest

from plc.image import ImageSize, ProcessImage
from plc.ladder import compile_text
from plc.modbus import ModbusFace
from plc.modbus.server import _Connection
from plc.runtime import RealtimeRunner, Runtime, RuntimeConfig
from plc.runtime.realtime import (
    RT_PRIORITY_ENV,
    ScanGate,
    guard_for_period,
    promote_current_thread,
    rt_priority_from_env,
)

PROGRAM = "XIC %IX0.0 OTE %QX0.0\n"


def _poll(condition, seconds: float = 10.0) -> bool:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.001)
    return True


# -- ScanGate ---------------------------------------------------------------------------------


def test_gate_asks_to_step_aside_only_within_the_guard_before_an_announced_scan():
    gate = ScanGate(guard_s=0.001)
    assert not gate.should_step_aside(1e9)  # nothing announced
    gate.announce(10.0)
    assert gate.step_aside_at == pytest.approx(9.999)
    assert not gate.should_step_aside(9.998)
    assert gate.should_step_aside(9.999)
    assert gate.should_step_aside(10.5)  # a late scan still owns the GIL when it comes
    gate.passed()
    assert gate.scans == 1 and gate.due == math.inf
    assert not gate.should_step_aside(10.5)


def test_step_aside_returns_at_once_when_no_scan_is_due():
    gate = ScanGate(guard_s=0.001)
    gate.announce(10.0)
    assert gate.step_aside(9.0) is False
    gate.passed()  # passed between the caller's check and its step_aside
    assert gate.step_aside(10.0) is False
    assert gate.holds == 0


def test_step_aside_gives_up_after_max_hold_when_the_scan_never_comes():
    gate = ScanGate(guard_s=0.001, max_hold_s=0.001)
    gate.announce(10.0)
    assert gate.step_aside(10.0) is False
    assert (gate.holds, gate.hold_timeouts) == (1, 1)


def test_a_thread_that_stepped_aside_resumes_when_the_scan_passed():
    gate = ScanGate(guard_s=0.001, max_hold_s=0.9)
    gate.announce(10.0)
    results = []
    waiter = threading.Thread(target=lambda: results.append(gate.step_aside(10.0)))
    waiter.start()
    assert _poll(lambda: gate.holds == 1)
    gate.passed()
    waiter.join(10)
    assert results == [True] and gate.hold_timeouts == 0


def test_close_releases_waiters_and_ends_all_holds():
    gate = ScanGate(guard_s=0.001, max_hold_s=0.9)
    gate.announce(10.0)
    waiter = threading.Thread(target=gate.step_aside, args=(10.0,))
    waiter.start()
    assert _poll(lambda: gate.holds == 1)
    gate.close()
    waiter.join(10)
    assert not waiter.is_alive()
    assert not gate.should_step_aside(1e9)


@pytest.mark.parametrize(
    ("guard", "hold"), [(-0.001, 0.003), (1.0, 0.003), (0.001, 0.0), (0.001, 2.0)]
)
def test_gate_refuses_nonsense_times(guard, hold):
    with pytest.raises(ValueError, match="ScanGate"):
        ScanGate(guard, hold)


def test_default_guard_is_capped_by_the_period():
    assert guard_for_period(10) == pytest.approx(0.0007)
    assert guard_for_period(2) == pytest.approx(0.00014)  # 7 % of a short period


# -- SCHED_FIFO --------------------------------------------------------------------------------


def test_rt_priority_from_the_environment():
    assert rt_priority_from_env({}) == 0
    assert rt_priority_from_env({RT_PRIORITY_ENV: " 20 "}) == 20
    with pytest.raises(ValueError, match=f"{RT_PRIORITY_ENV}='high': not an integer"):
        rt_priority_from_env({RT_PRIORITY_ENV: "high"})
    with pytest.raises(ValueError, match=f"{RT_PRIORITY_ENV}=100: SCHED_FIFO priorities"):
        rt_priority_from_env({RT_PRIORITY_ENV: "100"})


def test_promotion_reports_grant_and_refusal_without_raising():
    asked = []
    assert promote_current_thread(20, asked.append) == (True, "SCHED_FIFO 20")
    assert asked == [20]

    def refuse(priority: int) -> None:
        raise PermissionError(1, "Operation not permitted")

    granted, text = promote_current_thread(20, refuse)
    assert not granted and text == "SCHED_OTHER (SCHED_FIFO 20 refused: Operation not permitted)"
    assert promote_current_thread(0, refuse) == (False, "SCHED_OTHER (rt_priority 0)")


# -- the runner --------------------------------------------------------------------------------


class _Clock:
    """Fake monotonic ns clock: the start read, then each scan's deadline exactly (0, 10,
    20 ... ms), so the runner never waits."""

    def __init__(self) -> None:
        self.reads = 0

    def __call__(self) -> int:
        self.reads += 1
        return max(0, self.reads - 2) * 10_000_000


class _GateWatcher:
    """I/O provider that records the gate as each scan sees it, and stops after n scans."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.seen: list[tuple[float, int]] = []
        self.runner: RealtimeRunner | None = None
        self.done = threading.Event()

    def read_inputs(self, ix, iw, now_ms):
        gate = self.runner.gate
        self.seen.append((gate.due, gate.scans))
        if len(self.seen) >= self.n:
            self.runner._stop.set()
            self.done.set()

    def write_outputs(self, qx, qw, now_ms):
        pass


def test_runner_announces_each_deadline_and_passes_the_gate_after_each_scan():
    io = _GateWatcher(4)
    rt = Runtime(compile_text(PROGRAM, "rt.ld"), RuntimeConfig(period_ms=10), io=io)
    granted = []
    runner = RealtimeRunner(
        rt,
        clock_ns=_Clock(),
        switch_interval=None,
        rt_priority=7,
        promote=lambda p: (granted.append(p) or False, "SCHED_OTHER (test refusal)"),
    )
    io.runner = runner
    runner.start()
    assert runner.scheduling == "SCHED_OTHER (test refusal)" and granted == [7]
    assert io.done.wait(10)
    runner.stop()
    assert runner.error is None
    # during scan k the gate shows scan k's deadline and k scans passed before it
    assert [round(due, 6) for due, _ in io.seen] == [0.0, 0.01, 0.02, 0.03]
    assert rt.stats.missed == 0 and list(rt.stats.late_ms)[:4] == [0.0] * 4
    assert [passed for _, passed in io.seen] == [0, 1, 2, 3]
    assert runner.gate.scans >= 4 and runner.gate.due == math.inf  # closed at stop


def test_runner_takes_the_priority_from_the_environment(monkeypatch):
    monkeypatch.setenv(RT_PRIORITY_ENV, "15")
    rt = Runtime(compile_text(PROGRAM, "rt.ld"))
    assert RealtimeRunner(rt).rt_priority == 15
    assert RealtimeRunner(rt, rt_priority=0).rt_priority == 0
    monkeypatch.setenv(RT_PRIORITY_ENV, "-1")
    with pytest.raises(ValueError, match="SCHED_FIFO priorities"):
        RealtimeRunner(rt)


# -- the Modbus face ---------------------------------------------------------------------------


class _FakeGate:
    def __init__(self, step_aside_at: float) -> None:
        self.step_aside_at = step_aside_at
        self.calls: list[float] = []

    def step_aside(self, now: float) -> bool:
        self.calls.append(now)
        return True


class _Transport:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.sent.append(data)

    def get_extra_info(self, key: str):
        return ("127.0.0.1", 40000)

    def close(self) -> None:
        pass


@pytest.mark.parametrize(("step_aside_at", "steps"), [(math.inf, 0), (-math.inf, 2)])
def test_face_steps_aside_before_answering_when_the_gate_says_a_scan_is_due(step_aside_at, steps):
    size = ImageSize(ix=8, qx=8, mx=8, iw=8, qw=8, mw=8)
    snap = ProcessImage(size).snapshot(1)
    gate = _FakeGate(step_aside_at)
    face = ModbusFace(lambda: snap, None, size, port=0, scan_gate=gate)  # type: ignore[arg-type]

    async def serve() -> list[bytes]:
        conn = _Connection(face)
        transport = _Transport()
        conn.connection_made(transport)
        conn.data_received(struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, 2))
        conn.data_received(struct.pack(">HHHBBHH", 2, 0, 6, 1, 1, 0, 8))
        return transport.sent

    sent = asyncio.run(serve())
    assert len(sent) == 2  # answered either way
    assert len(gate.calls) == steps


def test_face_thread_priority_granted_refused_and_checked(monkeypatch):
    from plc.runtime import realtime

    size = ImageSize(ix=8, qx=8, mx=8, iw=8, qw=8, mw=8)
    snap = ProcessImage(size).snapshot(1)
    asked = []
    monkeypatch.setattr(realtime, "_set_fifo", asked.append)
    face = ModbusFace(lambda: snap, None, size, port=0)  # type: ignore[arg-type]
    face.start_in_thread(rt_priority=9)
    face.stop_thread()
    assert face.thread_scheduling == "SCHED_FIFO 9"
    assert asked == [9]

    def refuse(priority: int) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime, "_set_fifo", refuse)
    face = ModbusFace(lambda: snap, None, size, port=0)  # type: ignore[arg-type]
    face.start_in_thread(rt_priority=9)
    try:
        assert face.thread_scheduling == (
            "SCHED_OTHER (SCHED_FIFO 9 refused: Operation not permitted)"
        )
        sock = socket.create_connection(("127.0.0.1", face.bound_port), timeout=5)
        with sock:
            sock.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, 1))
            assert sock.recv(64) == struct.pack(">HHHBBBh", 1, 0, 5, 1, 3, 2, 0)  # serves anyway
    finally:
        face.stop_thread()
    with pytest.raises(ValueError, match="rt_priority 100 outside 0..99"):
        ModbusFace(lambda: snap, None, size, port=0).start_in_thread(rt_priority=100)  # type: ignore[arg-type]
