"""TEST DOUBLE (clearly a stand-in): a minimal controller with the `cnc.controller` contract.

The real controller is being written in parallel (cnc/controller). Until it lands, the
machine's composition is tested against this stand-in: it runs the real interpreter and the
real planner/interpolator (`cnc.interpolator.Motion`), talks to the real PLC through the
declared signals (M/S/T strobe and finish, CycleStart, FeedHold, EStopActive, AxisEnable)
and to the axis layer through axis commands. It is deliberately small: AUTO and REF modes,
homing, cycle start, feed hold, reset, E-stop, drive-fault alarms, NC following-error
supervision. Everything the machine does with it goes through the contract only, so the
same tests run unchanged against the real `cnc.controller.Controller`.
"""

from __future__ import annotations

import time

from cnc import canon
from cnc.faces.drip import DripBuffer
from cnc.interp import Interpreter, ToolOffset
from cnc.interpolator.motion import Motion
from cnc.machine.contract import CycleOutputs
from cnc.status import Alarm, AxisStatus, MachineStatus

FE_LIMIT_MM = 40.0  # the drives lag ~60 ms without feed-forward: 30 mm at rapid


def _drip_lines(buffer):
    """Blocks as the DNC port delivers them. The wait is for the network (the host sending),
    not for the simulation: in lockstep the machine cannot run ahead of its tape."""
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        block = buffer.take()
        if block is None:
            return
        if block is False:
            if buffer.aborted:
                return
            time.sleep(0.0005)
            continue
        deadline = time.monotonic() + 10.0
        yield block


class CommandRefused(Exception):
    pass


class StandInController:
    def __init__(self, config, memory, *, tools=None, work_offsets=None, cutting_model=None):
        self.config, self.memory = config, memory
        self.params = config.params
        self.axes = tuple(config.axes)
        self.mode = "AUTO"
        self.execution = "READY"
        self.program: int | None = None
        self.alarms: list[Alarm] = []
        self.homed = dict.fromkeys(self.axes, False)
        self._pending_axis = "none"
        self._home_req = False
        self._motion: Motion | None = None
        self._commands = None
        self._sync = None  # (signal strobe, finish) in progress
        self._estop = False
        self._hold = False
        self._start_req = False
        self._tools = tools or {1: ToolOffset(length=100.0, radius=5.0)}
        self._targets: dict[str, float] = {}
        self._line = 0
        self._t = 0.0
        self._dwell_until = None
        self._drip = None
        self._keep_targets = False
        self.blocks_done = 0
        self.status = MachineStatus()

    # -- contract: commands -------------------------------------------------------------
    def command(self, name, **args):
        if name == "mode":
            if self.execution in ("ACTIVE", "FEED_HOLD", "INTERRUPTED"):
                raise CommandRefused(f"mode change refused: program active ({self.execution})")
            self.mode = args["mode"]
        elif name == "home":
            if self.mode != "REF":
                raise CommandRefused(f"home refused: mode is {self.mode}, select REF first")
            self._home_req = True
        elif name == "select_program":
            n = args["number"]
            if n not in self.memory:
                raise CommandRefused(f"O{n:04d} is not in program memory")
            self.program = n
        elif name == "cycle_start":
            self._start_req = True
        elif name in ("reset", "alarm_reset"):
            self._reset()
        else:
            raise CommandRefused(f"{name}: not supported by the test stand-in")

    def drip_input(self):
        """A drip-feed (BTR) buffer the next cycle start executes from (AUTO, idle only)."""
        if self._motion is not None or self.mode != "AUTO":
            return None
        self._drip = DripBuffer(1024)
        self.program = None
        return self._drip

    def policy(self, op, number):
        if op == "READ" and number == self.program and self.execution == "ACTIVE":
            return f"O{number:04d} is running"
        return None

    def _reset(self):
        self.alarms = [a for a in self.alarms if a.source == "PLC"]
        self._motion = None
        self._sync = None
        self.execution = "READY"
        if not self._estop:
            self._pending_axis = "fault_reset"

    def _alarm(self, number, text, source="NC", axis=None):
        if not any(a.number == number and a.axis == axis for a in self.alarms):
            self.alarms.append(Alarm(number, text, source, axis=axis, time=self._t))
        if self._motion is not None:
            self._motion = None
            self.execution = "INTERRUPTED"

    # -- contract: cycle ----------------------------------------------------------------
    def cycle(self, inputs):
        self._t = inputs.t
        plc, fb = inputs.plc, inputs.axes
        axis_cmd, self._pending_axis = self._pending_axis, "none"
        out_plc = {"NcReady": True, "NcMode": {"AUTO": 1, "MDI": 2, "JOG": 3, "REF": 4}[self.mode]}
        if plc.get("EStopActive") and not self._estop:
            self._estop = True
            axis_cmd = "quick_stop"
            self.homed = dict.fromkeys(self.axes, False)
            self._alarm(3001, "emergency stop: axes quick-stopped, reference lost")
        elif not plc.get("EStopActive"):
            self._estop = False
        for axis, code, text in fb.faults:
            self._alarm(4000 + (code & 0xFFF), f"drive {axis}: {text}", "DRIVE", axis)
        for axis, fe in fb.following_error.items():
            if fb.enabled and abs(fe) > FE_LIMIT_MM:
                self._alarm(3010, f"following error {axis} {fe:.3f} mm", "NC", axis)
        if (
            axis_cmd == "none"
            and plc.get("AxisEnable")
            and not fb.enabled
            and not self._estop
            and not any(a.source == "DRIVE" for a in self.alarms)
        ):
            axis_cmd = "enable"
        if axis_cmd == "none" and self._home_req and fb.enabled:
            self._home_req = False
            axis_cmd = "home"
        for a, h in fb.homed.items():
            if h:
                self.homed[a] = True
            elif fb.homed.get(a) is False and axis_cmd != "home":
                self.homed[a] = self.homed[a] and True
        self.homed = {a: bool(fb.homed.get(a)) for a in self.axes}
        start = self._start_req or plc.get("CycleStart")
        self._start_req = False
        ready = self.program is not None or self._drip is not None
        if start and self._motion is None and not self.alarms and ready:
            if not all(self.homed.values()):
                self._alarm(3020, "cycle start refused: axes not referenced", "NC")
            else:
                self._begin(fb)
        self._hold = bool(plc.get("FeedHold"))
        if self._motion is not None:
            self._run(plc, out_plc, start)
        elif axis_cmd != "none" or not fb.enabled or not self._keep_targets:
            self._keep_targets = False
            self._targets = dict(fb.actual)
        out_plc["NcInCycle"] = self._motion is not None
        out_plc["NcAlarm"] = bool(self.alarms)
        alarms = tuple(self.alarms)
        if plc.get("PlcAlarm"):
            alarms += (Alarm(plc.get("PlcAlarmNumber"), "PLC alarm", "PLC"),)
        self.status = MachineStatus(
            execution=self.execution,
            mode_detail=self.mode if self.mode in ("AUTO", "MDI", "JOG", "REF") else "AUTO",
            controller_mode={"AUTO": "AUTOMATIC", "MDI": "MANUAL_DATA_INPUT"}.get(
                self.mode, "MANUAL"
            ),
            program=f"O{self.program:04d}" if self.program else "",
            line=self._line,
            axes={
                a: AxisStatus(fb.actual.get(a, 0.0), self._targets.get(a, 0.0)) for a in self.axes
            },
            alarms=alarms,
            emergency_stop="TRIGGERED" if self._estop else "ARMED",
        )
        return CycleOutputs(dict(self._targets), axis_cmd, (), out_plc, self.status)

    def _begin(self, fb):
        text = self.memory.get(self.program) if self._drip is None else _drip_lines(self._drip)
        start = tuple(fb.actual.get(a, 0.0) for a in ("X", "Y", "Z"))
        interp = Interpreter(self.params, tools=self._tools, start=start)
        self._commands = iter(interp.run(text))
        self._motion = Motion(self.params, start=start)
        self.execution = "ACTIVE"
        self.blocks_done = 0

    def _run(self, plc, out_plc, start):
        m = self._motion
        while m.space() > 0 and self._commands is not None:
            cmd = next(self._commands, None)
            if cmd is None:
                self._commands = None
                m.end_of_program()
                break
            m.push(cmd)
        if self._hold:
            m.feed_hold()
            self.execution = "FEED_HOLD"
        elif self.execution == "FEED_HOLD" and start:
            m.resume()
            self.execution = "ACTIVE"
        if self._sync is not None:
            self._handshake(plc, out_plc)
            return
        s = m.step()
        self._targets = dict(zip(("X", "Y", "Z"), s.pose, strict=True))
        if s.line != self._line:
            self.blocks_done += 1
            self._line = s.line
        if s.sync is not None:
            self._start_sync(s.sync, out_plc)
        if m.idle and self._commands is None and self._sync is None:
            self._motion = None
            self._keep_targets = True  # hold the last setpoint: the axes settle onto it
            self.execution = "PROGRAM_COMPLETED"

    def _start_sync(self, cmd, out_plc):
        if isinstance(cmd, canon.ToolChange):
            self._sync = ("MStrobe", "MFinish", {"MCode": 6})
        elif isinstance(cmd, canon.ToolSelect):
            self._sync = ("TStrobe", "TFinish", {"TCode": cmd.tool})
        elif isinstance(cmd, canon.Spindle):
            code = {"M3": 3, "M4": 4, "M5": 5, "M19": 19}[cmd.direction.value]
            self._sync = ("MStrobe", "MFinish", {"MCode": code, "SCode": int(cmd.rpm)})
        elif isinstance(cmd, canon.Coolant):
            self._sync = ("MStrobe", "MFinish", {"MCode": 8 if cmd.flood else 7 if cmd.mist else 9})
        elif isinstance(cmd, canon.AuxFunction):
            self._sync = ("MStrobe", "MFinish", {"MCode": cmd.code})
        else:
            self._motion.acknowledge()
            return
        self._strobe_on = False

    def _handshake(self, plc, out_plc):
        strobe, finish, codes = self._sync
        out_plc.update(codes)
        if not self._strobe_on:
            self._strobe_on = True
            out_plc[strobe] = True
        elif plc.get(finish):
            out_plc[strobe] = False
            self._sync = None
            self._motion.acknowledge()
        else:
            out_plc[strobe] = True


def test_stand_in_refuses_home_outside_ref_mode():
    from cnc.config import builtin_machine
    from cnc.program_memory import ProgramMemory

    c = StandInController(builtin_machine("mill3"), ProgramMemory(4096))
    try:
        c.command("home")
    except CommandRefused as exc:
        assert "REF" in str(exc)
    else:
        raise AssertionError("home in AUTO must be refused")
