"""Simulated machine I/O: the plant behind the machine-tool PLC program.

`MachineIO` is the PLC's I/O provider (`read_inputs`/`write_outputs`, see `plc.runtime.io`)
for a simulated 3-axis mill: a spindle drive with a speed ramp, drive-ready, speed-arrival,
zero-speed and orientation feedback; a coolant pump with a pressure switch; a 20-pocket
carousel and a double-arm tool changer with timed motions; the guard door with its switch and
lock; the E-stop chain; way lubrication; shop air; the machine panel buttons. The NC's side of
the interface is `MachineIO.nc`, an `NcPort` over the declared signal table (`plc.signals`).

Time: the plant reads no clock. `read_inputs(ix, iw, now_ms)` first advances the plant to
`now_ms` with the outputs of the previous scan (`step`), then fills the inputs, so a Runtime
scanned in lockstep (`rt.scan(t)`) and the plant share one virtual time. `step(dt_ms)` may
also be called directly. Faults are injected with `inject(name)` / `clear(name)`; operator
actions are methods (`open_door`, `press_estop`, `press`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from plc.image import ImageSize
from plc.ladder import LadderError, compile_program, load_file, parse_program
from plc.m_functions import with_m_functions
from plc.runtime import Runtime, RuntimeConfig
from plc.signals import FIELD_TO_PLC, PLC_TO_FIELD, NcPort, signal, signals

ARM_POSITIONS = ("home", "grip", "extract", "swap", "insert")
_ARM_OUTPUT = {
    "home": "ArmToHome",
    "grip": "ArmToGrip",
    "extract": "ArmToExtract",
    "swap": "ArmToSwap",
    "insert": "ArmToInsert",
}
_ARM_INPUT = {p: "ArmAt" + p.capitalize() for p in ARM_POSITIONS}

FAULTS = {
    "door_open": "guard door forced open (lock or switch defeated)",
    "air_pressure_loss": "shop air pressure drops to zero",
    "estop_button": "E-stop button pressed",
    "estop_chain": "E-stop chain open (wire break, safety relay)",
    "coolant_pump_fail": "coolant pump runs but builds no pressure",
    "carousel_jam": "carousel stops between pockets",
    "arm_jam": "changer arm stops mid-motion",
    "changer_jam": "carousel and arm both jammed",
    "spindle_drive_fault": "spindle drive not ready",
    "spindle_stall": "spindle never reaches the commanded speed",
    "orient_fail": "spindle orientation never completes",
    "lube_level_low": "lubricant tank below minimum",
    "lube_pump_fail": "lubrication pump builds no pressure",
    "door_lock_fail": "door lock bolt never engages",
}

# How the machine-tool PLC program (plc/programs/machine_tool.ld, docs/machine_plc.md)
# detects each field fault: (bound in seconds of machine time, counted from, what shows it).
# The bound is the program's timer plus a scan or two (10 ms); `from` is one of
# drives.fault_registry.DETECT_FROM. /api/fault-types and benches read it from here.
DETECTION: dict[str, tuple[float, str, str]] = {
    "door_open": (0.02, "injection", "1030 and feed hold in the scan that sees the door open"),
    "air_pressure_loss": (0.02, "injection", "1040 and feed hold in one scan"),
    "estop_button": (0.02, "injection", "1001 in one scan (NC 3001)"),
    "estop_chain": (0.02, "injection", "1001 in one scan (NC 3001)"),
    "coolant_pump_fail": (
        3.02,
        "coolant_on",
        "1006 once the flood pump has run 3 s without pressure: only while the pump runs "
        "(M8): a pump that is off shows nothing until the next M8",
    ),
    "carousel_jam": (5.1, "tool_change", "1017 (T) or 1011 (M6): 5 s step timeout"),
    "arm_jam": (2.7, "tool_change", "1012: orient, then the arm not at grip within 2 s"),
    "changer_jam": (5.1, "tool_change", "1017 / 1011: 5 s step timeout"),
    "spindle_drive_fault": (
        1.02,
        "injection",
        "1002 and feed hold: the drive not ready 1 s after enable (the enable is on whenever "
        "there is no E-stop, turning or not)",
    ),
    "spindle_stall": (
        2.02,
        "spindle_on",
        "1007 and feed hold once the turning spindle has been below its at-speed band for "
        "2 s; a spindle standing at the injection: 1003 10 s after the next M3/M4",
    ),
    "orient_fail": (5.3, "tool_change", "1010: spindle not oriented within 5 s of the M6"),
    "lube_level_low": (0.02, "injection", "1041 (cycle start refused) in one scan"),
    "lube_pump_fail": (
        32.1,
        "injection",
        "1042 at the end of the next 2 s lubrication pulse (every 32 s)",
    ),
    "door_lock_fail": (
        1.02,
        "door_lock",
        "1031 once the lock is commanded (spindle on, tool change) and not engaged for 1 s",
    ),
}

# What brings the machine back from each field fault (docs/recovery.md, /api/fault-types
# `recovery`): what a real machine's operator does, in order. Every alarm of the program is
# latched and cleared by RESET (an alarm whose cause persists comes back in the same scan),
# except 1030, which goes with the closed door; a RESET aborts the program. Homing only where
# the axes stopped on a fault and lost their reference (the E-stop, or a reset in a motion).
# tests/plc/test_machine_io.py holds docs/recovery.md to this table, tests/cnc/test_recovery.py
# runs it.
RECOVERY: dict[str, str] = {
    "door_open": (
        "close the door (1030 goes with it); CYCLE START resumes the program where it "
        "stopped (RESET instead aborts it); no homing: the axes were held, not faulted"
    ),
    "air_pressure_loss": (
        "restore the shop air (compressor, main valve, the air service unit's filter and "
        "regulator); RESET (1040 is latched: the held program is aborted); no homing: the axes "
        "were held, not faulted; run the program again"
    ),
    "estop_button": (
        "release the E-stop button; RESET (clears the PLC's 1001 and the NC's 3001); home "
        "(the reference is lost)"
    ),
    "estop_chain": (
        "find and close the open chain (a guard switch of the chain, a broken wire, the "
        "safety relay and its feedback); RESET (1001 clears only with the chain closed); home "
        "(the reference is lost)"
    ),
    "coolant_pump_fail": "repair the coolant pump; RESET; home",
    "carousel_jam": "free the carousel; RESET; no homing: the axes did not stop on a fault",
    "arm_jam": "free the changer arm; RESET; no homing: the axes did not stop on a fault",
    "changer_jam": (
        "free the carousel and the changer arm; RESET; no homing: the axes did not stop on a fault"
    ),
    "spindle_drive_fault": (
        "repair the spindle drive; RESET once (it drops the spindle enable for a scan: the "
        "drive restarts); home"
    ),
    "spindle_stall": "free the spindle; RESET once; home",
    "orient_fail": (
        "repair the spindle orientation (its sensor or drive); RESET; no homing: the axes did "
        "not stop on a fault"
    ),
    "lube_level_low": (
        "refill the lubricant tank; the program in progress cuts on (1041 refuses only the "
        "next cycle start); RESET once it has ended (1041 is latched); no homing"
    ),
    "lube_pump_fail": (
        "repair the lubrication pump (its line, the pressure switch); RESET (1042 is "
        "latched); no homing; the next pulse (every 32 s) checks the pressure again"
    ),
    "door_lock_fail": (
        "repair the door lock (bolt, solenoid, the locked switch); RESET (1031 is latched: "
        "the program is aborted); no homing: the axes did not stop on a fault; run the "
        "program again"
    ),
}

# The row of docs/recovery.md's fault class table each field fault belongs to.
RECOVERY_CLASS: dict[str, str] = {
    "door_open": "door",
    "air_pressure_loss": "air",
    "estop_button": "E-stop",
    "estop_chain": "E-stop",
    "coolant_pump_fail": "coolant",
    "carousel_jam": "tool changer",
    "arm_jam": "tool changer",
    "changer_jam": "tool changer",
    "spindle_drive_fault": "spindle",
    "spindle_stall": "spindle",
    "orient_fail": "tool changer",
    "lube_level_low": "lubrication",
    "lube_pump_fail": "lubrication",
    "door_lock_fail": "door lock",
}

PANEL_BUTTONS = ("PanelCycleStart", "PanelFeedHold", "PanelReset")


@dataclass(frozen=True, slots=True)
class MachineParams:
    """Plant constants. Times in ms, speeds in rpm."""

    spindle_max_rpm: int = 12000
    spindle_accel_rpm_per_s: int = 10000  # ramp up and down
    at_speed_tolerance_rpm: int = 20  # speed arrival: |actual - ref| <= max(this, 2 %)
    zero_speed_rpm: int = 10
    drive_ready_ms: int = 200  # enable -> ready
    orient_ms: int = 300  # at zero speed with orient on -> oriented
    coolant_pressure_ms: int = 400  # pump on -> pressure switch
    lube_pressure_ms: int = 300
    door_lock_ms: int = 100  # lock solenoid on -> bolt engaged
    pockets: int = 20
    pocket_index_ms: int = 200  # carousel: time per pocket
    arm_ms: tuple[tuple[str, int], ...] = (
        ("grip", 300),
        ("extract", 400),
        ("swap", 500),
        ("insert", 400),
        ("home", 300),
    )
    tool_in_spindle: int = 0  # 0 = empty

    def arm_time(self, position: str) -> int:
        return dict(self.arm_ms)[position]


@dataclass(slots=True)
class PlantState:
    """Everything the plant remembers between steps (inspect freely; tests read it)."""

    time_ms: int = 0
    spindle_rpm: float = 0.0
    drive_ready: bool = False
    drive_enable_ms: int = 0
    oriented: bool = False
    orient_ms: int = 0
    coolant_on_ms: int = 0
    coolant_pressure: bool = False
    lube_on_ms: int = 0
    lube_pressure: bool = False
    door_closed: bool = True
    door_locked: bool = False
    door_lock_ms: int = 0
    estop_pressed: bool = False
    carousel_pocket: int = 1
    carousel_progress_ms: int = 0  # time spent indexing toward the next pocket
    carousel_dir: int = 0  # +1 / -1 while indexing
    arm_position: str | None = "home"  # None while moving
    arm_target: str | None = None
    arm_remaining_ms: int = 0
    tool_in_spindle: int = 0
    pockets: list[int] = field(default_factory=list)  # pockets[i] = tool in pocket i+1
    buttons: dict[str, bool] = field(default_factory=dict)
    crashes: list[str] = field(default_factory=list)  # arm moved against an interlock


class MachineIO:
    """I/O provider for the machine-tool program: plant + NC port.

    MachineIO(params=None, size=None)
        .nc                          NcPort: the NC sets NC->PLC and reads PLC->NC signals
        .read_inputs / .write_outputs  IOProvider protocol (read_inputs steps the plant)
        .step(dt_ms)                 advance the plant with the last outputs
        .inject(fault) / .clear(fault) / .faults
        .open_door() -> bool / .close_door() / .press_estop() / .release_estop()
        .press(button) / .release(button)  PanelCycleStart, PanelFeedHold, PanelReset
        .output(name) / .input(name)  field signals by name (last outputs / current inputs)
        .state                        PlantState
    """

    def __init__(self, params: MachineParams | None = None, size: ImageSize | None = None):
        self.params = p = params or MachineParams()
        self.size = size or ImageSize()
        self.nc = NcPort()
        self.state = PlantState(
            tool_in_spindle=p.tool_in_spindle,
            pockets=[i + 1 for i in range(p.pockets)],
            buttons=dict.fromkeys(PANEL_BUTTONS, False),
        )
        if p.tool_in_spindle:  # its own pocket stays empty while it is in the spindle
            self.state.pockets[p.tool_in_spindle - 1] = 0
        self.faults: set[str] = set()
        self._out = {s.name: (False if s.type == "BOOL" else 0) for s in signals(PLC_TO_FIELD)}
        # (name, index) per image area, resolved once: the I/O copy runs every scan
        self._out_bits = [(s.name, s.index) for s in signals(PLC_TO_FIELD) if s.area == "QX"]
        self._out_words = [(s.name, s.index) for s in signals(PLC_TO_FIELD) if s.area == "QW"]
        self._in_bits = [(s.name, s.index) for s in signals(FIELD_TO_PLC) if s.area == "IX"]
        self._in_words = [(s.name, s.index) for s in signals(FIELD_TO_PLC) if s.area == "IW"]
        self._inputs: dict[str, bool | int] = {}
        self._last_ms: int | None = None

    # --- fault injection and operator actions ------------------------------------------
    def inject(self, fault: str) -> None:
        """Activate a fault (see `FAULTS`); ValueError names the known faults."""
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {', '.join(sorted(FAULTS))}")
        self.faults.add(fault)
        if fault == "door_open":
            self.state.door_closed = False
            self.state.door_locked = False

    def clear(self, fault: str) -> None:
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {', '.join(sorted(FAULTS))}")
        self.faults.discard(fault)
        if fault == "door_open":
            self.state.door_closed = True

    def open_door(self) -> bool:
        """The operator pulls the door: refused (False) while the bolt is engaged."""
        if self.state.door_locked:
            return False
        self.state.door_closed = False
        return True

    def close_door(self) -> None:
        if "door_open" not in self.faults:
            self.state.door_closed = True

    def press_estop(self) -> None:
        self.state.estop_pressed = True

    def release_estop(self) -> None:
        self.state.estop_pressed = False

    def press(self, button: str) -> None:
        if button not in PANEL_BUTTONS:
            raise ValueError(f"unknown panel button {button!r}; one of {PANEL_BUTTONS}")
        self.state.buttons[button] = True

    def release(self, button: str) -> None:
        if button not in PANEL_BUTTONS:
            raise ValueError(f"unknown panel button {button!r}; one of {PANEL_BUTTONS}")
        self.state.buttons[button] = False

    # --- signal access -------------------------------------------------------------------
    def output(self, name: str) -> bool | int:
        """A PLC->field output as the last scan wrote it."""
        s = signal(name)
        if s.direction != PLC_TO_FIELD:
            raise ValueError(f"{s.name} is {s.direction}, not a PLC->field output")
        return self._out[s.name]

    def input(self, name: str) -> bool | int:
        """A field->PLC input as the plant reports it now."""
        s = signal(name)
        if s.direction != FIELD_TO_PLC:
            raise ValueError(f"{s.name} is {s.direction}, not a field->PLC input")
        return self.field_inputs()[s.name]

    # --- IOProvider ------------------------------------------------------------------------
    def read_inputs(self, ix: list[bool], iw: list[int], now_ms: int) -> None:
        if self._last_ms is not None and now_ms > self._last_ms:
            self.step(now_ms - self._last_ms)
        self._last_ms = now_ms
        values = self.field_inputs()
        for name, index in self._in_bits:
            ix[index] = values[name]
        for name, index in self._in_words:
            iw[index] = values[name]
        self.nc.apply_inputs(ix, iw)

    def write_outputs(self, qx: list[bool], qw: list[int], now_ms: int) -> None:
        out = self._out
        for name, index in self._out_bits:
            out[name] = qx[index]
        for name, index in self._out_words:
            out[name] = qw[index]
        self.nc.take_outputs(qx, qw)
        if self._last_ms is None:
            self._last_ms = now_ms

    # --- the plant ------------------------------------------------------------------------
    def field_inputs(self) -> dict[str, bool | int]:
        st, p, f = self.state, self.params, self.faults
        target = self._spindle_command()
        rpm = st.spindle_rpm
        tol = max(p.at_speed_tolerance_rpm, abs(target) * 0.02)
        arm = st.arm_position
        inputs: dict[str, bool | int] = {
            "EStopChainOk": not (st.estop_pressed or "estop_button" in f or "estop_chain" in f),
            "DoorClosedSw": st.door_closed,
            "DoorLockedSw": st.door_closed and st.door_locked,
            "SpindleDriveReady": st.drive_ready,
            "SpindleAtSpeedFb": st.drive_ready and target != 0 and abs(rpm - target) <= tol,
            "SpindleOriented": st.oriented,
            "SpindleZeroSpeed": abs(rpm) < p.zero_speed_rpm,
            "CoolantPressureOk": st.coolant_pressure,
            "LubeLevelOk": "lube_level_low" not in f,
            "LubePressureOk": st.lube_pressure,
            "AirPressureOk": "air_pressure_loss" not in f,
            "CarouselInPos": st.carousel_dir == 0 and st.carousel_progress_ms == 0,
            "CarouselPocket": st.carousel_pocket,
            "SpindleSpeedFb": int(round(rpm)),
        }
        for pos, name in _ARM_INPUT.items():
            inputs[name] = arm == pos
        for name in PANEL_BUTTONS:
            inputs[name] = st.buttons[name]
        return inputs

    def _spindle_command(self) -> float:
        """The speed the drive is told to reach (signed rpm; 0 when it may not turn)."""
        out, st = self._out, self.state
        if not (st.drive_ready and out["SpindleEnable"]) or out["SpindleOrient"]:
            return 0.0
        ref = min(max(int(out["SpindleSpeedRef"]), 0), self.params.spindle_max_rpm)
        if out["SpindleFwd"] and not out["SpindleRev"]:
            return float(ref)
        if out["SpindleRev"] and not out["SpindleFwd"]:
            return float(-ref)
        return 0.0

    def _spindle_target(self) -> float:
        """The speed the spindle actually ramps to (a stalled spindle gets only half)."""
        command = self._spindle_command()
        return command / 2 if "spindle_stall" in self.faults else command

    def step(self, dt_ms: int) -> None:
        """Advance the plant by `dt_ms` with the outputs of the last scan."""
        if dt_ms <= 0:
            return
        st, p, out, f = self.state, self.params, self._out, self.faults
        st.time_ms += dt_ms
        # spindle drive: ready after the enable delay; a ramp toward the target
        if out["SpindleEnable"] and "spindle_drive_fault" not in f:
            st.drive_enable_ms += dt_ms
            st.drive_ready = st.drive_enable_ms >= p.drive_ready_ms
        else:
            st.drive_enable_ms = 0
            st.drive_ready = False
        target = self._spindle_target()
        delta = p.spindle_accel_rpm_per_s * dt_ms / 1000.0
        if abs(target - st.spindle_rpm) <= delta:
            st.spindle_rpm = target
        else:
            st.spindle_rpm += delta if target > st.spindle_rpm else -delta
        # orientation: at standstill with orient on, done after orient_ms
        if (
            out["SpindleOrient"]
            and st.drive_ready
            and abs(st.spindle_rpm) < p.zero_speed_rpm
            and "orient_fail" not in f
        ):
            st.orient_ms += dt_ms
            st.oriented = st.orient_ms >= p.orient_ms
        else:
            st.orient_ms = 0
            st.oriented = False
        # coolant and lubrication pumps: pressure after a delay, gone at once when off
        st.coolant_on_ms, st.coolant_pressure = _pressure(
            out["CoolantPump"] and "coolant_pump_fail" not in f,
            st.coolant_on_ms,
            dt_ms,
            p.coolant_pressure_ms,
        )
        st.lube_on_ms, st.lube_pressure = _pressure(
            out["LubePump"] and "lube_pump_fail" not in f and "lube_level_low" not in f,
            st.lube_on_ms,
            dt_ms,
            p.lube_pressure_ms,
        )
        # door lock bolt
        if out["DoorLock"] and st.door_closed and "door_lock_fail" not in f:
            st.door_lock_ms += dt_ms
            st.door_locked = st.door_lock_ms >= p.door_lock_ms
        else:
            st.door_lock_ms = 0
            st.door_locked = False
        self._step_carousel(dt_ms)
        self._step_arm(dt_ms)

    def _step_carousel(self, dt_ms: int) -> None:
        st, p, out = self.state, self.params, self._out
        if "carousel_jam" in self.faults or "changer_jam" in self.faults:
            return
        target = int(out["CarouselTarget"])
        if not out["CarouselGo"] or not 1 <= target <= p.pockets:
            return  # stays where it is (between pockets if stopped mid-index)
        remaining = dt_ms
        while remaining > 0:
            if st.carousel_dir == 0:
                if st.carousel_pocket == target:
                    return
                ahead = (target - st.carousel_pocket) % p.pockets
                st.carousel_dir = 1 if ahead <= p.pockets - ahead else -1
            need = p.pocket_index_ms - st.carousel_progress_ms
            if remaining < need:
                st.carousel_progress_ms += remaining
                return
            remaining -= need
            st.carousel_progress_ms = 0
            st.carousel_pocket = (st.carousel_pocket - 1 + st.carousel_dir) % p.pockets + 1
            st.carousel_dir = 0

    def _step_arm(self, dt_ms: int) -> None:
        st, out = self.state, self._out
        commanded = [pos for pos, name in _ARM_OUTPUT.items() if out[name]]
        if len(commanded) != 1:
            return  # no valve (or two: a blocked valve) -> the arm holds where it is
        target = commanded[0]
        if st.arm_position == target and st.arm_target is None:
            return
        if st.arm_target != target:
            self._check_arm_move(target)
            st.arm_target = target
            st.arm_position = None
            st.arm_remaining_ms = self.params.arm_time(target)
        if (
            "arm_jam" in self.faults
            or "changer_jam" in self.faults
            or "air_pressure_loss" in self.faults
        ):
            return  # pneumatic arm: no air, no motion
        st.arm_remaining_ms -= dt_ms
        if st.arm_remaining_ms <= 0:
            st.arm_position, st.arm_target, st.arm_remaining_ms = target, None, 0
            if target == "swap":
                pocket = st.carousel_pocket - 1
                st.tool_in_spindle, st.pockets[pocket] = st.pockets[pocket], st.tool_in_spindle

    def _check_arm_move(self, target: str) -> None:
        """Record a crash when the arm would hit a turning spindle or a moving carousel."""
        st = self.state
        if target == "home":
            return
        if not st.oriented:
            st.crashes.append(f"t={st.time_ms} ms: arm to {target} with the spindle not oriented")
        if st.carousel_dir != 0 or st.carousel_progress_ms:
            st.crashes.append(f"t={st.time_ms} ms: arm to {target} with the carousel moving")


def _pressure(on: bool, on_ms: int, dt_ms: int, delay_ms: int) -> tuple[int, bool]:
    if not on:
        return 0, False
    on_ms += dt_ms
    return on_ms, on_ms >= delay_ms


PROGRAM_PATH = os.path.join(
    os.path.dirname(os.path.abspath(__file__)), "programs", "machine_tool.ld"
)


def machine_plc(
    config=None,
    params: MachineParams | None = None,
    program_path: str | None = None,
    m_functions: tuple = (),
):
    """The standard wiring: the machine-tool program in a `Runtime` with a `MachineIO`.

    Returns (runtime, io). Scan it in lockstep with `runtime.scan(now_ms)` (the plant follows
    the same virtual time) or hand the runtime to a `RealtimeRunner`. The NC talks to it
    through `io.nc` (signal names of `plc.signals`). `m_functions`: the machine's M-code
    table (`plc.m_functions.MFunction`s), compiled into the program at its slot.
    """
    io = MachineIO(params)
    path = program_path or PROGRAM_PATH
    config = config or RuntimeConfig()
    if m_functions:
        program = _with_table(path, tuple(m_functions))
    else:
        program = load_file(path)
    runtime = Runtime(program, config, io=io)
    return runtime, io


def _with_table(path: str, table: tuple):
    with open(path, encoding="utf-8") as f:
        program, sink = parse_program(f.read(), str(path))
    if sink.has_errors:
        raise LadderError(sink.sorted())
    return compile_program(with_m_functions(program, table), sink)
