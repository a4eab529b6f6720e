"""Virtual CiA 402 servo drives on a simulated CAN bus, and the master-side axis group."""

from __future__ import annotations

from importlib import import_module
from pathlib import Path
from typing import Any

#: The electronic data sheet (CiA 306) of the virtual servo drive; `canopen.import_od` loads it.
EDS_PATH = str(Path(__file__).parent / "eds" / "fmscell_servo.eds")

# Imported on first use so that `import drives` (the CLI) does not pull in python-can/canopen.
_LAZY = {
    "CanHub": "drives.bus",
    "SimBus": "drives.bus",
    "open_bus": "drives.bus",
    "connect_network": "drives.bus",
    "plan_load": "drives.bus",
    "axis_traffic": "drives.bus",
    "BusOverloadError": "drives.bus",
    "BusLoadWarning": "drives.bus",
    "CanopenSlave": "drives.cia301",
    "Drive402": "drives.cia402",
    "PlantParams": "drives.plant",
    "VirtualDrive": "drives.virtual_drive",
    "AxisGroup": "drives.master",
    "AxisConfig": "drives.master",
    "AxisFeedback": "drives.master",
    "AxisFault": "drives.master",
    "AxisError": "drives.master",
    "FaultInjector": "drives.faults",
    "FAULT_KINDS": "drives.faults",
}

__all__ = ["EDS_PATH", *_LAZY]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'drives' has no attribute {name!r}")
    return getattr(import_module(module), name)
