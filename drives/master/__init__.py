"""Master side: the CiA 402 axis group the NC uses (CANopen master on one or more CAN lines)."""

from drives.master.config import AxisConfig, AxisError, AxisFault, AxisFeedback
from drives.master.group import AxisGroup, CycleStats

__all__ = ["AxisConfig", "AxisError", "AxisFault", "AxisFeedback", "AxisGroup", "CycleStats"]
