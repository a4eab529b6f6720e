"""Scan runtime: a pure scan core (`Runtime.scan(now_ms)`) and a realtime shell thread.

Public API::

    Runtime(program, config=RuntimeConfig(), *, image=None, io=None, retain_store=None,
            writes=None, clock_ns=time.thread_time_ns)
        .scan(now_ms, late_ms=0.0) -> Snapshot      one scan in virtual time
        .snapshot / .read(name) / .image / .writes (WriteQueue)
        .run() / .stop() / .reset_fault() / .mode (Mode.RUN|STOP|FAULT)
        .force(name, v) / .unforce(name) / .unforce_all() / .write_once(name, v)
        .load_program(compiled)                     online change at the next scan
        .alarms / .alarm_log / .raise_alarm() / .acknowledge(n)
        .stats (ScanStats) / .status() / .save_retain() / .close()
    RealtimeRunner(runtime, period_ms=None, *, rt_priority=None, gate_guard_s=None)
        .start() / .stop() / .gate (ScanGate) / .scheduling
    ScanGate: the next scan's deadline, for threads that step aside before it
    SimulatedIO, Debounce, MemoryRetainStore, FileRetainStore
"""

from plc.runtime.alarms import (
    ALARM_DIV_ZERO,
    ALARM_IO_FAULT,
    ALARM_PROGRAM_FAULT,
    ALARM_RETAIN_STORE,
    ALARM_TEXT,
    ALARM_WATCHDOG,
    ALARM_WRITE_REJECTED,
    Alarm,
)
from plc.runtime.core import Mode, ProgramSwapError, Runtime, RuntimeConfig
from plc.runtime.io import Debounce, IOProvider, SimulatedIO
from plc.runtime.realtime import RT_PRIORITY_ENV, ScanGate
from plc.runtime.retain import FileRetainStore, MemoryRetainStore, RetainStore
from plc.runtime.shell import RealtimeRunner
from plc.runtime.stats import ScanStats, Summary

__all__ = [
    "ALARM_DIV_ZERO",
    "ALARM_IO_FAULT",
    "ALARM_PROGRAM_FAULT",
    "ALARM_RETAIN_STORE",
    "ALARM_TEXT",
    "ALARM_WATCHDOG",
    "ALARM_WRITE_REJECTED",
    "Alarm",
    "Debounce",
    "FileRetainStore",
    "IOProvider",
    "MemoryRetainStore",
    "Mode",
    "ProgramSwapError",
    "RT_PRIORITY_ENV",
    "RealtimeRunner",
    "RetainStore",
    "Runtime",
    "ScanGate",
    "RuntimeConfig",
    "ScanStats",
    "SimulatedIO",
    "Summary",
]
