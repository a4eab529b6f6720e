"""One complete simulated CNC machine: controller + axes (CiA 402 over CAN) + soft-PLC.

Per IPO cycle (`step`): scheduled faults due now are applied, the controller takes the
axes' feedback and the PLC's last published signals and returns targets, an axis command,
NC->PLC signals and its status; the axis layer runs the command and one cycle (RPDOs, SYNC,
drive plants, TPDOs); every `plc.period / ipo` cycles the PLC scans at the same virtual time.
Nothing here reads the wall clock: in lockstep the same scenario gives the same trace and
candump byte for byte. `cnc.machine.runner.RealtimeRunner` paces `step` to the wall clock.
"""

from __future__ import annotations

import dataclasses
import queue
from collections import deque
from collections.abc import Callable
from typing import TextIO

from cnc.machine.axes import CanopenAxes, IdealAxes
from cnc.machine.contour import contour_error
from cnc.machine.contract import CommandRefused, CycleInputs, controller_class
from cnc.machine.faults import FaultSchedule, FaultSpec, parse_fault_spec
from cnc.machine.records import EventLog, TraceWriter
from cnc.machine_data import (
    counters_file,
    load,
    load_part_count,
    save,
    save_part_count,
    state_file,
)
from cnc.program_memory import ProgramMemory
from cnc.status import Alarm, CanBusLoad, MachineStatus
from plc.machine_io import machine_plc
from plc.runtime import RuntimeConfig

PANEL_BUTTONS = ("PanelCycleStart", "PanelFeedHold", "PanelReset")
_UNSET = object()


#: the declared epoch of lockstep timestamps: 2000-01-01T00:00:00Z. A virtual stream starts
#: there, at machine time 0, so it can never be mistaken for a real one (cf. a controller whose
#: clock was never set) and two lockstep runs give byte-identical SHDR streams.
LOCKSTEP_EPOCH = 946_684_800.0


class Machine:
    """A machine built from a `cnc.config.MachineConfig`.

    Parameters
    ----------
    config: the machine's configuration (`builtin_machine("mill3")`, `load_machine_config`).
    name: the machine's name (CAN channel, event texts).
    ideal: ideal axes instead of CiA 402 drives on a CAN bus.
    controller_factory: `(config, memory) -> controller`; default `cnc.controller.Controller`.
    faults: fault specs (`cnc.machine.faults`) as text or `FaultSpec`, scheduled in machine time.
    trace: a text stream for the per-cycle CSV trace (`TraceWriter`), or None.
    candump: a text stream for the CAN frames in candump log format, or None.
    event_log_path: JSONL file for the event log (the ring is always kept).
    shdr_every: publish the status to the SHDR face every n IPO cycles (default: each scan).
    epoch: in lockstep, SHDR timestamps are `epoch + machine time` (default
        `LOCKSTEP_EPOCH`, 2000-01-01T00:00:00Z: byte-identical streams, and a date no real
        observation carries). A realtime runner sets `wall_clock` (time.time): each
        timestamp is then the wall clock (UTC) at publish, whatever the machine's pace.
    state_dir: the machine's state directory: its machine data (tools, offsets, kept
        parameters) is loaded from `<state_dir>/<name>.machine-data.json` when the file
        exists (else the configuration's `machine_data` section) and saved there atomically
        whenever it changed and no program is in cycle, and at close; its part counter is
        kept in `<state_dir>/<name>.counters.json`, written at each count before any face
        reports it.
    machine_data: a cnc.machine_data.MachineData to start with instead of the
        configuration's `machine_data` section (a saved file in state_dir still wins).
    """

    def __init__(
        self,
        config,
        name: str = "machine",
        *,
        ideal: bool = False,
        controller_factory: Callable | None = None,
        faults=(),
        trace: TextIO | None = None,
        candump: TextIO | None = None,
        event_log_path: str | None = None,
        event_capacity: int = 10_000,
        shdr_every: int | None = None,
        epoch: float | None = None,
        substep: float | None = None,
        state_dir: str | None = None,
        machine_data=None,
    ) -> None:
        self.config = config
        self.name = name
        self.ipo_s = config.ipo_cycle_ms / 1000.0
        self.plc_period_ms = config.plc.period_ms
        ratio = self.plc_period_ms / config.ipo_cycle_ms
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"plc.period_ms {self.plc_period_ms} is not a multiple of ipo_cycle_ms "
                f"{config.ipo_cycle_ms}"
            )
        self.plc_every = round(ratio)
        self.shdr_every = shdr_every or self.plc_every
        self.epoch = LOCKSTEP_EPOCH if epoch is None else epoch
        #: set by a realtime runner: SHDR timestamps from this clock instead of epoch + t
        self.wall_clock: Callable[[], float] | None = None
        self.axis_names = tuple(config.axes)
        self.events = EventLog(event_capacity, event_log_path)
        self.schedule = FaultSchedule(
            [
                f if isinstance(f, FaultSpec) else parse_fault_spec(f, self.axis_names)
                for f in faults
            ]
        )
        self.memory = ProgramMemory(config.program_memory_bytes)
        factory = controller_factory or controller_class()
        if machine_data is not None:  # a given setup instead of the configuration's
            self.controller = factory(config, self.memory, machine_data=machine_data)
        else:
            self.controller = factory(config, self.memory)
        #: kept for the faces: the OPC UA face's certificate and trust list live under it
        self.state_dir = state_dir
        self.machine_data_file = None
        self._md_saved = -1
        md = getattr(self.controller, "machine_data", None)
        if state_dir is not None and md is not None:
            self.machine_data_file = state_file(state_dir, name)
            if self.machine_data_file.exists():
                md.replace_with(load(self.machine_data_file))
            self.save_machine_data()
        # The part counter, kept like a control keeps it over a power cycle: a part finished
        # just before the process died is still counted when it starts again, so the host
        # credits it once and never has it made a second time.
        self.counters_file = None
        self._count_saved = -1
        if state_dir is not None and hasattr(self.controller, "part_count"):
            self.counters_file = counters_file(state_dir, name)
            self.controller.part_count = self._count_saved = load_part_count(self.counters_file)
        self.axes = (
            IdealAxes(config)
            if ideal
            else CanopenAxes(config, name, candump=candump, substep=substep)
        )
        program = config.plc.program
        self.plc, self.io = machine_plc(
            RuntimeConfig(
                period_ms=self.plc_period_ms,
                watchdog_ms=config.plc.watchdog_ms,
                debounce_samples=config.plc.debounce_samples,
            ),
            program_path=program,
            m_functions=config.plc.m_functions,
        )
        # The scan watchdog and scan-time figures take the scan thread's CPU time (the
        # Runtime's default), in lockstep as in realtime: a busy host that deschedules the
        # machine mid-scan has not made the PLC overrun, while a scan that really takes too
        # long still trips it. (Machine time would read 0: it stands still during a scan.)
        self.trace = TraceWriter(trace, self.axis_names) if trace is not None else None
        self.cycle = 0
        self.t = 0.0
        self._sequence_s = 0.0  # virtual time spent in blocking drive sequences (homing...)
        self._next_scan_ms = 0
        self._release_after_scan: list[str] = []
        self._scan_until(0.0)
        self._plc_in = self.io.nc.outputs()
        self._inbox: queue.SimpleQueue = queue.SimpleQueue()  # callables from face threads
        self.face_alarms: list[Alarm] = []  # raised by faces (DNC), cleared by a reset
        self.status: MachineStatus = getattr(self.controller, "status", None) or MachineStatus()
        self.last_targets: dict[str, float] = {}
        self._prev_targets: dict[str, float] = {}
        self._prev_homed: dict[str, bool] = {}
        self._nc_sent: dict[str, int | bool] = {}
        self.max_following_error = dict.fromkeys(self.axis_names, 0.0)
        self.max_contour_error = 0.0
        self._path: deque = deque(maxlen=512)
        self._alarm_keys: set = set()
        self.shdr = None  # set by the faces
        self.opcua = None  # set by the faces
        self.faces = None

    # ------------------------------------------------------------------ the lockstep loop
    def step(self, n_cycles: int = 1) -> MachineStatus:
        """Run `n_cycles` IPO cycles; returns the last status."""
        for _ in range(n_cycles):
            self._one_cycle()
        return self.status

    def run_until(self, predicate: Callable[[Machine], bool], max_s: float) -> bool:
        """Step until `predicate(machine)` holds (True) or `max_s` of machine time pass."""
        end = self.t + max_s
        while not predicate(self):
            if self.t >= end:
                return False
            self._one_cycle()
        return True

    def service(self) -> None:
        """Run what the faces handed over (`call_soon`) without stepping (a paused clock)."""
        while not self._inbox.empty():
            self._inbox.get_nowait()()

    def _one_cycle(self) -> None:
        while not self._inbox.empty():
            self._inbox.get_nowait()()
        for spec in self.schedule.due(self.t):
            self.inject(spec)
        fb = self.axes.feedback()
        out = self.controller.cycle(CycleInputs(self.t, self._plc_in, fb))
        if self.counters_file is not None and self.controller.part_count != self._count_saved:
            # on disk before any face shows it: a count the host has seen is never lost
            self.save_part_count()
        nc, sent = self.io.nc, self._nc_sent
        for name, value in out.plc.items():
            if sent.get(name, _UNSET) != value:  # the signal table check is not free
                nc.set(name, value)
                sent[name] = value
        extra = self.axes.apply(out, self.ipo_s) or 0.0
        self.cycle += 1
        self._sequence_s += extra
        self.t = self.cycle * self.ipo_s + self._sequence_s
        self._scan_until(self.t)
        status = out.status if out.status is not None else self.status
        self.status = status
        self._prev_targets = self.last_targets
        self.last_targets = dict(out.targets) or self.last_targets
        self._measure(fb, status)
        if self.trace is not None:
            self.trace.row(self.t, self.last_targets, fb.actual, status.line)
        self._watch_alarms(status)
        if self.cycle % self.shdr_every == 0 and (self.shdr is not None or self.opcua is not None):
            full, ts = self.full_status(), self.timestamp()
            if self.shdr is not None:
                self.shdr.publish(full, ts)
            if self.opcua is not None:
                self.opcua.publish(full, ts)  # a reference store: never waits on a client
        if self.machine_data_file is not None and self.cycle % self.plc_every == 0:
            md = self.controller.machine_data
            if md.revision != self._md_saved and not self.controller.in_cycle:
                self.save_machine_data()

    def save_machine_data(self) -> None:
        """Write the machine data to the state directory now (atomically), if it changed."""
        md = getattr(self.controller, "machine_data", None)
        if self.machine_data_file is None or md is None or md.revision == self._md_saved:
            return
        save(self.machine_data_file, md)
        self._md_saved = md.revision

    def save_part_count(self) -> None:
        """Write the part counter to the state directory now (atomically), if it changed."""
        count = self.controller.part_count
        if self.counters_file is None or count == self._count_saved:
            return
        save_part_count(self.counters_file, count)
        self._count_saved = count

    def timestamp(self) -> float:
        """Seconds since the Unix epoch (UTC) for what the machine reports now: the wall
        clock under a realtime runner, the declared epoch plus machine time in lockstep."""
        clock = self.wall_clock
        return clock() if clock is not None else self.epoch + self.t

    def _scan_until(self, t: float) -> None:
        now_ms = t * 1000.0 + 1e-6
        while self._next_scan_ms <= now_ms:
            self.plc.scan(self._next_scan_ms)
            self._next_scan_ms += self.plc_period_ms
            self._plc_in = self.io.nc.outputs()
            for button in self._release_after_scan:
                self.io.release(button)
            self._release_after_scan.clear()

    def _measure(self, fb, status: MachineStatus) -> None:
        """Maximum following error per axis; contour error = distance of the actual position
        from the commanded path (the polyline of setpoints) while a program is ACTIVE."""
        prev = self._prev_targets
        homed_now, homed_before = fb.homed, self._prev_homed
        self._prev_homed = dict(homed_now)
        for axis in self.axis_names:
            fe = fb.following_error.get(axis)
            if fe is None:  # not on the bus: commanded (sent last cycle) - actual
                # (not in the cycle homing changed the frame: last cycle's target was in
                # the old one, up to the whole travel away)
                rehomed = homed_now.get(axis) != homed_before.get(axis)
                fe = (
                    prev.get(axis, 0.0) - fb.actual.get(axis, 0.0)
                    if fb.enabled and not rehomed
                    else 0.0
                )
            if abs(fe) > self.max_following_error[axis]:
                self.max_following_error[axis] = abs(fe)
        if status.execution != "ACTIVE" or not fb.enabled:
            self._path.clear()
            return
        names, targets, fb_actual = self.axis_names, self.last_targets, fb.actual
        point = tuple([targets.get(a, 0.0) for a in names])
        path = self._path
        if not path or path[-1] != point:
            path.append(point)
        best = contour_error(path, tuple([fb_actual.get(a, 0.0) for a in names]))
        if best > self.max_contour_error:
            self.max_contour_error = best

    def _watch_alarms(self, status: MachineStatus) -> None:
        if not status.alarms and not self._alarm_keys:
            return
        keys = {(a.number, a.source, a.axis) for a in status.alarms}
        if keys == self._alarm_keys:
            return
        for a in status.alarms:
            if (a.number, a.source, a.axis) not in self._alarm_keys:
                self.events.add(
                    self.t,
                    "alarm",
                    f"{a.source} {a.number}: {a.text}",
                    {"number": a.number, "source": a.source, "axis": a.axis, "line": status.line},
                )
        for key in self._alarm_keys - keys:
            self.events.add(self.t, "alarm_cleared", f"{key[1]} {key[0]}")
        self._alarm_keys = keys

    # ------------------------------------------------------------------ status
    def full_status(self) -> MachineStatus:
        """The controller's status plus what only the machine knows (bus load, PLC scan time,
        alarms raised by the faces)."""
        s = self.status
        load = self.axes.bus_load
        extra: dict = {}
        if load is not None:
            extra["can_bus_load"] = CanBusLoad(load.mean * 100.0, load.peak * 100.0)
        if self.face_alarms:
            extra["alarms"] = (*s.alarms, *self.face_alarms)
        scans = self.plc.stats.exec_us
        if scans:
            extra["plc_scan_time_ms"] = scans[-1] / 1000.0  # the last scan, as a PLC HMI shows
        return dataclasses.replace(s, **extra)

    @property
    def alarms(self) -> tuple[Alarm, ...]:
        return (*self.status.alarms, *self.face_alarms)

    # ------------------------------------------------------------------ operator and cell
    def command(self, name: str, **args):
        """An operator/cell command to the controller; `CommandRefused` says why not."""
        try:
            result = self.controller.command(name, **args)
        except Exception as exc:
            if isinstance(exc, CommandRefused) or type(exc).__name__ == "CommandRefused":
                self.events.add(self.t, "refused", f"{name}: {exc}", {"args": _plain(args)})
            raise
        self.events.add(self.t, "command", name, {"args": _plain(args)} if args else None)
        if name in ("reset", "alarm_reset"):
            self.face_alarms.clear()
        return result

    def power_on(self, *, home: bool = True, max_s: float = 60.0) -> None:
        """The operator's power-on routine at the machine, in lockstep before a runner
        starts: wait for the drives, reference every axis in the homing sequence (REF mode,
        home), then AUTO. RuntimeError (with the alarms) when homing does not finish."""
        if home:
            self.command("mode", mode="REF")
            end = self.t + max_s
            while True:  # the drives come up over the first PLC scans: home once enabled
                try:
                    self.command("home")
                    break
                except Exception:
                    if self.t >= end:
                        raise
                    self.step(self.plc_every)
            ctl = self.controller
            if not self.run_until(
                lambda m: all(ctl.referenced.values()) and not getattr(ctl, "homing", False),
                max_s,
            ):
                raise RuntimeError(
                    f"{self.name}: homing did not finish in {max_s} s (alarms {self.alarms})"
                )
        self.command("mode", mode="AUTO")
        self.step(self.plc_every)

    def load_program(self, text: str, number: int | None = None) -> int:
        """Store a program (tape text) in memory; returns its O number.

        `cnc.program_memory.MemoryFull` (its message suggests drip-feed) when it does not fit.
        """
        # deferred: the DNC port's module brings asyncio and ssl, which a lockstep machine
        # does not need
        from cnc.faces.dnc_port import program_number, stored_text

        lines = [ln.rstrip("\r") for ln in text.splitlines()]
        lines = [ln for ln in lines if ln.strip() not in ("%", "")]
        if number is None:
            number = program_number(lines) or 1
        self.memory.store(number, stored_text(lines))
        self.events.add(self.t, "program_stored", f"O{number:04d}")
        return number

    def inject(self, spec: FaultSpec | str) -> None:
        """Apply a fault now (drive, bus or PLC input); ValueError names what is wrong."""
        if isinstance(spec, str):
            spec = parse_fault_spec(spec, self.axis_names)
        if spec.target == "plc":
            self.io.inject(spec.kind)
        else:
            self.axes.inject(spec)
        self.events.add(self.t, "fault_injected", str(spec))

    def clear_fault(self, spec: FaultSpec | str) -> None:
        if isinstance(spec, str):
            spec = parse_fault_spec(spec, self.axis_names)
        if spec.target == "plc":
            self.io.clear(spec.kind)
        else:
            self.axes.clear(spec)
        self.events.add(self.t, "fault_cleared", str(spec))

    def open_door(self) -> bool:
        """The operator pulls the guard door: False (refused) while it is locked."""
        ok = self.io.open_door()
        self.events.add(self.t, "operator", "door opened" if ok else "door locked: not opened")
        return ok

    def close_door(self) -> None:
        self.io.close_door()
        self.events.add(self.t, "operator", "door closed")

    def press_estop(self) -> None:
        self.io.press_estop()
        self.events.add(self.t, "operator", "E-stop button pressed")

    def release_estop(self) -> None:
        self.io.release_estop()
        self.events.add(self.t, "operator", "E-stop button released")

    def press(self, button: str) -> None:
        """A panel push-button pressed for one PLC scan."""
        if button not in PANEL_BUTTONS:
            raise ValueError(f"unknown panel button {button!r}; one of {', '.join(PANEL_BUTTONS)}")
        self.io.press(button)
        self._release_after_scan.append(button)
        self.events.add(self.t, "operator", f"{button} pressed")

    def call_soon(self, fn: Callable[[], None]) -> None:
        """Run `fn` on the machine's thread at the start of the next cycle (faces use it)."""
        self._inbox.put(fn)

    def raise_face_alarm(
        self, number: int, text: str, source: str = "DNC", severity: str = "FAULT"
    ) -> None:
        """Thread-safe: an alarm raised by a face (DNC parity error, overrun...), or with
        severity WARNING a message that leaves the machine fit to run (a program load cut
        off); both stay in the alarm list until a reset."""
        alarm = Alarm(number, text, source=source, severity=severity, time=self.t)

        def add() -> None:
            self.face_alarms.append(alarm)
            self.events.add(
                self.t,
                "alarm" if severity == "FAULT" else "message",
                f"{source} {number}: {text}",
                {"number": number, "source": source, "axis": None, "line": 0},
            )

        self.call_soon(add)

    # ------------------------------------------------------------------ faces, lifetime
    def start_faces(
        self, *, simulation: bool | None = None, dnc_parity: bool = False, opcua_users=None
    ):
        """Start the faces (DNC, Modbus, SHDR, simulation if enabled) on one LoopThread.

        `dnc_parity`: ISO 7-bit even parity on the DNC port (a parity error rejects the
        program and raises alarm 2001). `opcua_users`: `(user, password) -> role` for a
        secured OPC UA face (docs/opcua.md)."""
        # deferred: the faces (asyncio servers, Modbus) load only when a machine starts them
        from cnc.machine.faces import MachineFaces

        self.faces = MachineFaces(self, simulation=simulation, dnc_parity=dnc_parity)
        self.faces.opcua_authenticate = opcua_users
        self.faces.start()
        return self.faces

    def close(self) -> None:
        try:
            self.save_machine_data()
        except OSError as err:  # a full disk must not keep the machine from closing
            self.events.add(self.t, "machine_data", f"cannot save machine data: {err}")
        if self.faces is not None:
            self.faces.stop()
            self.faces = None
        self.axes.close()
        self.events.close()


def _plain(args: dict) -> dict:
    return {
        k: (v if isinstance(v, int | float | str | bool | None) else repr(v))
        for k, v in args.items()
    }
