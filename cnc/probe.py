"""The skip signal's source: a tool-length sensor (tool setter) fixed on the machine.

A tool setter is a disc of `radius` at `x`, `y` (machine coordinates, mm) whose contact
plane is at `z_trigger`: it switches the skip signal when the tool's end, pressing along
the spindle axis Z, reaches that plane over the disc. The tool's end is a flat disc of
the tool's radius around the spindle axis (a face mill is measured on its cutting edge,
off its axis) at the spindle's gauge line (the machine position) minus the tool length
the control knows: the sensor sees what the control believes the tool to be, and a G31
towards it measures that (docs/gcode.md, "G31 skip and the tool setter").

Pure geometry, shared by the two users: the interpreter decides a G31 from its
programmed path in `nc check` / `nc plan` (`first_trip`), the real-time controller
tests the encoder position every IPO cycle (`trips`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_EPS = 1e-9


@dataclass(frozen=True, slots=True)
class ToolSetter:
    """A tool-length sensor in machine coordinates (mm)."""

    x: float
    y: float
    z_trigger: float
    radius: float = 5.0

    def trips(self, tip: tuple[float, ...], tool_radius: float = 0.0) -> bool:
        """Whether the sensor switches with the tool's end centred at `tip` (X Y Z, machine
        mm), a disc of `tool_radius`."""
        dx, dy = tip[0] - self.x, tip[1] - self.y
        reach = self.radius + max(tool_radius, 0.0)
        return tip[2] <= self.z_trigger + _EPS and dx * dx + dy * dy <= reach * reach + _EPS

    def first_trip(
        self,
        start: tuple[float, ...],
        end: tuple[float, ...],
        tool_length: float,
        tool_radius: float = 0.0,
    ) -> tuple[float, float, float] | None:
        """The first machine position (gauge line, X Y Z) on the straight move `start` ->
        `end` at which the sensor switches, or None when it never does; a move that
        starts with the tip already on the sensor switches at its start."""
        sx, sy, sz = start[0], start[1], start[2] - tool_length
        dx, dy, dz = end[0] - start[0], end[1] - start[1], end[2] - start[2]
        # t in [lo, hi] where the tip is at or below the contact plane
        lo, hi = 0.0, 1.0
        gap = self.z_trigger - sz  # the plane is reached when dz * t <= gap
        if abs(dz) < _EPS:
            if gap < -_EPS:
                return None
        elif dz < 0.0:
            lo = max(lo, gap / dz)
        else:
            hi = min(hi, gap / dz)
        # and over the disc: |(s - c) + t d|^2 <= (r + tool radius)^2 in X Y
        ox, oy = sx - self.x, sy - self.y
        reach = self.radius + max(tool_radius, 0.0)
        a = dx * dx + dy * dy
        b = 2.0 * (ox * dx + oy * dy)
        c = ox * ox + oy * oy - reach * reach
        if a < _EPS:
            if c > _EPS:
                return None
        else:
            disc = b * b - 4.0 * a * c
            if disc < 0.0:
                return None
            root = math.sqrt(disc)
            lo = max(lo, (-b - root) / (2.0 * a))
            hi = min(hi, (-b + root) / (2.0 * a))
        if lo > hi + _EPS:
            return None
        t = max(lo, 0.0)
        return (start[0] + t * dx, start[1] + t * dy, start[2] + t * dz)
