"""The tool tip of a 5-axis table-table machine (mill5) and its deviation from the line.

A posted 5-axis program is a list of joint positions (X Y Z B C) whose tool tips, by
forward kinematics, lie on the CAM system's straight CL segments; between two blocks the
NC interpolates the *joints* linearly, and the tool tip then bows away from the straight
line between the blocks' tips (the post bisects CL segments until that bow is <= T,
docs/cam.md). This monitor follows it every IPO cycle: the tip of the interpolated
(commanded) joints, its distance to the straight segment between the tips of the piece's
two end poses, the peak of that distance over the running program, and the same figure
for the drives' actual joints (which adds the servo lag).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from cnc.kinematics import MillBC45, kinematics_for
from cnc.params import MachineParams

Vec3 = tuple[float, float, float]


def distance_to_segment(p: Sequence[float], a: Sequence[float], b: Sequence[float]) -> float:
    """Distance from point p to the segment a-b (3-D)."""
    ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    ap = (p[0] - a[0], p[1] - a[1], p[2] - a[2])
    n2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]
    t = 0.0 if n2 <= 0.0 else (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / n2
    t = min(max(t, 0.0), 1.0)
    d = (ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2])
    return math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


class ToolTipMonitor:
    """Tool tip and deviation figures of one controller (mill5 only)."""

    def __init__(self, kin: MillBC45) -> None:
        self.kin = kin
        self.tip: Vec3 = (0.0, 0.0, 0.0)
        self.deviation = 0.0  # mm, now (commanded joints)
        self.peak = 0.0  # mm, the running or last program's peak
        self.actual_peak = 0.0  # mm, the same for the drives' actual joints
        self._ends: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self._line: tuple[Vec3, Vec3] | None = None

    @classmethod
    def for_params(cls, params: MachineParams) -> ToolTipMonitor | None:
        if params.kind != "mill5":
            return None
        kin = kinematics_for(params)
        assert isinstance(kin, MillBC45)
        return cls(kin)

    def reset(self) -> None:
        """A program starts: its peaks start at 0."""
        self.peak = self.actual_peak = self.deviation = 0.0

    def sample(self, pose: Sequence[float], motion, actual: Sequence[float] | None = None) -> None:
        """One IPO cycle: `pose` the interpolated joints, `motion` the cnc.interpolator
        Motion (for the piece under the position), `actual` the drives' joints."""
        tip = self.kin.tool_tip(pose)
        self.tip = tip
        ends = motion.segment_ends()
        if ends is None:
            self.deviation = 0.0
            return
        if ends != self._ends:
            self._ends = ends
            self._line = (self.kin.tool_tip(ends[0]), self.kin.tool_tip(ends[1]))
        assert self._line is not None
        a, b = self._line
        d = distance_to_segment(tip, a, b)
        self.deviation = d
        if d > self.peak:
            self.peak = d
        if actual is not None:
            da = distance_to_segment(self.kin.tool_tip(actual), a, b)
            if da > self.actual_peak:
                self.actual_peak = da
