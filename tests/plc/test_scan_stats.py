"""Scan statistics keep a fixed window: memory taken at once, never grown by scans."""

from __future__ import annotations

import tracemalloc

import pytest

from plc.runtime.stats import ScanStats, Window


@pytest.mark.parametrize(
    ("size", "pushed", "kept"),
    [
        (3, [], []),
        (3, [1.0], [1.0]),
        (3, [1.0, 2.0, 3.0], [1.0, 2.0, 3.0]),
        (3, [1.0, 2.0, 3.0, 4.0], [2.0, 3.0, 4.0]),
        (3, [float(i) for i in range(10)], [7.0, 8.0, 9.0]),
        (1, [5.0, 6.0], [6.0]),
    ],
)
def test_window_keeps_the_last_samples_oldest_first(size, pushed, kept):
    w = Window(size)
    for v in pushed:
        w.append(v)
    assert list(w) == kept and len(w) == len(kept) and bool(w) == bool(kept)
    for i in range(len(kept)):
        assert w[i] == kept[i] and w[-1 - i] == kept[-1 - i]
    with pytest.raises(IndexError, match="out of range"):
        w[len(kept)]


def test_window_refuses_an_empty_size():
    with pytest.raises(ValueError, match="window must be >= 1 scan, got 0"):
        Window(0)


def test_summary_p99_over_the_window_only():
    stats = ScanStats(window=100)
    for i in range(1000):  # the first 900 fall out of the window
        stats.record(exec_us=float(i), late_ms=0.0, overrun=False)
    e = stats.execution()
    assert (e.count, e.min, e.max) == (1000, 0.0, 999.0)
    assert e.p99 == 999.0 and e.mean == pytest.approx(499.5)
    assert list(stats.exec_us)[0] == 900.0 and stats.exec_us[-1] == 999.0


def test_memory_is_taken_at_once_and_does_not_grow_with_scans():
    # a deque(maxlen=window) of floats grew ~32 bytes a scan until full: 2 x 10 000 scans
    # were ~640 kB per machine, filling for up to an hour on a realtime cell
    tracemalloc.start()
    try:
        stats = ScanStats(window=10_000)
        stats.record(exec_us=1.0, late_ms=0.0, overrun=False)
        before, _ = tracemalloc.get_traced_memory()
        for i in range(25_000):
            stats.record(exec_us=100.0 + i * 1e-3, late_ms=i * 1e-4, overrun=False)
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    grown = after - before
    assert grown < 4_096, f"scan statistics grew {grown} bytes over 25 000 scans"
