"""The scan core: one `Runtime` per PLC, stepped by `scan(now_ms)` in virtual time.

Scan cycle (one call of `scan`):
    1. online change: a staged program is swapped in (data of same-named tags kept)
    2. queued writes (WriteQueue batches, each whole), then write-once values
    3. latch inputs from the I/O provider, through the debounce filter if configured
    4. forced inputs (and forced markers/internal tags)
    5. solve: the compiled program, in RUN only
    6. forced outputs (and forced markers/internal tags again)
    7. watchdog: execution time over the limit -> safe outputs, FAULT, alarm
    8. outputs to the I/O provider, statistics, publish the Snapshot

The core reads no clock of its own: time comes in as `now_ms`; the execution time is taken
with the injectable `clock_ns` (a test passes a fake one to make a scan look slow). The
default is the scan thread's CPU time, not the wall clock: a simulation process that the OS
deschedules for 100 ms on a loaded host has not overrun its scan, and a lockstep run must not
trip the watchdog (and so change its outcome) because of what else the host is doing; the
CPU time the scan thread spends in Python's garbage collector is subtracted too (gc_pause). Late
starts are the realtime shell's `late_ms` (`stall_periods`).
"""

from __future__ import annotations

import enum
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from plc.errors import PlcError
from plc.image import BIT_AREAS, ImageSize, ProcessImage, Snapshot, Write, WriteQueue, _to_int
from plc.ladder.compiler import CompiledProgram, TagInfo
from plc.ladder.instructions import MEMBER_ALIASES
from plc.ladder.symbols import (
    SLOT_DIV_ZERO,
    SLOT_FAULT_RUNG,
    SLOT_FIRST_SCAN,
    SLOT_OVERFLOW,
    parse_address,
)
from plc.runtime import gc_pause
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
from plc.runtime.io import Debounce, IOProvider
from plc.runtime.retain import RetainStore
from plc.runtime.stats import ScanStats


class Mode(enum.StrEnum):
    STOP = "STOP"
    RUN = "RUN"
    FAULT = "FAULT"


@dataclass(slots=True)
class RuntimeConfig:
    """How a PLC scans. Times in ms."""

    period_ms: int = 10
    watchdog_ms: float | None = None  # execution-time limit; None = 10 x period
    stall_periods: float | None = None  # also trip when a scan starts this many periods late
    debounce_samples: int = 0  # 0 = off; 4 = the GE 1050 filter (a change counts after 4)
    safe_qx: dict[int, bool] = field(default_factory=dict)  # safe state: these %QX, others 0
    safe_clear_qw: bool = False  # safe state also zeroes every %QW
    stop_outputs: str = "safe"  # in STOP: "safe" (safe state) or "hold" (keep last outputs)
    retain_mw: tuple[int, int] | None = None  # (first %MW, count) kept over a restart
    retain_save_ms: int = 1000  # virtual ms between saves of retentive data (0 = on stop only)
    start_mode: Mode = Mode.RUN
    stats_window: int = 10_000

    @property
    def watchdog_limit_ms(self) -> float:
        return self.watchdog_ms if self.watchdog_ms is not None else 10.0 * self.period_ms


Target = tuple[str, int]  # (area, index); area "V" = the program's slot list


class ProgramSwapError(PlcError, ValueError):
    pass


class Runtime:
    """One soft-PLC: process image, compiled program, modes, forcing, alarms, retain."""

    def __init__(
        self,
        program: CompiledProgram,
        config: RuntimeConfig | None = None,
        *,
        image: ProcessImage | None = None,
        io: IOProvider | None = None,
        retain_store: RetainStore | None = None,
        writes: WriteQueue | None = None,
        clock_ns: Callable[[], int] = time.thread_time_ns,
    ) -> None:
        self.config = config or RuntimeConfig()
        self.image = image or ProcessImage(program.size)
        _check_fits(program, self.image.size)
        self.program = program
        self.writes = writes or WriteQueue()
        self.io = io
        self.retain_store = retain_store
        self.clock_ns = clock_ns
        # garbage collections are not the program's time on the thread CPU clock (gc_pause);
        # a test's own clock has no collector to subtract
        self._gc_ns: Callable[[], int] = _no_gc
        if clock_ns is time.thread_time_ns:
            gc_pause.install()
            self._gc_ns = gc_pause.thread_gc_ns
        self.stats = ScanStats(self.config.stats_window)
        self.mode = self.config.start_mode
        self.scan_count = 0
        self.program_changes = 0
        self.alarms: dict[int, Alarm] = {}  # active, by number
        self.alarm_log: deque[Alarm] = deque(maxlen=1000)
        self._v: list = list(program.v_init)
        self._first = True
        self._last_ms: int | None = None
        self._pending: CompiledProgram | None = None
        self._once: list[tuple[Target, int]] = []
        self._control = threading.Lock()
        self._force_in: tuple[tuple[Target, int], ...] = ()
        self._force_out: tuple[tuple[Target, int], ...] = ()
        self._forces: dict[Target, int] = {}
        size = self.image.size
        self._raw_ix = [False] * size.ix
        self._raw_iw = [0] * size.iw
        self._debounce = (
            Debounce(self.config.debounce_samples) if self.config.debounce_samples else None
        )
        self._last_retain: dict | None = None
        self._bits_cache: dict[str, tuple[list, bytes]] = {}
        self._next_retain_ms: int | None = None
        if retain_store is not None:
            self._restore_retain()
        self.snapshot: Snapshot = self.image.snapshot(0)
        # the program and its slot values of the last published scan, replaced as one
        # object so a reader on another thread never pairs one program with another's slots
        self._pub: tuple[CompiledProgram, tuple] = (program, tuple(self._v))

    # -- the scan ----------------------------------------------------------------------------
    def scan(self, now_ms: int, late_ms: float = 0.0) -> Snapshot:
        """Run one scan at virtual time `now_ms` and return the published Snapshot."""
        t0 = self.clock_ns()
        gc0 = self._gc_ns()
        cfg = self.config
        dt = 0 if self._last_ms is None else max(0, now_ms - self._last_ms)
        self._last_ms = now_ms
        self.scan_count += 1
        if self._pending is not None:
            self._swap()
        img = self.image
        self._apply_writes()
        if self.io is not None and self.mode is not Mode.FAULT:
            try:
                self.io.read_inputs(self._raw_ix, self._raw_iw, now_ms)
            except Exception as exc:  # a broken field bus stops the PLC, not the process
                self._fault(ALARM_IO_FAULT, f"read_inputs: {type(exc).__name__}: {exc}", now_ms)
            else:
                if self._debounce is not None:
                    self._debounce.filter(self._raw_ix, img.ix)
                else:
                    img.ix[:] = self._raw_ix
                img.iw[:] = self._raw_iw
        v = self._v
        for (area, index), value in self._force_in:
            (v if area == "V" else img.area(area))[index] = value
        if self.mode is Mode.RUN:
            v[SLOT_FIRST_SCAN] = self._first
            v[SLOT_OVERFLOW] = v[SLOT_DIV_ZERO] = False
            self._first = False
            try:
                self.program.scan_fn(img.ix, img.qx, img.mx, img.iw, img.qw, img.mw, v, dt)
            except Exception as exc:  # a fault in the logic stops the PLC, never the process
                rung = self.program.locate(exc)
                where = self.program.describe_rung(rung) if rung else "unknown rung"
                self._fault(ALARM_PROGRAM_FAULT, f"{where}: {type(exc).__name__}: {exc}", now_ms)
            if v[SLOT_DIV_ZERO]:
                self.raise_alarm(ALARM_DIV_ZERO, f"rung {v[SLOT_FAULT_RUNG]}", now_ms)
            if self.program.alarms:
                self._program_alarms(now_ms)
        elif self.mode is Mode.STOP and cfg.stop_outputs == "safe":
            self._safe_outputs()
        for (area, index), value in self._force_out:
            (v if area == "V" else img.area(area))[index] = value
        exec_ms = (self.clock_ns() - t0 - (self._gc_ns() - gc0)) / 1e6
        if self.mode is Mode.RUN:
            if exec_ms > cfg.watchdog_limit_ms:
                self._fault(
                    ALARM_WATCHDOG,
                    f"scan took {exec_ms:.3f} ms, limit {cfg.watchdog_limit_ms:g} ms",
                    now_ms,
                )
            elif cfg.stall_periods is not None and late_ms > cfg.stall_periods * cfg.period_ms:
                self._fault(ALARM_WATCHDOG, f"scan started {late_ms:.1f} ms late", now_ms)
        if self.mode is Mode.FAULT:
            self._safe_outputs()  # safety wins over forces
        if self.io is not None:
            try:
                self.io.write_outputs(img.qx, img.qw, now_ms)
            except Exception as exc:
                self._fault(ALARM_IO_FAULT, f"write_outputs: {type(exc).__name__}: {exc}", now_ms)
        self.stats.record(exec_ms * 1000.0, late_ms, exec_ms > cfg.period_ms)
        snap = self._publish()
        self.snapshot = snap
        self._pub = (self.program, tuple(v))
        if self.retain_store is not None and cfg.retain_save_ms > 0:
            if self._next_retain_ms is None:
                self._next_retain_ms = now_ms + cfg.retain_save_ms
            elif now_ms >= self._next_retain_ms:
                self._next_retain_ms = now_ms + cfg.retain_save_ms
                self.save_retain(now_ms)
        return snap

    def _program_alarms(self, now_ms: int) -> None:
        """ALARM declarations: active while their bit is 1, cleared when it drops."""
        img, v, active = self.image, self._v, self.alarms
        for a in self.program.alarms:
            on = (v if a.area == "V" else img.area(a.area))[a.index]
            if on and a.number not in active:
                self.raise_alarm(a.number, text=a.text, now_ms=now_ms)
            elif not on and a.number in active and a.number < 9000:
                del active[a.number]

    def _publish(self) -> Snapshot:
        """The scan's Snapshot (same content as `ProcessImage.snapshot`). Converting a bit
        list to bytes is the costly part of publishing, so an unchanged bit area reuses the
        previous scan's bytes."""
        img, cache = self.image, self._bits_cache
        bits = []
        for area in ("ix", "qx", "mx"):
            lst = getattr(img, area)
            hit = cache.get(area)
            if hit is None or hit[0] != lst:
                hit = (lst[:], bytes(lst))
                cache[area] = hit
            bits.append(hit[1])
        return Snapshot(
            self.scan_count, bits[0], bits[1], bits[2], tuple(img.iw), tuple(img.qw), tuple(img.mw)
        )

    def _apply_writes(self) -> None:
        img = self.image
        for batch in self.writes.drain():
            bad = next((w for w in batch if not _fits(img, w)), None)
            if bad is not None:
                self.raise_alarm(
                    ALARM_WRITE_REJECTED,
                    f"%{bad.area}{bad.index} x{len(bad.values)}",
                    self._last_ms or 0,
                )
                continue
            for w in batch:
                img.apply(w)
        if self._once:
            with self._control:
                once, self._once = self._once, []
            for (area, index), value in once:
                (self._v if area == "V" else img.area(area))[index] = value

    def _safe_outputs(self) -> None:
        qx = self.image.qx
        qx[:] = [False] * len(qx)
        for index, value in self.config.safe_qx.items():
            qx[index] = bool(value)
        if self.config.safe_clear_qw:
            qw = self.image.qw
            qw[:] = [0] * len(qw)

    def _fault(self, number: int, detail: str, now_ms: int) -> None:
        self.mode = Mode.FAULT
        self._safe_outputs()
        self.raise_alarm(number, detail, now_ms, fatal=True)

    # -- modes and alarms --------------------------------------------------------------------
    def run(self) -> None:
        """STOP -> RUN (the next scan has S_FIRST_SCAN set). Refused in FAULT."""
        if self.mode is Mode.FAULT:
            raise RuntimeError("PLC is in FAULT: reset_fault() first")
        if self.mode is Mode.STOP:
            self._first = True
        self.mode = Mode.RUN

    def stop(self) -> None:
        """RUN -> STOP: logic no longer solved; outputs per `stop_outputs`; retain saved."""
        if self.mode is Mode.RUN:
            self.mode = Mode.STOP
        self.save_retain()

    def reset_fault(self) -> None:
        """FAULT -> STOP and clear the fatal alarms (the operator's explicit reset)."""
        if self.mode is Mode.FAULT:
            self.mode = Mode.STOP
        for number in [n for n, a in self.alarms.items() if a.fatal]:
            del self.alarms[number]

    def raise_alarm(
        self,
        number: int,
        detail: str = "",
        now_ms: int = 0,
        fatal: bool = False,
        text: str | None = None,
    ) -> Alarm:
        """Raise a numbered alarm (kept active until acknowledged); logged every time."""
        alarm = Alarm(
            number,
            text or ALARM_TEXT.get(number, f"alarm {number}"),
            detail,
            self.scan_count,
            now_ms,
            fatal,
        )
        self.alarm_log.append(alarm)
        self.alarms.setdefault(number, alarm)
        return alarm

    def acknowledge(self, number: int) -> None:
        """Clear a non-fatal alarm. Fatal ones clear with `reset_fault`."""
        alarm = self.alarms.get(number)
        if alarm is not None and not alarm.fatal:
            del self.alarms[number]

    # -- forcing, write-once, reading ----------------------------------------------------------
    def resolve(self, name: str, program: CompiledProgram | None = None) -> Target:
        """An IEC address (`%QX0.1`) or a tag (`Motor`, `T1.ACC`) -> (area, index)."""
        if name.startswith("%"):
            parsed = parse_address(name)
            if isinstance(parsed, str):
                raise KeyError(parsed)
            area, index = parsed
            if index >= self.image.size.of(area):
                raise KeyError(f"{name} is outside the image")
            return area, index
        base, _, member = name.partition(".")
        info = (program or self.program).tag(base)
        if member:
            m = MEMBER_ALIASES.get(member.upper(), member.upper())
            if m not in info.members:
                raise KeyError(f"{info.type} tag {info.name!r} has no member .{member}")
            return "V", info.members[m]
        if info.members:
            raise KeyError(f"{info.type} tag {info.name!r}: name a member (.DN, .ACC ...)")
        assert info.area is not None and info.index is not None
        return info.area, info.index

    def _value_for(self, target: Target, value: int | bool) -> int | bool:
        area, index = target
        if area in BIT_AREAS or (area == "V" and isinstance(self.program.v_init[index], bool)):
            return bool(value)
        if area == "V" and index in self._ms_slots():
            return max(0, int(value))  # timer .ACC/.PRE hold ms, wider than INT
        return _to_int(int(value))

    def _ms_slots(self) -> set[int]:
        return {
            i
            for info in self.program.tags.values()
            if info.type == "TIMER"
            for m, i in info.members.items()
            if m in ("ACC", "PRE")
        }

    def force(self, name: str, value: int | bool) -> None:
        """Pin a value: inputs before the logic, outputs after it, markers/tags both times."""
        target = self.resolve(name)
        with self._control:
            self._forces[target] = self._value_for(target, value)
            self._rebuild_forces()

    def unforce(self, name: str) -> None:
        target = self.resolve(name)
        with self._control:
            self._forces.pop(target, None)
            self._rebuild_forces()

    def unforce_all(self) -> None:
        with self._control:
            self._forces.clear()
            self._rebuild_forces()

    @property
    def forces(self) -> dict[Target, int]:
        return dict(self._forces)

    def _rebuild_forces(self) -> None:
        items = tuple(self._forces.items())
        self._force_in = tuple(i for i in items if i[0][0] not in ("QX", "QW"))
        self._force_out = tuple(i for i in items if i[0][0] not in ("IX", "IW"))

    def write_once(self, name: str, value: int | bool) -> None:
        """Set a value once at the start of the next scan; the logic may then change it."""
        target = self.resolve(name)
        with self._control:
            self._once.append((target, self._value_for(target, value)))

    def read(self, name: str) -> int | bool | dict:
        """A value as published by the last scan (safe from any thread)."""
        program, values = self._pub
        snapshot = self.snapshot
        if not name.startswith("%") and "." not in name:
            info = program.tag(name)
            if info.members:
                return {m: values[i] for m, i in info.members.items()}
        area, index = self.resolve(name, program)
        if area == "V":
            return values[index]
        value = snapshot.area(area)[index]
        return bool(value) if area in BIT_AREAS else value

    # -- online change -----------------------------------------------------------------------
    def load_program(self, program: CompiledProgram) -> None:
        """Stage an online change: the program is swapped in at the start of the next scan,
        keeping the values of same-named tags of the same type (retentive data, timers,
        counters, latches). Raises ProgramSwapError if it does not fit the image."""
        try:
            _check_fits(program, self.image.size)
        except ValueError as exc:
            raise ProgramSwapError(str(exc)) from None
        with self._control:
            self._pending = program

    def _swap(self) -> None:
        with self._control:
            new, self._pending = self._pending, None
        assert new is not None
        old_v, old = self._v, self.program
        v = list(new.v_init)
        for key, info in new.tags.items():
            prev = old.tags.get(key)
            if prev is None or prev.type != info.type:
                continue
            for a, b in _slot_pairs(prev, info):
                v[b] = old_v[a]
        # forces on internal tags refer to slots of the old program: drop those
        with self._control:
            self._forces = {t: val for t, val in self._forces.items() if t[0] != "V"}
            self._rebuild_forces()
        self._v = v
        self.program = new
        self.program_changes += 1

    # -- retentive memory ----------------------------------------------------------------------
    def retain_data(self) -> dict:
        """The data that survives a restart: RETAIN tags by name and the %MW range."""
        tags: dict[str, object] = {}
        v = self._v
        for info in self.program.tags.values():
            if not info.retain:
                continue
            if info.members:
                tags[info.name.upper()] = {m: v[i] for m, i in info.members.items()}
            elif info.area == "V":
                tags[info.name.upper()] = v[info.index]
            else:
                tags[info.name.upper()] = self.image.area(info.area)[info.index]
        data: dict = {"program": self.program.name, "tags": tags}
        if self.config.retain_mw is not None:
            start, count = self.config.retain_mw
            data["mw"] = {"start": start, "values": list(self.image.mw[start : start + count])}
        return data

    def save_retain(self, now_ms: int | None = None) -> None:
        if self.retain_store is None:
            return
        data = self.retain_data()
        if data == self._last_retain:
            return
        try:
            self.retain_store.save(data)
            self._last_retain = data
        except OSError as exc:
            self.raise_alarm(ALARM_RETAIN_STORE, f"save: {exc}", now_ms or 0)

    def _restore_retain(self) -> None:
        assert self.retain_store is not None
        try:
            data = self.retain_store.load()
        except (OSError, ValueError) as exc:
            self.raise_alarm(ALARM_RETAIN_STORE, f"load: {exc}")
            return
        if not data:
            return
        v = self._v
        for name, value in (data.get("tags") or {}).items():
            info = self.program.tags.get(name)
            if info is None or not info.retain:
                continue
            if info.members and isinstance(value, dict):
                for m, i in info.members.items():
                    if m in value:
                        v[i] = value[m]
            elif not info.members and not isinstance(value, dict):
                if info.area == "V":
                    v[info.index] = value
                else:
                    self.image.area(info.area)[info.index] = value
        mw = data.get("mw")
        if mw and self.config.retain_mw is not None:
            start, count = self.config.retain_mw
            saved_start, values = mw["start"], mw["values"]
            for k, value in enumerate(values):
                idx = saved_start + k
                if start <= idx < start + count and idx < len(self.image.mw):
                    self.image.mw[idx] = _to_int(value)
        self._last_retain = data

    def close(self) -> None:
        """Save retentive data (call at shutdown)."""
        self.save_retain()

    def status(self) -> dict:
        return {
            "mode": str(self.mode),
            "program": self.program.name,
            "program_hash": self.program.hash,
            "scan": self.scan_count,
            "program_changes": self.program_changes,
            "alarms": [str(a) for a in self.alarms.values()],
            "stats": self.stats.as_dict(),
        }


def _no_gc() -> int:
    return 0


def _slot_pairs(prev: TagInfo, new: TagInfo):
    if new.members:
        for m, b in new.members.items():
            if m == "PRE":
                continue  # the new program's preset operand decides the preset
            a = prev.members.get(m)
            if a is not None:
                yield a, b
    elif prev.area == "V" and new.area == "V":
        assert prev.index is not None and new.index is not None
        yield prev.index, new.index


def _fits(img: ProcessImage, w: Write) -> bool:
    try:
        n = len(img.area(w.area))
    except AttributeError:
        return False
    return w.index >= 0 and w.index + len(w.values) <= n


def _check_fits(program: CompiledProgram, size: ImageSize) -> None:
    for area in ("ix", "qx", "mx", "iw", "qw", "mw"):
        if getattr(program.size, area) > getattr(size, area):
            raise ValueError(
                f"program {program.name!r} was compiled for %{area.upper()} of "
                f"{getattr(program.size, area)}, the image has {getattr(size, area)}"
            )
