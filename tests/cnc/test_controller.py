"""Controller core: lockstep rigs (IdealAxes + a fake PLC or the real machine-tool PLC) and
the basic run/stop behaviour. Other test_controller_*.py files reuse the rigs."""

from __future__ import annotations

import pytest

from cnc.controller import CommandRefused, Controller, CycleInputs, IdealAxes
from cnc.program_memory import ProgramMemory
from plc.signals import PLC_TO_NC, signals
from tests.cnc.setups import machine_coordinates

PLC_PERIOD_CYCLES = 5  # 10 ms PLC scan at a 2 ms IPO cycle


class FakePlc:
    """Answers every strobe with its finish one scan later and drops it with the strobe."""

    def __init__(self) -> None:
        self.out = {s.name: (False if s.type == "BOOL" else 0) for s in signals(PLC_TO_NC)}
        self.out.update(
            PlcReady=True,
            AxisEnable=True,
            SpindleAtSpeed=True,
            DoorClosed=True,
            DoorLocked=True,
            FeedOverride=100,
            RapidOverride=100,
            SpindleOverride=100,
        )
        self.seen: list[tuple[str, int]] = []  # (letter, code) of every strobe taken

    def scan(self, nc: dict, now_ms: int) -> None:
        for k in "MST":
            strobe = nc.get(f"{k}Strobe", False)
            if strobe and not self.out[f"{k}Finish"]:
                self.seen.append((k, nc[f"{k}Code"]))
            self.out[f"{k}Finish"] = bool(strobe)

    def outputs(self) -> dict:
        return dict(self.out)


class RealPlc:
    """The machine-tool PLC program with its simulated machine, scanned in lockstep."""

    def __init__(self) -> None:
        from plc.ladder import load_file
        from plc.machine_io import PROGRAM_PATH, MachineIO
        from plc.runtime import Runtime, RuntimeConfig

        # the scan clock is frozen: a busy test machine must not trip the PLC's watchdog
        self.io = MachineIO()
        program = load_file(PROGRAM_PATH)
        self.rt = Runtime(program, RuntimeConfig(), io=self.io, clock_ns=lambda: 0)
        self.seen: list[tuple[str, int]] = []
        self._prev = {}

    def scan(self, nc: dict, now_ms: int) -> None:
        for k in "MST":
            if nc.get(f"{k}Strobe") and not self._prev.get(f"{k}Strobe"):
                self.seen.append((k, nc[f"{k}Code"]))
        self._prev = dict(nc)
        for name, value in nc.items():
            self.io.nc.set(name, value)
        self.rt.scan(now_ms)

    def outputs(self) -> dict:
        return self.io.nc.outputs()


class Rig:
    """A controller in lockstep with IdealAxes and a PLC (fake or real)."""

    def __init__(self, machine="mill3", plc="fake", programs=None, lag_s=0.0, **kw):
        # the programs here are in machine coordinates: G54 = 0, not the factory setup
        self.config = machine_coordinates(machine)
        self.memory = ProgramMemory(self.config.program_memory_bytes)
        for number, text in (programs or {}).items():
            self.memory.store(number, text)
        self.ctl = Controller(self.config, self.memory, **kw)
        self.axes = IdealAxes(self.config, lag_s=lag_s, homing_time_s=0.05)
        self.plc = FakePlc() if plc == "fake" else RealPlc()
        self.k = 0
        self.dt = self.config.ipo_cycle_ms / 1000.0
        self.plc_in = self.plc.outputs()
        self.trace: list = []
        self.outputs = None

    @property
    def t(self) -> float:
        return self.k * self.dt

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.k += 1
            inputs = CycleInputs(self.t, self.plc_in, self.axes.feedback())
            out = self.ctl.cycle(inputs)
            self.outputs = out
            self.trace.append(out.status)
            self.axes.apply(out, self.dt)
            if self.k % PLC_PERIOD_CYCLES == 0:
                self.plc.scan(dict(out.plc), round(self.t * 1000))
                self.plc_in = self.plc.outputs()

    def until(self, cond, limit_s: float = 30.0) -> None:
        end = self.k + int(limit_s / self.dt)
        while not cond():
            if self.k >= end:
                raise AssertionError(
                    f"condition not reached within {limit_s} s; execution "
                    f"{self.ctl.execution}, alarms {self.ctl.alarms}, events "
                    f"{self.ctl.events[-5:]}"
                )
            self.step()

    def cmd(self, name: str, **args) -> None:
        self.ctl.command(name, **args)

    def home(self) -> None:
        self.step(10)  # PLC ready, drives enabled
        mode = self.ctl.mode
        self.cmd("mode", mode="REF")
        self.cmd("home")
        self.until(lambda: all(self.ctl.referenced.values()), 10)
        self.cmd("mode", mode=mode)

    def run_program(self, number: int, limit_s: float = 60.0) -> None:
        self.cmd("select_program", number=number)
        self.cmd("cycle_start")
        self.until(lambda: self.ctl.execution in ("PROGRAM_COMPLETED", "STOPPED"), limit_s)

    @property
    def ex(self) -> str:
        return self.ctl.execution

    def pos(self, axis: str) -> float:
        return self.axes.actual[axis]


SQUARE = """%
O1000
G90 G17 G21 G54
G0 X-100 Y-100 Z-50
S2000 M3
G1 Z-60 F600
G1 X-150 F1200
G1 Y-150
G1 X-100
G1 Y-100
G0 Z-50
M5
M30
%
"""


def test_cycle_start_runs_to_program_completed_and_counts_the_part():
    rig = Rig(programs={1000: SQUARE})
    rig.home()
    assert rig.ex == "READY"
    rig.cmd("select_program", number=1000)
    rig.cmd("cycle_start")
    rig.step()
    assert rig.ex == "ACTIVE"
    assert rig.outputs.plc["NcInCycle"] is True
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")
    assert rig.ctl.part_count == 1
    assert rig.outputs.status.part_count == 1
    assert rig.pos("X") == pytest.approx(-100.0, abs=1e-9)
    assert rig.pos("Z") == pytest.approx(-50.0, abs=1e-9)
    assert ("S", 2000) in rig.plc.seen and ("M", 3) in rig.plc.seen
    assert rig.plc.seen[-1] == ("M", 30)
    assert rig.ctl.cutting_time > 0 and rig.ctl.run_time > rig.ctl.cutting_time
    assert rig.ctl.spindle_time > 0
    assert not rig.outputs.plc["NcInCycle"]
    # a second cycle start runs it again
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ex == "PROGRAM_COMPLETED")
    assert rig.ctl.part_count == 2


def test_cycle_start_refused_until_homed():
    rig = Rig(programs={1000: SQUARE})
    rig.step(10)
    rig.cmd("select_program", number=1000)
    with pytest.raises(CommandRefused, match=r"machine not homed \(X, Y, Z\)"):
        rig.cmd("cycle_start")
    rig.home()
    rig.cmd("cycle_start")


def test_homing_order_is_tool_axis_first():
    rig = Rig()
    rig.step(10)
    rig.cmd("mode", mode="REF")
    rig.cmd("home")
    rig.step()
    # the tool axis alone first; X and Y together once Z is referenced
    assert rig.outputs.axis_command == "home"
    assert rig.outputs.home_axes == ("Z",)
    assert rig.ctl.home_sequence == (("Z",), ("X", "Y"))
    lathe = Rig("lathe2")
    assert lathe.ctl.home_order == ("X", "Z")
    assert lathe.ctl.home_sequence == (("X",), ("Z",))
