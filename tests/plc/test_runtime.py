"""Scan runtime in lockstep: scan order, debounce, forcing, write-once, RUN/STOP, retain,
online change, watchdog (fake scan-time clock), program faults, statistics."""

from __future__ import annotations

import itertools

import pytest

from plc.image import ImageSize, Write
from plc.ladder import compile_text
from plc.runtime import (
    ALARM_IO_FAULT,
    ALARM_PROGRAM_FAULT,
    ALARM_WATCHDOG,
    ALARM_WRITE_REJECTED,
    Debounce,
    FileRetainStore,
    MemoryRetainStore,
    Mode,
    ProgramSwapError,
    Runtime,
    RuntimeConfig,
    SimulatedIO,
)

PROGRAM = """
PROGRAM cell
TAG Start : BOOL AT %IX0.0
TAG Stop  : BOOL AT %IX0.1
TAG Motor : BOOL AT %QX0.0
TAG Lamp  : BOOL AT %QX0.1
TAG Count : INT AT %MW0
TAG Parts : COUNTER RETAIN
TAG Hours : INT RETAIN
TAG Temp  : INT
TAG Run   : TIMER
BST XIC Start NXB XIC Motor BND XIO Stop OTE Motor
XIC Motor TON Run 100
XIC Start CTU Parts 1000
XIC Motor ADD Count 1 Count
XIC Motor ADD Hours 1 Hours
XIC Motor ADD Temp 1 Temp
XIC Run.DN OTE Lamp
"""


def make(config: RuntimeConfig | None = None, **kw) -> Runtime:
    return Runtime(compile_text(PROGRAM, "cell.ld"), config, **kw)


def test_scan_publishes_a_snapshot_per_scan():
    rt = make()
    assert rt.snapshot.scan == 0
    rt.image.ix[0] = True
    snap = rt.scan(0)
    assert snap.scan == 1 and snap.qx[0] == 1 and rt.snapshot is snap
    rt.image.ix[0] = False
    rt.scan(10)
    assert snap.qx[0] == 1 and rt.snapshot.scan == 2 and rt.read("Motor") is True


def test_write_queue_batches_applied_whole_at_scan_start():
    rt = make()
    rt.writes.put([Write("IX", 0, (1,)), Write("MW", 0, (500, 0xFFFF))])
    rt.scan(0)
    assert rt.snapshot.qx[0] == 1 and rt.snapshot.mw[0] == 501 and rt.snapshot.mw[1] == -1
    # a batch with one bad write is dropped whole and raises an alarm
    rt.writes.put([Write("MW", 5, (7,)), Write("MW", 1023, (1, 2))])
    rt.scan(10)
    assert rt.snapshot.mw[5] == 0 and ALARM_WRITE_REJECTED in rt.alarms
    rt.acknowledge(ALARM_WRITE_REJECTED)
    assert not rt.alarms


def test_debounce_change_counts_after_four_identical_samples():
    io = SimulatedIO()
    rt = make(RuntimeConfig(debounce_samples=4), io=io)
    io.set_input(0, True)
    seen = []
    for k in range(5):
        rt.scan(k * 10)
        seen.append(rt.read("Start"))
    assert seen == [False, False, False, True, True]
    # a glitch of 3 samples never reaches the logic
    io.set_input(1, True)
    for k in range(5, 8):
        rt.scan(k * 10)
    io.set_input(1, False)
    for k in range(8, 12):
        rt.scan(k * 10)
        assert rt.read("Stop") is False
    assert io.qx[0] is True  # outputs reach the provider


@pytest.mark.parametrize(
    "samples, pattern, expected",
    [
        (4, [1, 1, 1, 1, 1], [0, 0, 0, 1, 1]),
        (4, [1, 1, 0, 1, 1, 1, 1], [0, 0, 0, 0, 0, 0, 1]),
        (4, [1, 1, 1, 1, 0, 0, 0, 1, 0, 0, 0, 0], [0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1, 0]),
        (1, [1, 0, 1], [1, 0, 1]),
    ],
)
def test_debounce_table(samples, pattern, expected):
    f = Debounce(samples)
    stable = [False, False]
    out = []
    for bit in pattern:
        f.filter([bool(bit), False], stable)
        out.append(int(stable[0]))
    assert out == expected


def test_debounce_rejects_zero_samples():
    with pytest.raises(ValueError):
        Debounce(0)


def test_forcing_inputs_before_and_outputs_after_the_logic():
    io = SimulatedIO()
    rt = make(io=io)
    rt.force("Start", True)  # forced input: the logic sees it although the field says 0
    rt.scan(0)
    assert rt.read("Motor") is True and rt.read("Start") is True
    rt.force("%QX0.0", False)  # forced output wins over the logic
    rt.scan(10)
    assert rt.read("Motor") is False and io.qx[0] is False
    assert rt.forces == {("IX", 0): True, ("QX", 0): False}
    rt.unforce("Motor")
    rt.scan(20)
    assert rt.read("Motor") is True
    rt.force("Count", 7)  # forced marker word: pinned before and after the logic
    rt.scan(30)
    assert rt.read("Count") == 7
    rt.force("Temp", -3)  # internal tag
    rt.scan(40)
    assert rt.read("Temp") == -3
    rt.unforce_all()
    rt.scan(50)
    assert rt.read("Count") == 8 and rt.read("Temp") == -2 and rt.forces == {}


def test_write_once_is_applied_once_and_logic_may_change_it():
    rt = make()
    rt.write_once("Count", 100)
    rt.write_once("%IX0.0", True)
    rt.scan(0)
    assert rt.read("Count") == 101  # written, then the logic added 1
    rt.scan(10)
    assert rt.read("Count") == 102


def test_unknown_names_are_refused():
    rt = make()
    with pytest.raises(KeyError):
        rt.force("Nope", 1)
    with pytest.raises(KeyError):
        rt.write_once("%IX0.9", 1)
    with pytest.raises(KeyError):
        rt.read("Run.XX")
    with pytest.raises(KeyError):
        rt.force("Parts", 1)


def test_run_stop_and_safe_outputs():
    rt = make(RuntimeConfig(safe_qx={1: True}))
    rt.image.ix[0] = True
    rt.scan(0)
    assert rt.read("Motor") is True
    rt.stop()
    assert rt.mode is Mode.STOP
    rt.scan(10)
    assert rt.read("Motor") is False and rt.read("Lamp") is True  # safe state
    temp = rt.read("Temp")
    rt.scan(20)
    assert rt.read("Temp") == temp  # logic not solved in STOP
    rt.run()
    rt.scan(30)
    assert rt.read("Motor") is True and rt.read("Temp") == temp + 1


def test_stop_can_hold_outputs():
    rt = make(RuntimeConfig(stop_outputs="hold", start_mode=Mode.STOP))
    rt.image.qx[0] = True
    rt.scan(0)
    assert rt.read("Motor") is True and rt.mode is Mode.STOP


class FakeClock:
    """Scan-time measurement under test control: each scan takes `cost_ns`."""

    def __init__(self) -> None:
        self.t = 0
        self.cost_ns = 1_000
        self.calls = itertools.count()

    def __call__(self) -> int:
        if next(self.calls) % 2:
            self.t += self.cost_ns
        return self.t


def test_watchdog_trips_on_a_slow_scan():
    clock = FakeClock()
    io = SimulatedIO()
    rt = make(RuntimeConfig(period_ms=10, watchdog_ms=25, safe_qx={1: True}), io=io, clock_ns=clock)
    io.set_input(0, True)
    rt.scan(0)
    assert rt.read("Motor") is True and rt.mode is Mode.RUN
    clock.cost_ns = 20_000_000  # 20 ms: an overrun of the period, still under the watchdog
    rt.scan(10)
    assert rt.mode is Mode.RUN and rt.stats.overruns == 1
    clock.cost_ns = 30_000_000  # 30 ms > 25 ms
    rt.scan(20)
    assert rt.mode is Mode.FAULT
    assert rt.read("Motor") is False and rt.read("Lamp") is True and io.qx[0] is False
    alarm = rt.alarms[ALARM_WATCHDOG]
    assert alarm.fatal and "30.000 ms" in alarm.detail and alarm.scan == 3
    clock.cost_ns = 1_000
    rt.force("%QX0.0", True)  # forces cannot re-energize outputs in FAULT
    rt.scan(30)
    assert rt.read("Motor") is False
    with pytest.raises(RuntimeError):
        rt.run()
    rt.unforce_all()
    rt.reset_fault()
    assert rt.mode is Mode.STOP and ALARM_WATCHDOG not in rt.alarms
    rt.run()
    rt.scan(40)
    assert rt.read("Motor") is True


def test_watchdog_on_a_late_start_when_configured():
    rt = make(RuntimeConfig(period_ms=10, stall_periods=3))
    rt.scan(0, late_ms=29.0)
    assert rt.mode is Mode.RUN
    rt.scan(40, late_ms=31.0)
    assert rt.mode is Mode.FAULT and "late" in rt.alarms[ALARM_WATCHDOG].detail


def test_program_fault_points_at_the_rung():
    rt = make()
    rt.scan(0)
    bad = compile_text(PROGRAM + "XIC Motor OTE Lamp\n", "cell.ld")
    rt.load_program(bad)
    rt.scan(10)
    # break the program's slot list on purpose: the TON rung reads a missing slot
    del rt._v[-1:]
    rt.image.ix[0] = True
    rt.scan(20)
    assert rt.mode is Mode.FAULT
    detail = rt.alarms[ALARM_PROGRAM_FAULT].detail
    assert detail.startswith("cell.ld:") and "rung" in detail and "IndexError" in detail


def test_retentive_data_survives_a_restart(tmp_path):
    store = FileRetainStore(str(tmp_path / "retain.json"))
    cfg = RuntimeConfig(retain_mw=(0, 1), retain_save_ms=0)
    rt = make(cfg, retain_store=store)
    rt.image.ix[0] = True
    for k in range(5):
        rt.scan(k * 10)
        rt.image.ix[0] = k % 2 == 0
    assert rt.read("Parts.ACC") == 2 and rt.read("Hours") == 5 and rt.read("Count") == 5
    rt.close()
    again = make(cfg, retain_store=store)
    assert again.read("Parts.ACC") == 2 and again.read("Hours") == 5 and again.read("Count") == 5
    assert again.read("Temp") == 0  # not retentive
    assert again.read("Run.ACC") == 0


def test_retain_saved_periodically_in_virtual_time():
    store = MemoryRetainStore()
    rt = make(RuntimeConfig(retain_save_ms=100), retain_store=store)
    rt.image.ix[0] = True
    for k in range(10):
        rt.scan(k * 10)
    assert store.saves == 0
    rt.scan(100)
    assert store.saves == 1 and store.data["tags"]["HOURS"] == 11
    rt.stop()
    assert store.saves == 1  # nothing changed since the last save
    rt.run()
    rt.scan(110)
    rt.stop()
    assert store.saves == 2 and store.data["tags"]["HOURS"] == 12


def test_online_change_keeps_data_and_misses_no_scan():
    rt = make(RuntimeConfig(retain_mw=(0, 4)))
    rt.image.ix[0] = True
    for k in range(8):
        rt.scan(k * 10)
    assert rt.read("Run.ACC") == 70 and rt.read("Parts.ACC") == 1 and rt.read("Temp") == 8
    # new version: one rung more, a new tag, and Temp is now a TIMER (type change: reinit)
    new_text = PROGRAM.replace("TAG Temp  : INT", "TAG Temp : TIMER\nTAG Extra : INT")
    new_text = new_text.replace("XIC Motor ADD Temp 1 Temp\n", "XIC Motor ADD Extra 2 Extra\n")
    new_text += "XIC Motor OTE %QX0.5\n"
    new = compile_text(new_text, "cell.ld")
    scans = [rt.snapshot.scan]
    rt.load_program(new)
    assert rt.program is not new  # staged, not yet swapped
    for k in range(8, 12):
        snap = rt.scan(k * 10)
        scans.append(snap.scan)
    assert scans == [8, 9, 10, 11, 12] and rt.program is new and rt.program_changes == 1
    assert rt.read("Run.ACC") == 100 and rt.read("Run.DN") is True  # timer kept running
    assert rt.read("Lamp") is True and rt.read("%QX0.5") is True
    assert rt.read("Parts.ACC") == 1 and rt.read("Hours") == 12 and rt.read("Count") == 12
    assert rt.read("Extra") == 8 and rt.read("Temp.ACC") == 0


def test_online_change_refuses_a_program_that_does_not_fit():
    rt = Runtime(compile_text(PROGRAM, "cell.ld"), image=None)
    big = compile_text("XIC %IX0.0 OTE %QX0.0\n", "big.ld", size=ImageSize(ix=4096))
    with pytest.raises(ProgramSwapError):
        rt.load_program(big)


def test_statistics():
    clock = FakeClock()
    rt = make(RuntimeConfig(period_ms=10), clock_ns=clock)
    for k, cost in enumerate([1000, 3000, 2000, 12_000_000]):
        clock.cost_ns = cost
        rt.scan(k * 10, late_ms=k * 0.5)
    e, la = rt.stats.execution(), rt.stats.lateness()
    assert (e.count, e.min, e.max) == (4, 1.0, 12000.0) and e.p99 == 12000.0
    assert la.max == 1.5 and la.mean == pytest.approx(0.75) and rt.stats.overruns == 1
    assert rt.status()["stats"]["overruns"] == 1


def test_timers_use_virtual_time_only():
    rt = make()
    rt.image.ix[0] = True
    rt.scan(1_000_000)
    rt.scan(1_000_099)
    assert rt.read("Lamp") is False
    rt.scan(1_000_100)
    assert rt.read("Lamp") is True


class BrokenIO(SimulatedIO):
    def __init__(self) -> None:
        super().__init__()
        self.fail = False

    def read_inputs(self, ix, iw, now_ms):
        if self.fail:
            raise OSError("bus off")
        super().read_inputs(ix, iw, now_ms)


def test_io_failure_faults_the_plc_with_safe_outputs():
    io = BrokenIO()
    rt = make(io=io)
    io.set_input(0, True)
    rt.scan(0)
    assert rt.read("Motor") is True
    io.fail = True
    rt.scan(10)
    assert rt.mode is Mode.FAULT and rt.read("Motor") is False
    assert "bus off" in rt.alarms[ALARM_IO_FAULT].detail
    rt.scan(20)  # in FAULT the broken provider is not read again
    assert rt.mode is Mode.FAULT


ALARM_PROGRAM = """
TAG Req : BOOL AT %IX0.0
TAG Ack : BOOL AT %IX0.1
TAG Reset : BOOL AT %IX0.2
TAG Tmo : TIMER
TAG AlmSpin : BOOL
ALARM 1012 AlmSpin "spindle not at speed within 2 s"   // text may hold // too
ALARM 1013 %MX0.0 "lube low"
XIC Req XIO Ack TON Tmo 2000
XIC Tmo.DN OTL AlmSpin
XIC Reset OTU AlmSpin
"""


def test_program_alarms_follow_their_bit():
    rt = Runtime(compile_text(ALARM_PROGRAM, "alm.ld"))
    rt.write_once("Req", True)
    rt.scan(0)
    rt.scan(1990)
    assert 1012 not in rt.alarms
    rt.scan(2000)
    alarm = rt.alarms[1012]
    assert alarm.text == "spindle not at speed within 2 s"
    assert str(alarm) == "PLC 1012: spindle not at speed within 2 s" and not alarm.fatal
    rt.write_once("Reset", True)
    rt.scan(2010)
    assert 1012 not in rt.alarms and [a.number for a in rt.alarm_log] == [1012]
    rt.write_once("%MX0.0", True)
    rt.scan(2020)
    assert rt.alarms[1013].text == "lube low"


@pytest.mark.parametrize(
    "decl, fragment",
    [
        ('ALARM 9100 %MX0.0 "x"', "outside 1..8999"),
        ('ALARM 5 %MW0 "x"', "a word where a bit"),
        ("ALARM 5 %MX0.0", 'expected: ALARM number tag "text"'),
        ('ALARM 5 %MX0.0 "a"\nALARM 5 %MX0.1 "b"', "alarm 5 already declared on line 1"),
    ],
)
def test_alarm_declaration_errors(decl, fragment):
    from plc.ladder import check_text

    diags = check_text(decl + "\nXIC %IX0.0 OTE %QX0.0\n", "a.ld")
    assert any(fragment in d.message for d in diags), [str(d) for d in diags]


def test_written_values_take_the_target_type():
    rt = make()
    rt.write_once("Temp", 70000)  # INT tag: wraps like a Modbus register
    rt.write_once("Run.ACC", 70000)  # timer ms: not an INT
    rt.write_once("%MX0.3", 5)
    rt.stop()
    rt.scan(0)
    assert rt.read("Temp") == 4464 and rt.read("Run.ACC") == 70000 and rt.read("%MX0.3") is True


def test_simulated_io_of_another_size_keeps_the_image_size():
    from plc.image import ImageSize

    io = SimulatedIO(ImageSize(ix=8, iw=2, qx=8, qw=2))
    rt = make(io=io)
    io.set_input(0, True)
    rt.scan(0)
    assert len(rt.image.ix) == 1024 and rt.read("Motor") is True and io.qx[0] is True


class _CollectingIO(SimulatedIO):
    """Field I/O whose read runs a full garbage collection over a large heap, as happens to
    whichever thread of a busy process crosses the collector's threshold."""

    def __init__(self) -> None:
        super().__init__()
        self.heap = [[i] for i in range(400_000)]  # containers the collector must traverse

    def read_inputs(self, ix, iw, now_ms):
        import gc

        gc.collect()
        super().read_inputs(ix, iw, now_ms)


class _BusyIO(SimulatedIO):
    def read_inputs(self, ix, iw, now_ms):
        import time

        end = time.thread_time_ns() + 5_000_000  # 5 ms of this thread's CPU
        while time.thread_time_ns() < end:
            pass
        super().read_inputs(ix, iw, now_ms)


def test_a_garbage_collection_in_the_scan_thread_is_not_the_programs_time():
    """A full collection (tens of ms of the scan thread's CPU) does not trip a 2 ms
    watchdog on the default clock; 5 ms of real work in the scan does."""
    import gc
    import time

    io = _CollectingIO()
    t0 = time.thread_time_ns()
    gc.collect()
    assert time.thread_time_ns() - t0 > 2_000_000  # the premise: a collection costs > 2 ms
    rt = make(RuntimeConfig(period_ms=10, watchdog_ms=2), io=io)
    for n in range(3):
        rt.scan(10 * n)
    assert rt.mode is Mode.RUN and ALARM_WATCHDOG not in rt.alarms
    busy = make(RuntimeConfig(period_ms=10, watchdog_ms=2), io=_BusyIO())
    busy.scan(0)
    assert busy.mode is Mode.FAULT and ALARM_WATCHDOG in busy.alarms
