"""Adaptive control constraint (ACC, NC book part 5): a cutting-load model and a feed loop.

The model estimates the spindle load from the cut (Kienzle's specific cutting force):

    f_z   = v_f / (n z)                   feed per tooth, mm (chip thickness h ~ f_z)
    k_c   = k_c1.1 h^-m_c x material      specific cutting force, N/mm^2
    a_p   = max(0, stock_top - position)  depth of cut along the depth axis, mm
    P     = a_p a_e v_f k_c / 60e6        cutting power, kW  (v_f in mm/min)
    load  = idle + 100 P / P_rated        spindle load, % of rated

The ACC loop keeps the load under a limit by lowering a factor on the feed override (never
raising it above the operator's override): an integral step on the relative excess each
IPO cycle, quantised to 1 % so the planner is not re-planned every cycle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class CuttingModel:
    """Configurable cutting-load model. Lengths in mm, machine coordinates.

    `depth_axis`/`stock_top_mm`: the depth of cut is `stock_top_mm - position(depth_axis)`
    (the tool reference point; a mill cuts below the stock top in Z). `width_mm` is the
    radial engagement a_e, `teeth` the cutter's flutes, `material_factor` scales k_c1.1
    (1.0 = the reference steel, ~0.3 aluminium)."""

    kc11: float = 1800.0  # N/mm^2, reference steel (C45 ~ 1500..2200)
    mc: float = 0.25  # Kienzle exponent
    material_factor: float = 1.0
    rated_power_kw: float = 7.5
    idle_load_pct: float = 2.0
    depth_axis: str = "Z"
    stock_top_mm: float = -100.0
    width_mm: float = 10.0
    teeth: int = 4
    min_chip_mm: float = 0.005

    def load(self, feed_mm_min: float, rpm: float, position: float | None) -> float:
        """Spindle load in % for a feed move at `feed_mm_min` with the spindle at `rpm`."""
        if rpm <= 0.0:
            return 0.0
        if position is None or feed_mm_min <= 0.0:
            return self.idle_load_pct
        depth = max(0.0, self.stock_top_mm - position)
        if depth == 0.0:
            return self.idle_load_pct
        fz = feed_mm_min / (rpm * max(1, self.teeth))
        h = max(fz, self.min_chip_mm)
        kc = self.kc11 * math.pow(h, -self.mc) * self.material_factor
        power_kw = depth * self.width_mm * feed_mm_min * kc / 60e6
        return self.idle_load_pct + 100.0 * power_kw / self.rated_power_kw


class AdaptiveLoop:
    """The ACC feed loop: `factor` in [min_factor, 1] multiplies the feed override."""

    def __init__(self, gain_per_s: float = 4.0, min_factor: float = 0.05) -> None:
        self.on = False
        self.limit_pct = 100.0
        self.gain = gain_per_s
        self.min_factor = min_factor
        self.factor = 1.0
        self._raw = 1.0

    def set(self, on: bool, limit_pct: float | None = None) -> None:
        self.on = bool(on)
        if limit_pct is not None:
            self.limit_pct = float(limit_pct)
        if not self.on:
            self.factor = self._raw = 1.0

    def update(self, load_pct: float, cutting: bool, dt: float) -> None:
        """One IPO cycle: integrate the relative excess (or deficit) of the load."""
        if not self.on:
            return
        if cutting and load_pct > 0.0:
            err = (self.limit_pct - load_pct) / self.limit_pct
            self._raw = min(1.0, max(self.min_factor, self._raw + self.gain * err * dt))
        elif not cutting:
            pass  # keep the factor through rapids and stops: the next cut starts from it
        q = math.floor(self._raw * 100.0 + 1e-9) / 100.0
        self.factor = max(self.min_factor, q)

    def state(self, cutting: bool) -> str:
        """MTConnect-style state for MachineStatus.adaptive_control."""
        if not self.on:
            return "OFF"
        if self.factor < 1.0:
            return "LIMITING"
        return "ACTIVE" if cutting else "STANDBY"
