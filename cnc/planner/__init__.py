"""Look-ahead planner: path pieces with G64 blends, per-axis limits, S-curve spans."""

from cnc.planner.geometry import Arc, Line
from cnc.planner.limits import AxisLimits
from cnc.planner.path import Path, Segment
from cnc.planner.profile import Span, partition, solve

__all__ = ["Arc", "AxisLimits", "Line", "Path", "Segment", "Span", "partition", "solve"]
