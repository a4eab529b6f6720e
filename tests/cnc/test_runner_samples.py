"""The realtime runner's lateness and work samples: the last N kept in a fixed array."""

from __future__ import annotations

from cnc.machine.runner import SampleRing


def test_keeps_the_last_samples_in_order_of_arrival_until_full():
    ring = SampleRing(4)
    assert len(ring) == 0 and list(ring) == []
    for x in (1.0, 2.0, 3.0):
        ring.append(x)
    assert len(ring) == 3 and list(ring) == [1.0, 2.0, 3.0]


def test_overwrites_the_oldest_once_full_and_never_grows():
    ring = SampleRing(4)
    size_before = ring._values.buffer_info()[1]
    for x in range(10):
        ring.append(float(x))
    assert len(ring) == 4
    assert sorted(ring) == [6.0, 7.0, 8.0, 9.0]
    assert ring._values.buffer_info()[1] == size_before == 4


def test_runner_summary_reads_the_ring():
    from cnc.machine.runner import RealtimeRunner

    runner = RealtimeRunner.__new__(RealtimeRunner)
    runner.lateness_s, runner.work_s = SampleRing(8), SampleRing(8)
    for x in (0.001, 0.002, 0.003):
        runner.lateness_s.append(x)
        runner.work_s.append(x / 2)
    runner.cycles, runner.late_cycles, runner.skipped_slots = 3, 0, 0
    runner.error, runner.scheduling, runner.old_collections = None, "SCHED_OTHER", 0
    s = runner.summary()
    assert s["lateness_ms_max"] == 3.0 and s["lateness_ms_p50"] == 2.0
    assert s["work_ms_max"] == 1.5
