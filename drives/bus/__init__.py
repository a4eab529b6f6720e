"""Simulated CAN bus: bit-exact frame timing, arbitration, load account, faults, candump."""

from drives.bus.candump import CandumpWriter, candump_frame, candump_line
from drives.bus.config import open_bus
from drives.bus.frame import frame_bits, nominal_bits, worst_case_bits
from drives.bus.hub import BusLoadAccount, CanHub, SimBus, connect_network, drop_hub, get_hub
from drives.bus.loadplan import (
    BusLoadWarning,
    BusOverloadError,
    CyclicFrame,
    LoadPlan,
    axis_traffic,
    plan_load,
)

__all__ = [
    "BusLoadAccount",
    "BusLoadWarning",
    "BusOverloadError",
    "CandumpWriter",
    "CanHub",
    "CyclicFrame",
    "LoadPlan",
    "SimBus",
    "axis_traffic",
    "candump_frame",
    "candump_line",
    "connect_network",
    "drop_hub",
    "frame_bits",
    "get_hub",
    "nominal_bits",
    "open_bus",
    "plan_load",
    "worst_case_bits",
]
