"""`Controller`: the CNC controller core, stepped once per IPO cycle.

It joins the NC kernel (interpreter -> planner/interpolator), the PLC signal table and the
axis layer: modes, homing, program execution with M/S/T handshakes, operator commands from
the API and from the PLC (one path, the same interlocks), alarms, supervision and ACC.
Pure: no clock, no I/O, no threads; `cycle(inputs)` is the only way time advances.
docs/controller.md describes the behaviour and the public API.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass

from cnc import canon
from cnc.config import MachineConfig
from cnc.controller import alarms as al
from cnc.controller.adaptive import AdaptiveLoop, CuttingModel
from cnc.controller.contract import (
    AxisFeedback,
    CommandRefused,
    CycleInputs,
    CycleOutputs,
)
from cnc.controller.handshake import Handshake
from cnc.controller.program import DripLines
from cnc.controller.tooltip import ToolTipMonitor
from cnc.errors import NcError
from cnc.faces.drip import DripBuffer
from cnc.interp import Interpreter
from cnc.interpolator import Motion
from cnc.machine_data import MachineData, MachineDataError, ToolData
from cnc.program_memory import ProgramMemory, program_number_error
from cnc.status import AxisStatus, MachineStatus, ToolTipStatus
from plc.signals import (
    AXIS_BITS,
    MODE_AUTO,
    MODE_JOG,
    MODE_MDI,
    MODE_NONE,
    MODE_REF,
    REFUSE_BAD_NUMBER,
    REFUSE_ESTOP,
    REFUSE_HOMING,
    REFUSE_NOT_ENABLED,
    REFUSE_NOT_IN_MEMORY,
    REFUSE_NOT_REF_MODE,
    REFUSE_PROGRAM_ACTIVE,
    dword_value,
    dword_words,
)

MODES = ("AUTO", "MDI", "JOG", "REF", "EDIT")
_MODE_NUMBER = {"AUTO": MODE_AUTO, "MDI": MODE_MDI, "JOG": MODE_JOG, "REF": MODE_REF}
_MODE_BY_NUMBER = {v: k for k, v in _MODE_NUMBER.items()}
_CONTROLLER_MODE = {
    "AUTO": "AUTOMATIC",
    "MDI": "MANUAL_DATA_INPUT",
    "JOG": "MANUAL",
    "REF": "MANUAL",
    "EDIT": "EDIT",
}
_AXIS_PRIORITY = {
    "none": 0,
    "enable": 1,
    "home": 2,
    "fault_reset": 3,
    "disable": 4,
    "quick_stop": 5,
}
# Execution states in which a program is active (NcInCycle; mode changes refused).
IN_CYCLE = ("ACTIVE", "INTERRUPTED", "FEED_HOLD", "PROGRAM_STOPPED", "OPTIONAL_STOP")
MDI_MAX_CHARS = 2048
EVENTS_KEPT = 1000
SYNC_AHEAD = 32  # non-motion commands queued in the planner at most
INTERP_BUDGET = 64  # canonical commands taken from the interpreter per IPO cycle


@dataclass(frozen=True)
class ControllerSettings:
    """Controller data that the machine YAML does not (yet) carry; defaults in brackets.

    home_sequence: the homing sequence, groups of axes homed together, one group after the
    other; overrides the machine YAML's `home_sequence` [that key, else for a mill: ((Z,), (X, Y)), the tool axis clear of the work first; a lathe:
    ((X,), (Z,)), the cross slide clear of the chuck first; other kinds: the tool axis Z,
    then the others together]; home_order: a flat order instead, one axis at a time
    [None: the order of home_sequence]; ferror_max_mm / ferror_min_mm: the NC's following-error limit,
    scaled with the commanded axis speed like LinuxCNC's FERROR/MIN_FERROR [5.0 / 1.0];
    jog_feed / dry_run_feed in mm/min [1000 / 3000]; enable_retry_s [1.0];
    drip_buffer_bytes [4096]; homing_start_timeout_s: the axis layer must report `homing`
    within this time of the request [1.0]."""

    home_sequence: tuple[tuple[str, ...], ...] | None = None
    home_order: tuple[str, ...] | None = None
    ferror_max_mm: float = 5.0
    ferror_min_mm: float = 1.0
    jog_feed: float = 1000.0
    dry_run_feed: float = 3000.0
    enable_retry_s: float = 1.0
    drip_buffer_bytes: int = 4096
    homing_start_timeout_s: float = 1.0


class _Run:
    """One program execution (AUTO memory program, MDI text or drip-feed)."""

    def __init__(self, kind: str, name: str, motion: Motion, interp: Interpreter, source):
        self.kind = kind  # "AUTO" | "MDI" | "DRIP"
        self.name = name  # "O1234", "MDI", "DRIP"
        self.motion = motion
        self.interp = interp
        self.source = source  # list of lines (AUTO/MDI) or DripLines
        self.gen = interp.run(source) if not isinstance(source, list) or kind != "MDI" else None
        self.cmds: deque = deque()  # MDI: interpreted up front
        self.pending = None
        self.src_done = False
        self.stop = ""  # "M0" | "M1" while stopped at a program stop
        self.aborting = ""  # "reset" | "alarm" while braking to abort
        self.syncs_out = 0
        self.steps: deque = deque()  # the current sync point's handshake steps
        self.sync = None  # the sync command being done
        self.step_started = False
        self.dwell_until = 0.0
        self.end_kind = None  # canon.StopKind when M2/M30 was reached
        self.line = 0
        self.lines_feed: dict[int, float | None] = {}  # line -> max feed mm/min (None rapid)
        self.thread_rpm: dict[int, float] = {}  # line -> the rpm its thread moves are fed for
        self.text_lines = source if isinstance(source, list) else None
        self.skip: _SkipWait | None = None  # a G31 move under way: no block is taken after it


class _SkipWait:
    """A G31 move in the motion queue: `block` its number there; `latched` the encoder
    position (X Y Z, machine mm) of the IPO cycle its skip signal came, None until then."""

    __slots__ = ("cmd", "block", "latched")

    def __init__(self, cmd: canon.SkipFeed, block: int) -> None:
        self.cmd = cmd
        self.block = block
        self.latched: tuple[float, float, float] | None = None


class Controller:
    """The CNC controller core. See docs/controller.md."""

    def __init__(
        self,
        config: MachineConfig,
        memory: ProgramMemory,
        *,
        tools=None,
        work_offsets=None,
        machine_data: MachineData | None = None,
        cutting_model: CuttingModel | None = None,
        settings: ControllerSettings | None = None,
    ) -> None:
        self.config = config
        self.params = config.params
        self.memory = memory
        # the controller's own machine data: G10 in one program is seen by the next; the
        # machine shell saves it to its state directory (cnc.machine_data.store)
        if machine_data is None:
            section = getattr(config, "machine_data", None)
            machine_data = section.initial() if section is not None else MachineData()
        self.machine_data = machine_data
        self._common_variables: dict[int, float] = {}  # Macro B #100-#199
        if tools is not None:  # an explicit table (tests, a DNC-side setup) replaces it
            machine_data.tools = {
                n: ToolData(length=o.length, radius=o.radius, x=o.x, z=o.z)
                for n, o in tools.items()
            }
        for index, xyz in (work_offsets or {}).items():
            machine_data.set_work_offset(index, xyz)
        self.cutting_model = cutting_model or CuttingModel()
        self.settings = settings or ControllerSettings()
        self.axes = tuple(config.axes)
        # a pose's components: X Y Z, then the rotary axes (cnc.params.pose_axes)
        self._pose_axes = self.params.pose_axes
        # mill5: the tool tip by forward kinematics and its deviation from the line
        self._tip = ToolTipMonitor.for_params(self.params)
        self.ipo = config.ipo_cycle_ms / 1000.0
        self.home_sequence = self._home_sequence()
        self.home_order = tuple(a for group in self.home_sequence for a in group)
        self._vmax = {a: c.max_velocity / 60.0 for a, c in config.axes.items()}
        self.acc = AdaptiveLoop()
        self._alarms = al.AlarmList()
        self._events: deque[tuple[float, str]] = deque(maxlen=EVENTS_KEPT)
        self._hs = {k: Handshake(k) for k in "MST"}
        # operator state
        self.mode = "AUTO"
        self.selected: int | None = None
        self.single_block = False
        self.optional_stop = False
        self.block_skip = False
        self.dry_run = False
        self.feed_override = 100.0
        self.rapid_override = 100.0
        self.spindle_override = 100.0  # NC side, applied to SCode
        # machine state
        self._t = 0.0
        self._cmd = {a: 0.0 for a in self.axes}  # commanded position
        self._prev_cmd: dict[str, float] | None = None
        self._prev2: dict[str, float] | None = None
        self._actual = dict(self._cmd)
        self._synced = False  # commanded taken from the first feedback
        self._ref = dict.fromkeys(self.axes, False)  # referenced by a homing run since E-stop
        self._fb: AxisFeedback | None = None
        self._plc: dict = {}
        self._plc_prev: dict = {}
        self._plc_was_ready = False  # PlcReady seen: a later drop is the PLC stopping
        self._plc_src = None
        self._ex = "READY"
        self._plc_out_key = None
        self._plc_out: dict = {}
        self._estop = False
        self._enabled = False
        self._want_enable = False
        self._enable_sent_at: float | None = None
        self._axis_cmd = "none"
        self._home_axes: tuple[str, ...] = ()
        self._homing = ""  # "" | "requested" | "running"
        self._homing_axes: tuple[str, ...] = ()  # the group homing now
        self._homing_next: deque[tuple[str, ...]] = deque()  # the groups after it
        self._homing_done: list[str] = []  # axes of this homing run referenced so far
        self._homing_since = 0.0
        # answers to the PLC's program select / zero return requests, held while the
        # request is: None, or (taken, refusal code)
        self._select_answer: tuple[bool, int] | None = None
        self._home_answer: tuple[bool, int] | None = None
        self._run: _Run | None = None
        self._final = "READY"
        self._hold = False
        self._plc_hold = False
        self._drip: DripBuffer | None = None
        self._mdi_run_pending: list[str] | None = None
        self._resetting_until = -1.0
        self._jog: dict[str, tuple[float, float, float]] = {}  # axis -> (target, feed, v)
        self._spindle_on = False
        self._spindle_rpm = 0.0
        self._coolant = (False, False)
        self.part_count = 0
        self.run_time = 0.0
        self.cutting_time = 0.0
        self.spindle_time = 0.0
        self.blocks = 0
        self.max_following_error = dict.fromkeys(self.axes, 0.0)
        self._path_v = 0.0
        self._load = 0.0
        self._rpm = 0.0
        self._spindle_phase = 0.0  # revolutions, mod 1 (an ideal encoder on the spindle)
        self._spindle_index = False  # the one-revolution signal came in the last cycle
        self._cutting = False
        # tool life: the tool M6 put in the spindle and its cutting time not yet booked
        self._life_tool = 0
        self._life_cut_s = 0.0
        self._fo_applied = -1.0
        self._ro_applied = -1.0
        self._status = MachineStatus()
        self._status_key = None
        self._start_refused = ""  # why the last cycle start was refused (until a start/select)
        self._unreferenced: tuple[str, ...] = ()
        self._was_referenced: set[str] = set()  # axes referenced at least once

    # ================================================================ public API ===========
    @property
    def alarms(self):
        """Active alarms (cnc.status.Alarm), oldest first."""
        return self._alarms.active

    @property
    def events(self) -> tuple[tuple[float, str], ...]:
        """The event log: (time s, text), the last EVENTS_KEPT entries."""
        return tuple(self._events)

    @property
    def status(self) -> MachineStatus:
        """The MachineStatus of the last cycle."""
        return self._status

    @property
    def execution(self) -> str:
        return self._execution()

    @property
    def homing(self) -> bool:
        """A homing sequence is running (one of its groups requested or homing)."""
        return bool(self._homing)

    @property
    def referenced(self) -> dict[str, bool]:
        """Per axis: homed since power-on / the last E-stop."""
        return {a: self._ref[a] and self._fb_homed(a) for a in self.axes}

    def command(self, name: str, **args) -> None:
        """Operator command; raises CommandRefused(reason) when the mode/state forbids it."""
        fn = getattr(self, f"_cmd_{name}", None)
        try:
            if fn is None:
                raise CommandRefused(f"unknown command {name!r}")
            try:
                fn(**args)
            except (TypeError, ValueError) as exc:
                raise CommandRefused(f"{name}: bad arguments ({exc})") from None
        except CommandRefused as exc:
            self._event(exc.reason)
            raise

    def drip_input(self) -> DripBuffer | None:
        """A fresh drip-feed buffer for the DNC port's DRIP (None = refused now). The drip
        program runs at the next cycle start in AUTO."""
        if self.mode != "AUTO" or self._execution() in IN_CYCLE or self._drip is not None:
            return None
        self._drip = DripBuffer(self.settings.drip_buffer_bytes)
        self._event("drip-feed armed: cycle start runs the program as it arrives")
        return self._drip

    def put_machine_data(self, what: str, doc) -> None:
        """Replace the tool table (`what` = "tools": {number: {...}}) or the offsets
        ("offsets": {work_offsets: {name: [x, y, z]}, g92: [...]}) as an operator does at
        the control's offset screen: refused (CommandRefused) while a program is in cycle,
        as a real control refuses offset input then; a bad document raises
        MachineDataError with the JSON pointer and changes nothing."""
        ex = self._execution()
        if ex in IN_CYCLE:
            raise CommandRefused(f"machine is {ex}: offsets can be changed only out of cycle")
        if what == "tools":
            new = self.machine_data.copy()
            new.set_tools_from(doc, "")
        elif what == "offsets":
            new = self.machine_data.copy()
            new.set_offsets_from(doc)
        else:
            raise MachineDataError(f"unknown machine data {what!r} (tools, offsets)")
        self.machine_data.replace_with(new)
        self._event(f"machine data: {what} changed by the operator")

    @property
    def in_cycle(self) -> bool:
        return self._execution() in IN_CYCLE

    def policy(self, op: str, number: int | None) -> str | None:
        """The DNC port's question: may `op` (READ, DELETE, PUNCH, DRIP) touch `number`?"""
        running = self._run is not None and self._run.kind == "AUTO"
        if op in ("READ", "DELETE") and running and self._run.name == f"O{number or 0:04d}":
            return f"program O{number:04d} is running"
        if op == "DRIP" and (self.mode != "AUTO" or self._execution() in IN_CYCLE):
            return f"machine is {self._execution()} in {self.mode}; DRIP needs AUTO and READY"
        return None

    # ================================================================ the IPO cycle =======
    def cycle(self, inputs: CycleInputs) -> CycleOutputs:
        """One IPO cycle: read PLC and axes, run the program, supervise, write outputs."""
        dt = self.ipo if self._fb is None else max(0.0, inputs.t - self._t)
        self._t = inputs.t
        fb = inputs.axes
        self._fb = fb
        plc_src = inputs.plc
        # between two PLC scans the PLC signals do not change: skip their edges and levels
        plc_new = plc_src is not self._plc_src and plc_src != self._plc
        self._plc_src = plc_src
        if plc_new:
            self._plc_prev, self._plc = self._plc, dict(plc_src)
        else:
            self._plc_prev = self._plc
        actual = fb.actual
        self._actual = {a: float(actual.get(a, self._cmd[a])) for a in self.axes}
        if not self._synced:
            self._cmd = dict(self._actual)
            self._synced = True
        self._supervise_axes(fb)
        if plc_new:
            self._plc_requests()
        self._manage_enable(fb)
        self._homing_step(fb)
        self._watch_reference()
        if not fb.enabled or fb.homing or self._homing:
            # drives off or homing: the command follows the actual position (no jump later)
            self._cmd = dict(self._actual)
            if self._run is not None and self._estop:
                self._abort_now("STOPPED")
        self._path_v = 0.0
        if self._run is not None:
            self._run_step(dt)
        elif self._jog:
            self._jog_step(dt)
        self._following_error(fb, dt)
        self._adaptive(dt)
        self._timers(dt)
        self._prev_cmd = dict(self._cmd)
        self._ex = self._execution()
        out_plc = self._plc_outputs()
        self._status = self._build_status()
        axis_cmd, home_axes = self._axis_cmd, self._home_axes
        self._axis_cmd, self._home_axes = "none", ()
        return CycleOutputs(
            targets=dict(self._cmd),
            axis_command=axis_cmd,
            home_axes=home_axes if axis_cmd == "home" else (),
            plc=out_plc,
            status=self._status,
        )

    def _axis(self, cmd: str, axes: tuple[str, ...] = ()) -> None:
        """Request a one-shot axis command for this cycle's (or the next) outputs; a
        stronger request wins (quick stop over disable over fault reset over home...)."""
        if _AXIS_PRIORITY[cmd] > _AXIS_PRIORITY[self._axis_cmd]:
            self._axis_cmd = cmd
            self._home_axes = axes

    # ================================================================ commands ============
    def _cmd_mode(self, mode: str) -> None:
        mode = str(mode).upper()
        if mode not in MODES:
            raise CommandRefused(f"mode {mode!r} unknown (one of {', '.join(MODES)})")
        ex = self._execution()
        if ex in IN_CYCLE:
            raise CommandRefused(f"mode change refused while {ex}")
        if self._homing:
            raise CommandRefused("mode change refused while homing")
        if mode != self.mode:
            self._jog.clear()
            self.mode = mode
            self._event(f"mode {mode}")

    def _select_refusal(self, number: int) -> tuple[int, str] | None:
        """Why program `number` cannot be selected now: (refusal code, text), or None."""
        if self._execution() in IN_CYCLE:
            return REFUSE_PROGRAM_ACTIVE, f"program select refused while {self._execution()}"
        why = program_number_error(number)
        if why is not None:
            return REFUSE_BAD_NUMBER, f"program select refused: {why}"
        if number not in self.memory:
            return REFUSE_NOT_IN_MEMORY, f"program O{number:04d} not in memory"
        return None

    def _cmd_select_program(self, number: int) -> None:
        number = int(number)
        why = self._select_refusal(number)
        if why is not None:
            raise CommandRefused(why[1])
        self.selected = number
        self._final = "READY"
        self._start_refused = ""
        self._event(f"program O{number:04d} selected")

    def _cmd_cycle_start(self) -> None:
        try:
            self._cycle_start()
        except CommandRefused as exc:
            self._start_refused = exc.reason
            raise

    def _cmd_feed_hold(self) -> None:
        ex = self._execution()
        if ex not in ("ACTIVE", "INTERRUPTED") and not self._jog:
            raise CommandRefused(f"feed hold refused: nothing is moving ({ex})")
        self._feed_hold("operator")

    def _cmd_reset(self) -> None:
        self._reset("operator")

    def _cmd_single_block(self, on: bool) -> None:
        self.single_block = bool(on)
        if self._run is not None:
            self._run.motion.set_single_block(self.single_block)

    def _cmd_optional_stop(self, on: bool) -> None:
        self.optional_stop = bool(on)

    def _cmd_block_skip(self, on: bool) -> None:
        self.block_skip = bool(on)
        if self._run is not None:
            self._run.interp.block_delete = self.block_skip  # from the next block read

    def _cmd_dry_run(self, on: bool) -> None:
        if self._execution() in IN_CYCLE:
            raise CommandRefused(f"dry run switch refused while {self._execution()}")
        self.dry_run = bool(on)

    def _cmd_feed_override(self, pct: float) -> None:
        self.feed_override = _pct("feed override", pct, 0, 200)

    def _cmd_rapid_override(self, pct: float) -> None:
        self.rapid_override = _pct("rapid override", pct, 0, 100)

    def _cmd_spindle_override(self, pct: float) -> None:
        self.spindle_override = _pct("spindle override", pct, 50, 120)

    def _cmd_acc(self, on: bool, limit_pct: float | None = None) -> None:
        if limit_pct is not None and not 1.0 <= float(limit_pct) <= 200.0:
            raise CommandRefused(f"ACC limit {limit_pct} % outside 1..200 %")
        self.acc.set(on, limit_pct)
        self._event(f"ACC {'on' if on else 'off'} limit {self.acc.limit_pct:g} %")

    def _cmd_alarm_reset(self) -> None:
        self._start_refused = ""
        kept = self._alarms.reset(self._active_causes())
        self._event(f"alarm reset: {len(kept)} alarm(s) remain")

    def _cmd_mdi(self, text: str) -> None:
        why = self._start_interlocks("MDI", "MDI")
        if why:
            raise CommandRefused(f"MDI refused: {why}")
        if len(text) > MDI_MAX_CHARS:
            raise CommandRefused(f"MDI refused: {len(text)} characters (at most {MDI_MAX_CHARS})")
        lines = text.splitlines() or [""]
        interp = self._interpreter("MDI")
        try:
            cmds = list(interp.run(lines))
        except NcError as exc:
            raise CommandRefused(f"MDI refused: {exc}") from None
        run = _Run("MDI", "MDI", self._motion(), interp, lines)
        run.cmds.extend(cmds)
        self._start(run)

    def _cmd_jog(
        self,
        axis: str,
        direction: int,
        feed: float | None = None,
        increment: float | None = None,
    ) -> None:
        if self.mode != "JOG":
            raise CommandRefused(f"jog refused: mode is {self.mode}, not JOG")
        if axis not in self.axes:
            raise CommandRefused(f"jog refused: no axis {axis!r} (axes {', '.join(self.axes)})")
        if self._estop or not self._enabled:
            raise CommandRefused("jog refused: axes not enabled")
        d = int(direction)
        if d == 0:
            if axis in self._jog:
                tgt, f, v = self._jog[axis]
                self._jog[axis] = (self._stop_point(axis, v), f, v)
            return
        if d not in (-1, 1):
            raise CommandRefused("jog refused: direction must be -1, 0 or +1")
        f = self.settings.jog_feed if feed is None else float(feed)
        vmax = self.config.axes[axis].max_velocity
        if not 0.0 < f <= vmax:
            raise CommandRefused(f"jog refused: feed {f:g} mm/min outside 0..{vmax:g}")
        lo, hi = self.config.axes[axis].min_mm, self.config.axes[axis].max_mm
        homed = self._ref[axis] and self._fb_homed(axis)
        if increment is not None:
            target = self._cmd[axis] + d * abs(float(increment))
            if homed and not lo - 1e-9 <= target <= hi + 1e-9:
                raise CommandRefused(
                    f"jog refused: axis {axis} move to {target:.4f} mm is beyond the soft "
                    f"limit [{lo:g}, {hi:g}] mm"
                )
        else:
            # continuous: to the soft limit when referenced; unreferenced, a long way
            # (soft limits mean nothing before homing, as in LinuxCNC)
            target = (hi if d > 0 else lo) if homed else self._cmd[axis] + d * 1e6
            if homed and abs(target - self._cmd[axis]) < 1e-9:
                raise CommandRefused(f"jog refused: axis {axis} is at its soft limit")
        v0 = self._jog.get(axis, (0.0, 0.0, 0.0))[2]
        self._jog[axis] = (target, f / 60.0, v0)

    def _home_refusal(self) -> tuple[int, str] | None:
        """Why a homing run cannot start now: (refusal code, text), or None."""
        if self.mode != "REF":
            return REFUSE_NOT_REF_MODE, f"homing refused: mode is {self.mode}, not REF"
        if self._estop:
            return REFUSE_ESTOP, "homing refused: emergency stop active"
        if not self._enabled:
            return REFUSE_NOT_ENABLED, "homing refused: axes not enabled"
        if self._homing:
            return REFUSE_HOMING, "homing refused: homing already in progress"
        return None

    def _cmd_home(self, axes=None) -> None:
        why = self._home_refusal()
        if why is not None:
            raise CommandRefused(why[1])
        if axes is not None:
            unknown = [a for a in axes if a not in self.axes]
            if unknown:
                raise CommandRefused(f"homing refused: no axis {', '.join(unknown)}")
        # the configured sequence, keeping only the axes asked for
        groups = [
            tuple(a for a in group if axes is None or a in axes) for group in self.home_sequence
        ]
        groups = [g for g in groups if g]
        self._homing_next = deque(groups[1:])
        self._homing_done = []
        self._home_group(groups[0])
        self._event("homing " + " then ".join(" ".join(g) for g in groups))

    def _home_group(self, group: tuple[str, ...]) -> None:
        """Ask the axis layer to home one group of the sequence."""
        self._homing = "requested"
        self._homing_axes = group
        self._homing_since = self._t
        self._axis("home", group)

    # ================================================================ operator actions ====
    def _start_interlocks(self, what: str, need_mode: str) -> str | None:
        """Why a program start (`what`) is refused now, or None."""
        if self.mode != need_mode:
            return f"mode is {self.mode}, not {need_mode}"
        ex = self._execution()
        if ex in IN_CYCLE:
            return f"{what} already {ex}"
        if self._estop:
            return "emergency stop active"
        blocking = self._alarms.blocking
        if blocking:
            return f"alarm {blocking[0].number} active ({blocking[0].text})"
        if self._plc.get("PlcReady", True) and self._plc.get("PlcAlarm", False):
            return f"PLC alarm {self._plc.get('PlcAlarmNumber', 0)} active"
        if not self._plc.get("DoorClosed", True):
            return "door open"
        if self._plc.get("FeedHold", False) and self._plc.get("PlcReady", True):
            return "feed hold from the PLC is active"
        if not self._enabled:
            return "axes not enabled"
        missing = [a for a in self.home_order if not (self._ref[a] and self._fb_homed(a))]
        if missing:
            return f"machine not homed ({', '.join(sorted(missing, key=self.axes.index))})"
        if self._homing:
            return "homing in progress"
        return None

    def _cycle_start(self) -> None:
        run = self._run
        if run is not None:
            if self._estop:
                raise CommandRefused("cycle start refused: emergency stop active")
            if run.aborting:
                raise CommandRefused("cycle start refused: program is being aborted")
            if self._plc.get("FeedHold", False) and self._plc.get("PlcReady", True):
                raise CommandRefused("cycle start refused: feed hold from the PLC is active")
            if self._alarms.blocking:
                a = self._alarms.blocking[0]
                raise CommandRefused(f"cycle start refused: alarm {a.number} active ({a.text})")
            if run.stop:
                self._event(f"cycle start: continue after {run.stop}")
                run.stop = ""
                self._ack(run)
                return
            if self._hold or run.motion.holding:
                self._hold = False
                self._plc_hold = False
                run.motion.resume()
                self._event("cycle start: resume")
                return
            raise CommandRefused(f"cycle start refused: program already {self._execution()}")
        if self.mode == "MDI":
            raise CommandRefused("cycle start refused: MDI has no program (type a block: mdi)")
        why = self._start_interlocks("program", "AUTO")
        if why:
            raise CommandRefused(f"cycle start refused: {why}")
        if self._drip is not None:
            lines = DripLines(self._drip)
            self._drip = None
            self._start(_Run("DRIP", "DRIP", self._motion(), self._interpreter("DRIP"), lines))
            return
        if self.selected is None:
            raise CommandRefused("cycle start refused: no program selected")
        if self.selected not in self.memory:
            raise CommandRefused(f"cycle start refused: program O{self.selected:04d} not in memory")
        text = self.memory.get(self.selected)
        name = f"O{self.selected:04d}"
        lines = text.splitlines()
        self._start(_Run("AUTO", name, self._motion(), self._interpreter(name), lines))

    def _start(self, run: _Run) -> None:
        self._start_refused = ""
        if self._tip is not None:
            self._tip.reset()
        run.motion.set_single_block(self.single_block)
        self._run = run
        self._hold = False
        self._plc_hold = False
        self._fo_applied = self._ro_applied = -1.0
        self._jog.clear()
        self._event(f"cycle start: {run.name}")

    def _feed_hold(self, who: str) -> None:
        if self._run is not None and not self._hold:
            self._hold = True
            self._run.motion.feed_hold()
            self._event(f"feed hold ({who})")
        for a, (_tgt, f, v) in list(self._jog.items()):
            self._jog[a] = (self._stop_point(a, v), f, v)

    def _reset(self, who: str) -> None:
        self._resetting_until = self._t + 2.0 * self.config.plc.period_ms / 1000.0
        for hs in self._hs.values():
            hs.abort()
        run = self._run
        if run is not None:
            if self._path_v == 0.0:
                self._abort_now("READY")
            else:
                run.aborting = "reset"
                run.motion.feed_hold()
        else:
            self._final = "READY"
        self._hold = False
        self._spindle_on = False
        self._jog.clear()
        if self._drip is not None:  # an armed drip-feed is rewound: the sender is told
            self._drip.abort("reset at the machine")
            self._drip = None
        drive_faults = any(
            e.number in (al.DRIVE_FAULT, al.BUS_FAULT, al.FOLLOWING_ERROR, al.AXES_DISABLED)
            for e in self._alarms.active
        )
        self._start_refused = ""
        kept = self._alarms.reset(self._active_causes())
        if drive_faults and not self._estop:
            self._axis("fault_reset")
            self._enable_sent_at = None  # re-enable in the next cycles
        self._event(f"reset ({who}); {len(kept)} alarm(s) remain")

    def _abort_now(self, final: str) -> None:
        self._book_cut_time()
        run = self._run
        self._run = None
        self._final = final
        self._hold = False
        for hs in self._hs.values():
            hs.abort()
        if run is not None:
            if isinstance(run.source, DripLines) and not run.source.ended:
                run.source.buffer.abort(f"program {final.lower()} at the machine")
            self._event(f"{run.name} aborted ({final})")

    # ================================================================ PLC side ============
    def _rose(self, name: str) -> bool:
        return bool(self._plc.get(name, False)) and not bool(self._plc_prev.get(name, False))

    def _plc_requests(self) -> None:
        plc = self._plc
        estop = bool(plc.get("EStopActive", False))
        if estop and not self._estop:
            self._estop_event()
        elif not estop and self._estop:
            self._estop = False
            self._event("E-stop released (reset and home to continue)")
        if not plc.get("PlcReady", False):
            if self._plc_was_ready and not self._alarms.has(al.PLC_STOPPED):
                # its outputs are off: axis enable, spindle and coolant go with them, so a cut
                # stops with 3002; this alarm says why (the PLC's own alarm list says more)
                self._alarms.raise_(
                    al.PLC_STOPPED,
                    "PLC not running (STOP or FAULT): its outputs are off; see the PLC's alarms",
                    self._t,
                    source="PLC",
                    rule=al.SELF,
                    cause="plc_stopped",
                )
                self._event("PLC stopped running")
            return  # a PLC that is not running gives no requests (its outputs are 0)
        self._plc_was_ready = True
        if self._alarms.has(al.PLC_STOPPED):
            self._alarms.clear_self("plc_stopped")
        if self._rose("NcReset"):
            self._reset("PLC")
        mode = int(plc.get("ModeSelect", 0))
        if mode != MODE_NONE and mode != int(self._plc_prev.get("ModeSelect", 0)):
            name = _MODE_BY_NUMBER.get(mode)
            try:
                if name is None:
                    raise CommandRefused(f"mode request {mode} from the PLC unknown")
                self._cmd_mode(name)
            except CommandRefused as exc:
                self._event(f"PLC: {exc.reason}")
        for sig, attr, lo, hi in (
            ("FeedOverride", "feed_override", 0, 200),
            ("RapidOverride", "rapid_override", 0, 100),
        ):
            if sig in plc and plc[sig] != self._plc_prev.get(sig):
                setattr(self, attr, float(min(max(int(plc[sig]), lo), hi)))
        self._plc_select_and_home(plc)
        if plc.get("FeedHold", False) and self._run is not None and not self._hold:
            self._plc_hold = True
            self._feed_hold("PLC")
        if self._rose("CycleStart"):
            try:
                self._cycle_start()
            except CommandRefused as exc:
                self._start_refused = exc.reason
                self._event(f"PLC: {exc.reason}")
        # the PLC alarm the NC sees: the lowest active number, mirrored as a SELF alarm
        number = int(plc.get("PlcAlarmNumber", 0)) if plc.get("PlcAlarm", False) else 0
        self._alarms.clear_self("plc", keep=number or None)
        if number:
            text = al.PLC_ALARM_TEXTS.get(number, f"PLC alarm {number}")
            self._alarms.raise_(number, text, self._t, source="PLC", rule=al.SELF, cause="plc")

    def _plc_select_and_home(self, plc) -> None:
        """The PLC's program select and zero return requests (remote operator panel): taken
        on the rising edge, answered with done/refused (and a code) until the request drops."""
        if self._rose("ProgSelectReq"):
            # 32 bits in two words, low word first (plc.signals)
            number = dword_value(plc.get("ProgSelectNumber", 0), plc.get("ProgSelectNumberHigh", 0))
            why = self._select_refusal(number)
            if why is None:
                self.selected = number
                self._final = "READY"
                self._start_refused = ""
                self._event(f"program O{number:04d} selected (PLC)")
                self._select_answer = (True, 0)
            else:
                self._event(f"PLC: {why[1]}")
                self._select_answer = (False, why[0])
        elif not plc.get("ProgSelectReq", False):
            self._select_answer = None
        if self._rose("HomeAllReq"):
            why = self._home_refusal()
            if why is None:
                self._cmd_home()
                self._home_answer = (True, 0)
            else:
                self._event(f"PLC: {why[1]}")
                self._home_answer = (False, why[0])
        elif not plc.get("HomeAllReq", False):
            self._home_answer = None

    def _estop_event(self) -> None:
        self._estop = True
        self._axis("quick_stop")
        self._spindle_on = False
        self._jog.clear()
        if self._run is not None:
            self._abort_now("STOPPED")
        self._ref = dict.fromkeys(self.axes, False)  # incremental encoders lose the reference
        self._homing = ""
        self._homing_next.clear()
        self._alarms.raise_(
            al.ESTOP,
            "emergency stop: axes quick-stopped, spindle stopped, reference lost (home again)",
            self._t,
            rule=al.CAUSE_GONE,
            cause="estop",
        )
        self._event("E-stop: quick stop")

    def _active_causes(self) -> set[str]:
        causes = set()
        if self._estop or self._plc.get("EStopActive", False):
            causes.add("estop")
        return causes

    def _plc_outputs(self) -> dict:
        """NC->PLC signals; the same (read-only) dict while nothing changes."""
        hs = self._hs
        referenced = 0
        for a in self.axes:
            if self._ref[a] and self._fb_homed(a):
                referenced |= 1 << AXIS_BITS.index(a) if a in AXIS_BITS else 0
        active = dword_words(self.selected or 0)  # the O number: 32 bits, low word first
        key = (
            self._ex in IN_CYCLE or self._run is not None,
            self._t < self._resetting_until,
            self._alarms.nc_count(),
            self.mode,
            hs["M"].phase,
            hs["M"].code,
            hs["S"].phase,
            hs["S"].code,
            hs["T"].phase,
            hs["T"].code,
            self._select_answer,
            self._home_answer,
            bool(self._homing),
            self.selected,
            referenced,
        )
        if key == self._plc_out_key:
            return self._plc_out
        out = {
            "NcReady": True,
            "NcInCycle": key[0],
            "NcResetting": key[1],
            "NcAlarm": key[2] > 0,
            "NcMode": _MODE_NUMBER.get(self.mode, MODE_NONE),
            "ProgSelectDone": self._select_answer is not None and self._select_answer[0],
            "ProgSelectFail": self._select_answer is not None and not self._select_answer[0],
            "ProgSelectFailCode": self._select_answer[1] if self._select_answer else 0,
            "HomeAck": self._home_answer is not None and self._home_answer[0],
            "HomeFail": self._home_answer is not None and not self._home_answer[0],
            "HomeFailCode": self._home_answer[1] if self._home_answer else 0,
            "HomingActive": bool(self._homing),
            "AllReferenced": all(self._ref[a] and self._fb_homed(a) for a in self.axes),
            "ActiveProgram": active[0],
            "ActiveProgramHigh": active[1],
            "ReferencedAxes": referenced,
        }
        for h in hs.values():
            h.write(out)
        self._plc_out_key, self._plc_out = key, out
        return out

    # ================================================================ axes ================
    def _fb_homed(self, axis: str) -> bool:
        return bool(self._fb.homed.get(axis, False)) if self._fb is not None else False

    def _home_sequence(self) -> tuple[tuple[str, ...], ...]:
        s = self.settings
        if s.home_sequence is not None:
            groups = tuple(tuple(g) for g in s.home_sequence)
            what = f"home_sequence {[list(g) for g in groups]}"
        elif s.home_order is not None:
            groups = tuple((a,) for a in s.home_order)
            what = f"home_order {tuple(s.home_order)}"
        elif self.config.home_sequence is not None:  # the machine YAML's key
            groups = tuple(tuple(g) for g in self.config.home_sequence)
            what = f"home_sequence {[list(g) for g in groups]}"
        elif self.config.kind == "lathe":
            # the cross slide first, clear of the chuck, then the carriage
            first = [a for a in self.axes if a == "X"]
            groups = tuple((a,) for a in first + [a for a in self.axes if a != "X"])
            what = "the lathe's default homing sequence"
        else:
            # the tool axis first, clear of the work and the fixtures, then the table
            first = tuple(a for a in self.axes if a == "Z")
            rest = tuple(a for a in self.axes if a != "Z")
            groups = tuple(g for g in (first, rest) if g)
            what = "the default homing sequence"
        flat = [a for g in groups for a in g]
        if any(not g for g in groups) or sorted(flat) != sorted(self.axes):
            raise ValueError(
                f"{what} must name each axis of {', '.join(self.axes)} exactly once,"
                " in non-empty groups"
            )
        return groups

    def _supervise_axes(self, fb: AxisFeedback) -> None:
        for axis, code, text in fb.faults:
            bus = 0x8100 <= code <= 0x81FF
            number = al.BUS_FAULT if bus else al.DRIVE_FAULT
            self._alarms.raise_(
                number,
                f"{'bus' if bus else 'drive'} fault {code:#06x} on {axis}: {text}",
                self._t,
                source="BUS" if bus else "DRIVE",
                axis=axis,
            )
            if 0x7300 <= code <= 0x73FF and axis in self._ref:
                self._ref[axis] = False  # encoder fault: the position is no longer known
            self._event(f"fault {axis} {code:#06x}: {text}")
        if fb.faults and (self._run is not None or self._jog):
            # one axis down stops them all: the others would leave the path
            self._axis("quick_stop")
            self._jog.clear()
            if self._run is not None:
                self._abort_now("STOPPED")
        for a in self.axes:
            if not fb.homed.get(a, False) and not fb.homing:
                self._ref[a] = False
        moving = self._run is not None or bool(self._jog)
        if self._enabled and not fb.enabled and not self._estop and not fb.faults and moving:
            self._alarms.raise_(al.AXES_DISABLED, "axis drives disabled during motion", self._t)
            self._abort_now("STOPPED")
        self._enabled = fb.enabled

    def _manage_enable(self, fb: AxisFeedback) -> None:
        want = bool(self._plc.get("AxisEnable", True)) and not self._estop
        if want and not fb.enabled:
            due = (
                self._enable_sent_at is None
                or self._t - self._enable_sent_at >= self.settings.enable_retry_s - 1e-9
            )
            free = self._axis_cmd == "none"  # a fault reset or homing goes first
            # with a drive, bus or following-error alarm active the drives stay off until
            # the operator's reset (it sends the fault reset first): enabling a drive in FAULT
            # only fails again, every retry period, with an alarm of its own
            held = (al.FOLLOWING_ERROR, al.DRIVE_FAULT, al.BUS_FAULT)
            if due and free and not any(self._alarms.has(n) for n in held):
                self._axis("enable")
                self._enable_sent_at = self._t
        elif not want and self._want_enable and fb.enabled and not self._estop:
            self._axis("disable")
        if fb.enabled:
            self._enable_sent_at = None
        self._want_enable = want

    def _homing_step(self, fb: AxisFeedback) -> None:
        if not self._homing:
            return
        if self._homing == "requested":
            done = all(fb.homed.get(a, False) for a in self._homing_axes)
            if fb.homing or (done and self._t - self._homing_since > self.ipo * 1.5):
                self._homing = "running"
            elif self._t - self._homing_since > self.settings.homing_start_timeout_s:
                self._homing_failed("the axis layer did not start homing")
                return
        if self._homing == "running" and not fb.homing:
            bad = [a for a in self._homing_axes if not fb.homed.get(a, False)]
            if bad:
                self._homing_failed(f"axis {', '.join(bad)} not referenced")
                return
            for a in self._homing_axes:
                self._ref[a] = True
            self._homing_done.extend(self._homing_axes)
            self._cmd = dict(self._actual)
            if self._homing_next:
                # the next group starts once this one is referenced (Z clear, then X Y)
                self._home_group(self._homing_next.popleft())
                return
            self._homing = ""
            self._event(f"homed {' '.join(self._homing_done)}")

    def _watch_reference(self) -> None:
        """Which axes are not referenced (`MachineStatus.unreferenced`: before the first
        homing, after an E-stop, a quick stop, an encoder fault, a drive that rebooted): the
        status says so at once, not first at a refused cycle start. An axis that *loses* its
        reference also raises the warning 3031 "axis X not referenced: home the machine"
        (rule self: homing ends it, RESET does not); at power-on the status alone says it,
        as a control shows "reference return" before the first homing without an alarm."""
        ref = self._ref
        missing = tuple(a for a in self.axes if not (ref[a] and self._fb_homed(a)))
        if missing == self._unreferenced:
            return
        for a in self._unreferenced:
            if a not in missing:
                self._alarms.clear(al.NOT_REFERENCED, a)
                self._was_referenced.add(a)
        for a in missing:
            if a not in self._unreferenced and a in self._was_referenced:
                self._alarms.raise_(
                    al.NOT_REFERENCED,
                    f"axis {a} not referenced: home the machine (REF mode, home)",
                    self._t,
                    axis=a,
                    rule=al.SELF,
                    cause="reference",
                    severity="WARNING",
                )
                self._event(f"axis {a} lost its reference: home the machine")
        self._unreferenced = missing

    def _homing_failed(self, why: str) -> None:
        self._homing = ""
        self._homing_next.clear()
        self._alarms.raise_(al.HOMING_FAILED, f"homing failed: {why}", self._t)

    def _following_error(self, fb: AxisFeedback, dt: float) -> None:
        prev = self._prev_cmd
        if prev is None or dt <= 0.0:
            return
        prev2 = self._prev2 or prev
        self._prev2 = dict(prev)
        if not fb.enabled or fb.homing or self._homing:
            return
        s = self.settings
        fmin, fmax = s.ferror_min_mm, s.ferror_max_mm
        fes = fb.following_error
        peak = self.max_following_error
        for a, vmax in self._vmax.items():
            fe = fes.get(a)
            if fe is None:
                fe = prev[a] - self._actual[a]
            fe = abs(fe)
            if fe > peak[a]:
                peak[a] = fe
            if fe <= fmin:
                continue
            v = abs(prev[a] - prev2[a]) / dt
            limit = max(fmin, fmax * min(1.0, v / vmax))
            if fe > limit:
                self._alarms.raise_(
                    al.FOLLOWING_ERROR,
                    f"following error on {a}: {fe:.3f} mm exceeds the NC limit {limit:.3f} mm",
                    self._t,
                    axis=a,
                )
                self._event(f"following error {a} {fe:.3f} mm")
                self._axis("quick_stop")
                self._jog.clear()
                if self._run is not None:
                    self._abort_now("STOPPED")

    # ================================================================ jog =================
    def _stop_point(self, axis: str, v: float) -> float:
        a = self.config.axes[axis].max_accel
        return self._cmd[axis] + (v * abs(v) / (2.0 * a) if a > 0 else 0.0)

    def _jog_step(self, dt: float) -> None:
        if self._estop or not self._enabled:
            self._jog.clear()
            return
        for axis, (target, f, v) in list(self._jog.items()):
            acc = self.config.axes[axis].max_accel
            pos = self._cmd[axis]
            dist = target - pos
            # speed allowed by the braking distance, then acceleration-limited change
            vbrake = (2.0 * acc * abs(dist)) ** 0.5
            vwant = min(f, vbrake) * (1.0 if dist > 0 else -1.0)
            dv = max(-acc * dt, min(acc * dt, vwant - v))
            v += dv
            step = v * dt
            if abs(step) >= abs(dist) or abs(dist) < 1e-9:
                self._cmd[axis] = target
                del self._jog[axis]
                continue
            self._cmd[axis] = pos + step
            self._jog[axis] = (target, f, v)

    # ================================================================ program run =========
    def _interpreter(self, name: str) -> Interpreter:
        start = tuple(self._cmd.get(a, 0.0) for a in self._pose_axes)
        return Interpreter(
            self.params,
            programs=_MemoryPrograms(self.memory),
            machine_data=self.machine_data,
            # #500-#999 are kept in the machine data (saved with it); #100-#199 live as long
            # as the controller: from one program to the next, cleared at power off
            macro_variables=self.machine_data.macro_variables,
            common_variables=self._common_variables,
            block_delete=self.block_skip,
            file=name,
            start=start,
        )

    def _motion(self) -> Motion:
        start = tuple(self._cmd.get(a, 0.0) for a in self._pose_axes)
        return Motion(self.params, start=start, ipo_cycle_s=self.ipo)

    def _next_cmd(self, run: _Run):
        """The next canonical command (None: none now); sets src_done at the end."""
        if run.kind == "MDI":
            if run.cmds:
                return run.cmds.popleft()
            run.src_done = True
            return None
        src = run.source
        if isinstance(src, DripLines):
            if src.buffer.aborted:
                self._program_alarm(
                    al.DRIP_ABORTED, f"drip-feed aborted: {src.buffer.aborted}", "DNC"
                )
                return None
            if not src.fill():
                return None
        try:
            cmd = next(run.gen)
        except StopIteration:
            run.src_done = True
            return None
        except NcError as exc:
            if isinstance(src, DripLines) and exc.file == run.name:
                exc.line = src.real_line(exc.line)
            self._program_alarm(al.PROGRAM_ERROR, f"program error: {exc}", "NC")
            return None
        except Exception as exc:  # a fault in the interpreter stops the program, not the NC
            text = f"program error: {run.name}:{run.line}: internal {type(exc).__name__}: {exc}"
            self._program_alarm(al.PROGRAM_ERROR, text, "NC")
            return None
        if isinstance(src, DripLines):
            if isinstance(cmd, canon.Dwell) and src.is_marker(cmd.line):
                return False
            cmd = dataclasses.replace(cmd, line=src.real_line(cmd.line))
        return cmd

    def _program_alarm(self, number: int, text: str, source: str) -> None:
        run = self._run
        self._alarms.raise_(number, text, self._t, source=source)
        self._event(text)
        if run is not None:
            run.src_done = True
            run.aborting = "alarm"
            run.motion.feed_hold()

    def _feed_interpreter(self, run: _Run) -> None:
        m = run.motion
        for _ in range(INTERP_BUDGET):
            if run.src_done or run.aborting or run.skip is not None:
                return  # (after a G31 the next block waits for its skip position)
            if run.pending is None:
                cmd = self._next_cmd(run)
                if cmd is False:
                    continue
                if cmd is None:
                    if run.src_done and not run.aborting:
                        m.end_of_program()
                    return
                if self.dry_run and isinstance(cmd, canon.StraightFeed | canon.ArcFeed):
                    cmd = dataclasses.replace(cmd, feed=self.settings.dry_run_feed)
                run.pending = cmd
            cmd = run.pending
            motion = isinstance(cmd, canon.MOTION_TYPES)
            sync = not motion and not isinstance(cmd, canon.SetPathMode)
            if sync and run.syncs_out >= SYNC_AHEAD:
                return
            blocks = m.path.blocks
            try:
                if not m.push(cmd):
                    return
            except NcError as exc:
                self._program_alarm(al.PROGRAM_ERROR, f"program error: {exc}", "NC")
                return
            run.pending = None
            if type(cmd) is canon.SkipFeed:
                if m.path.blocks > blocks:
                    run.skip = _SkipWait(cmd, m.path.blocks)
                else:  # no distance to go: it ends where it starts, without a signal
                    run.interp.skipped(None, cmd.end)
            if motion:
                feed = getattr(cmd, "feed", None)
                if cmd.line not in run.lines_feed:
                    run.lines_feed[cmd.line] = feed
                elif feed is not None:
                    run.lines_feed[cmd.line] = max(run.lines_feed[cmd.line] or 0.0, feed)
                if len(run.lines_feed) > 4096:
                    del run.lines_feed[next(iter(run.lines_feed))]
                if isinstance(cmd, canon.ThreadFeed) and cmd.rpm > 0.0:
                    run.thread_rpm[cmd.line] = cmd.rpm
                    if len(run.thread_rpm) > 4096:
                        del run.thread_rpm[next(iter(run.thread_rpm))]
            elif not isinstance(cmd, canon.SetPathMode):
                run.syncs_out += 1

    def _apply_overrides(self, run: _Run) -> None:
        fo = self.feed_override / 100.0 * self.acc.factor
        if self._spindle_on and not self.dry_run and not self._plc.get("SpindleAtSpeed", True):
            fo = 0.0  # feed only with the spindle at speed (docs/machine_plc.md)
        thread_rpm = run.thread_rpm.get(run.line) if run.thread_rpm else None
        if thread_rpm and not self.dry_run:
            # thread cutting: the feed follows the spindle speed the NC runs (S x the
            # spindle overrides), so the lead holds; feed override and ACC are out of effect
            fo = self._spindle_rpm_now() / thread_rpm
        ro = self.rapid_override / 100.0
        if fo != self._fo_applied:
            run.motion.set_feed_override(fo)
            self._fo_applied = fo
        if ro != self._ro_applied:
            run.motion.set_rapid_override(ro)
            self._ro_applied = ro

    def _run_step(self, dt: float) -> None:
        run = self._run
        if not self._enabled:
            return
        self._feed_interpreter(run)
        if self._run is not run:
            return
        self._apply_overrides(run)
        if run.sync is not None and not run.stop:
            self._sync_step(run)
        s = run.motion.step()
        for i, a in enumerate(self._pose_axes):
            if a in self._cmd:
                self._cmd[a] = s.pose[i]
        if self._tip is not None:
            actual = tuple(self._actual.get(a, 0.0) for a in self._pose_axes)
            self._tip.sample(s.pose, run.motion, actual)
        self._path_v = s.velocity
        if run.skip is not None:
            self._skip_step(run, s.velocity)
        if s.line != run.line:
            run.line = s.line
            self.blocks += 1
        if s.sync is not None:
            run.syncs_out -= 1
            self._begin_sync(run, s.sync)
        if run.aborting and s.velocity == 0.0 and (run.motion.holding or run.motion.idle):
            self._abort_now("READY" if run.aborting == "reset" else "STOPPED")
            return
        if (
            run.src_done
            and run.pending is None
            and run.motion.idle
            and run.sync is None
            and not run.aborting
        ):
            self._finish(run)

    def _skip_step(self, run: _Run, v: float) -> None:
        """G31 under way: test the tool setter on the encoder position of this IPO cycle
        while the skip move runs; at the signal latch that position and stop along the
        path (as a feed hold); once at rest, drop the rest of the move and hand the
        interpreter the latch and the stop position. The latch resolves one IPO cycle:
        the tool travels feed x cycle between two tests (100 mm/min, 2 ms: 3.3 um),
        where a real control latches the encoder in hardware within microseconds."""
        sk = run.skip
        assert sk is not None
        m = run.motion
        sensor = self.params.tool_setter
        if sk.latched is None and sensor is not None and m.block == sk.block and v > 0.0:
            a = self._actual
            at = (a.get("X", 0.0), a.get("Y", 0.0), a.get("Z", 0.0))
            if sensor.trips((at[0], at[1], at[2] - sk.cmd.tool_length), sk.cmd.tool_radius):
                sk.latched = at
                m.feed_hold()
                self._event(f"G31 skip signal at line {sk.cmd.line}: Z {at[2]:.4f}")
        if sk.latched is not None:
            if v == 0.0 and m.holding:
                stop = m.pose
                run.motion = m.continued()
                run.skip = None
                run.interp.skipped(sk.latched, stop)
        elif m.idle:
            run.skip = None
            run.interp.skipped(None, m.pose)

    def _book_cut_time(self) -> None:
        """Book the cutting time since the last tool change on that tool (its life)."""
        if self._life_cut_s > 0.0 and self._life_tool:
            self.machine_data.count_use(self._life_tool, cut_time_s=self._life_cut_s)
        self._life_cut_s = 0.0

    def _finish(self, run: _Run) -> None:
        self._book_cut_time()
        self._run = None
        if run.end_kind is not None and not self.dry_run and run.kind != "MDI":
            self.part_count += 1
        self._final = "READY" if run.kind == "MDI" else "PROGRAM_COMPLETED"
        self._event(f"{run.name} completed (part count {self.part_count})")

    # -- sync points (non-motion commands) ------------------------------------------------
    def _begin_sync(self, run: _Run, cmd) -> None:
        run.sync = cmd
        steps = run.steps
        steps.clear()
        if isinstance(cmd, canon.Dwell):
            steps.append(("DWELL", self._t + cmd.seconds))
        elif isinstance(cmd, canon.Spindle):
            rpm = cmd.rpm * self.spindle_override / 100.0
            if cmd.direction in (canon.SpindleDirection.CW, canon.SpindleDirection.CCW):
                s = int(round(min(max(rpm, 0.0), 12000.0)))
                if s != round(self._spindle_rpm):
                    steps.append(("S", s))
                steps.append(("M", 3 if cmd.direction is canon.SpindleDirection.CW else 4))
                self._spindle_rpm = s
            else:
                steps.append(("M", 5 if cmd.direction is canon.SpindleDirection.STOP else 19))
        elif isinstance(cmd, canon.Coolant):
            mist0, flood0 = self._coolant
            if (mist0 and not cmd.mist) or (flood0 and not cmd.flood):
                steps.append(("M", 9))
                mist0 = flood0 = False
            if cmd.mist and not mist0:
                steps.append(("M", 7))
            if cmd.flood and not flood0:
                steps.append(("M", 8))
            self._coolant = (cmd.mist, cmd.flood)
        elif isinstance(cmd, canon.SpindleSync):
            steps.append(("INDEX", 0))
        elif isinstance(cmd, canon.ToolSelect):
            steps.append(("T", cmd.tool))
        elif isinstance(cmd, canon.ToolChange):
            steps.append(("M", 6))
            if not self.dry_run:
                self._book_cut_time()
                self.machine_data.count_use(cmd.tool)  # tool life: one more use
                self._life_tool = cmd.tool
        elif isinstance(cmd, canon.AuxFunction):
            steps.append(("M", cmd.code))
        elif isinstance(cmd, canon.ProgramStop):
            kind = cmd.kind
            if kind is canon.StopKind.PROGRAM_STOP:
                steps.append(("STOP", "M0"))
            elif kind is canon.StopKind.OPTIONAL_STOP:
                if self.optional_stop:
                    steps.append(("STOP", "M1"))
            else:
                steps.append(("M", 30 if kind is canon.StopKind.PROGRAM_END_REWIND else 2))
                run.end_kind = kind
        self._sync_step(run)

    def _sync_step(self, run: _Run) -> None:
        """Work on the current sync point's steps; acknowledge when all are done."""
        while run.steps:
            kind, value = run.steps[0]
            if kind == "DWELL":
                if self._t + 1e-9 < value:
                    return
            elif kind == "INDEX":  # a thread pass starts on the spindle's index
                if not self._spindle_index and not self.dry_run:
                    return  # (a spindle not turning keeps the pass waiting, as on a control)
            elif kind == "STOP":
                if run.stop != "done":
                    run.stop = value
                    self._event(f"program stop {value} at line {run.line}")
                    return
                run.stop = ""
            else:
                hs = self._hs[kind]
                if not run.step_started:
                    hs.start(value)
                    run.step_started = True
                    self._after_function(kind, value)
                    return  # the strobe goes out with this cycle's outputs
                if not hs.step(bool(self._plc.get(hs.finish_signal, False))):
                    return
            run.steps.popleft()
            run.step_started = False
        run.sync = None
        run.motion.acknowledge()

    def _ack(self, run: _Run) -> None:
        """Cycle start after M0/M1: the STOP step is done."""
        run.stop = "done"
        self._sync_step(run)

    def _after_function(self, kind: str, value: int) -> None:
        if kind == "M":
            if value in (3, 4, 13, 14):
                self._spindle_on = True
            elif value in (5, 19, 6, 2, 30):
                self._spindle_on = False
            if value in (2, 30):
                self._coolant = (False, False)

    # ================================================================ ACC, timers, status ==
    def _cutting_now(self) -> bool:
        run = self._run
        if run is None or self._path_v <= 0.0:
            return False
        feed = run.lines_feed.get(run.line, None)
        if feed is None:
            return False
        # a line with rapids and feeds (a canned cycle) cuts at feed speeds only
        return self._path_v * 60.0 <= feed * 2.0 + 1e-6

    def _spindle_rpm_now(self) -> float:
        if not self._spindle_on or not self._plc.get("SpindleAtSpeed", True):
            return 0.0
        return self._spindle_rpm * self._plc_spindle_pct() / 100.0

    def _plc_spindle_pct(self) -> float:
        if self._plc.get("PlcReady", False) and "SpindleOverride" in self._plc:
            return float(self._plc["SpindleOverride"])
        return 100.0

    def _adaptive(self, dt: float) -> None:
        self._cutting = self._cutting_now()
        m = self.cutting_model
        pos = self._actual.get(m.depth_axis)
        rpm = self._rpm = self._spindle_rpm_now()
        # the spindle's angle (revolutions, mod 1) from the speed it runs: its one-revolution
        # signal starts a thread pass (canon.SpindleSync)
        prev = self._spindle_phase
        self._spindle_phase = (prev + rpm / 60.0 * dt) % 1.0
        self._spindle_index = rpm > 0.0 and self._spindle_phase < prev
        feed = self._path_v * 60.0 if self._cutting else 0.0
        self._load = m.load(feed, rpm, pos) if self._cutting else (m.idle_load_pct if rpm else 0)
        self.acc.update(self._load, self._cutting, dt)

    def _timers(self, dt: float) -> None:
        if self._run is not None and self._execution() == "ACTIVE":
            self.run_time += dt
        if self._cutting:
            self.cutting_time += dt
            if not self.dry_run:
                self._life_cut_s += dt
        if self._rpm > 0.0:
            self.spindle_time += dt

    def _execution(self) -> str:
        run = self._run
        if run is None:
            return self._final
        if run.aborting:
            return "STOPPED"
        if run.stop == "M0":
            return "PROGRAM_STOPPED"
        if run.stop == "M1":
            return "OPTIONAL_STOP"
        if self._hold:
            return "FEED_HOLD"
        if run.motion.holding and self._path_v == 0.0:
            return "INTERRUPTED"  # single-block stop
        if isinstance(run.source, DripLines) and run.source.starved and run.motion.idle:
            return "INTERRUPTED"  # drip-feed: waiting for data
        return "ACTIVE"

    def _block_text(self, run: _Run | None) -> str:
        if run is None or run.line <= 0:
            return ""
        if run.text_lines is not None and run.line <= len(run.text_lines):
            return run.text_lines[run.line - 1].strip()
        if isinstance(run.source, DripLines):
            return run.source.recent.get(run.line, "").strip()
        return ""

    def _build_status(self) -> MachineStatus:
        run = self._run
        key = (
            self._ex,
            self.mode,
            run,
            run.line if run is not None else 0,
            self.selected,
            self._path_v,
            tuple(self._actual.values()),
            tuple(self._cmd.values()),
            self._rpm,
            self._load,
            self.spindle_override,
            self._plc_spindle_pct(),
            self.feed_override * self.acc.factor,
            self.rapid_override,
            self._alarms.raised,
            len(self._alarms),
            self.part_count,
            self._estop,
            self.acc.state(self._cutting),
            self._unreferenced,
            self._start_refused,
        )
        if key == self._status_key:
            return self._status  # nothing changed: the same snapshot (cheap when idle)
        self._status_key = key
        prog = (
            run.name
            if run is not None
            else (f"O{self.selected:04d}" if self.selected is not None else "")
        )
        return MachineStatus(
            execution=self._ex,
            controller_mode=_CONTROLLER_MODE[self.mode],
            mode_detail=self.mode,
            program=prog,
            line=run.line if run is not None else 0,
            block=self._block_text(run),
            path_feed_rate=self._path_v * 60.0,
            axes={a: AxisStatus(self._actual[a], self._cmd[a]) for a in self.axes},
            spindle_speed=self._rpm,
            spindle_load=self._load,
            spindle_override=self.spindle_override * self._plc_spindle_pct() / 100.0,
            feed_override=self.feed_override * self.acc.factor,
            rapid_override=self.rapid_override,
            alarms=self._alarms.active,
            part_count=self.part_count,
            emergency_stop="TRIGGERED" if self._estop else "ARMED",
            adaptive_control=self.acc.state(self._cutting),
            unreferenced=self._unreferenced,
            cycle_start_refused=self._start_refused,
            tool_tip=self._tool_tip_status(),
        )

    def _tool_tip_status(self) -> ToolTipStatus | None:
        tip = self._tip
        if tip is None:
            return None
        return ToolTipStatus(tip.tip, tip.deviation, tip.peak, tip.actual_peak)

    def _event(self, text: str) -> None:
        self._events.append((self._t, text))


class _MemoryPrograms:
    """Program memory as the interpreter's M98 `programs` mapping (read when called)."""

    def __init__(self, memory: ProgramMemory) -> None:
        self.memory = memory

    def keys(self):
        return [e.number for e in self.memory.directory()]

    def __getitem__(self, number: int) -> str:
        return self.memory.get(number)

    def __iter__(self):
        return iter(self.keys())

    def __len__(self) -> int:
        return len(self.keys())

    def __contains__(self, number: object) -> bool:
        return number in self.memory


def _pct(what: str, value: float, lo: float, hi: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CommandRefused(f"{what} {value!r} is not a number") from None
    if not lo <= v <= hi:
        raise CommandRefused(f"{what} {v:g} % outside {lo:g}..{hi:g} %")
    return v
