"""CPU time each thread spends in Python's garbage collector, for the scan watchdog.

The watchdog measures a scan's execution on the scan thread's CPU clock so that a loaded host
does not trip it (plc.runtime.core). A cyclic garbage collection is the other thing that is
not the PLC program's doing: it runs in whichever thread crosses the allocation threshold,
and in a process that also holds a DNC host, an API and other machines a full collection
costs 50-300 ms of that thread's CPU. Charged to a 10 ms scan it tripped the 100 ms watchdog
(alarm 9001, outputs off, axis enable withdrawn in the middle of a cut). A real soft-PLC has
no collector in its scan; the simulation's is subtracted, as a descheduled thread's time is.
"""

from __future__ import annotations

import gc
import threading
import time

_started: dict[int, int] = {}  # thread id -> thread CPU ns when its collection started
_spent: dict[int, int] = {}  # thread id -> CPU ns spent collecting, cumulative
_installed = False
_lock = threading.Lock()


def _on_gc(phase: str, info: dict) -> None:
    tid = threading.get_ident()
    now = time.thread_time_ns()
    if phase == "start":
        _started[tid] = now
    else:
        began = _started.pop(tid, None)
        if began is not None:
            _spent[tid] = _spent.get(tid, 0) + (now - began)


def install() -> None:
    """Start accounting (idempotent; one callback for the whole process)."""
    global _installed
    with _lock:
        if not _installed:
            gc.callbacks.append(_on_gc)
            _installed = True


def thread_gc_ns() -> int:
    """CPU ns the calling thread has spent in garbage collections since `install()`."""
    return _spent.get(threading.get_ident(), 0)
