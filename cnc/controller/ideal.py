"""`IdealAxes`: an axis layer without drives, for tests and `nc simulate --ideal`.

Each axis follows its target perfectly (lag_s = 0) or as a first-order lag with time
constant lag_s; homing runs the axes one after the other in the order requested, each
taking `homing_time_s`, and ends at the axis' reference point (config `home_mm`); a quick
stop disables the axes (and loses every reference with `quick_stop_loses_reference`; the
controller itself drops the reference on an E-stop either way). Faults can be
injected (`inject_fault`) and a following error can be forced (`disturb`) to exercise the
controller's supervision. Pure: time advances only by `apply(outputs, dt)`.
"""

from __future__ import annotations

import math

from cnc.config import MachineConfig
from cnc.controller.contract import AxisFeedback, CycleOutputs


class IdealAxes:
    def __init__(
        self,
        config: MachineConfig,
        *,
        lag_s: float = 0.0,
        homing_time_s: float = 0.1,
        start: dict[str, float] | None = None,
        homed: bool = False,
        enabled: bool = False,
        quick_stop_loses_reference: bool = False,
    ) -> None:
        self.config = config
        self.names = tuple(config.axes)
        self.lag_s = lag_s
        self.homing_time_s = homing_time_s
        self.quick_stop_loses_reference = quick_stop_loses_reference
        mid = {n: (a.min_mm + a.max_mm) / 2.0 for n, a in config.axes.items()}
        self.actual = {n: float((start or mid).get(n, mid[n])) for n in self.names}
        self.target = dict(self.actual)
        self.homed = dict.fromkeys(self.names, homed)
        self.enabled = enabled
        self.faulted = False
        self.offset = dict.fromkeys(self.names, 0.0)  # forced following error, mm
        self._homing: list[str] = []
        self._homing_left = 0.0
        self._faults: list[tuple[str, int, str]] = []
        self.commands: list[str] = []  # every axis command received, in order

    # -- fault injection -----------------------------------------------------------------
    def inject_fault(self, axis: str, code: int, text: str, *, lose_reference: bool = False):
        """A drive fault: reported once in the next feedback; the drives drop out."""
        self._faults.append((axis, code, text))
        self.faulted = True
        self.enabled = False
        self._homing.clear()
        if lose_reference:
            self.homed[axis] = False

    def disturb(self, axis: str, mm: float) -> None:
        """Hold the actual position `mm` behind where the axis would be (a stuck slide);
        0 removes the disturbance."""
        self.actual[axis] += self.offset[axis] - mm
        self.offset[axis] = mm

    # -- the axis layer ------------------------------------------------------------------
    def feedback(self) -> AxisFeedback:
        faults, self._faults = tuple(self._faults), []
        return AxisFeedback(
            actual=dict(self.actual),
            following_error={n: self.target[n] - self.actual[n] for n in self.names},
            enabled=self.enabled,
            homed=dict(self.homed),
            homing=bool(self._homing),
            faults=faults,
        )

    def apply(self, outputs: CycleOutputs, dt: float) -> None:
        cmd = outputs.axis_command
        if cmd != "none":
            self.commands.append(cmd)
        if cmd == "enable" and not self.faulted:
            self.enabled = True
        elif cmd == "disable":
            self.enabled = False
            self._homing.clear()
        elif cmd == "quick_stop":
            self.enabled = False
            self._homing.clear()
            if self.quick_stop_loses_reference:
                self.homed = dict.fromkeys(self.names, False)
        elif cmd == "fault_reset":
            self.faulted = False
        elif cmd == "home" and self.enabled:
            self._homing = [a for a in outputs.home_axes if a in self.actual]
            self._homing_left = self.homing_time_s
        if self._homing:
            self._homing_left -= dt
            if self._homing_left <= 1e-12:
                a = self._homing.pop(0)
                self.actual[a] = self.target[a] = self.config.axes[a].home_mm
                self.homed[a] = True
                self._homing_left = self.homing_time_s
            return
        if not self.enabled:
            self.target = dict(self.actual)
            return
        alpha = 1.0 if self.lag_s <= 0.0 else 1.0 - math.exp(-dt / self.lag_s)
        for n in self.names:
            tgt = float(outputs.targets.get(n, self.target[n]))
            self.target[n] = tgt
            ideal = self.actual[n] + self.offset[n]
            self.actual[n] = ideal + (tgt - ideal) * alpha - self.offset[n]
