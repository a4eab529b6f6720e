"""The machine: controller + CiA 402 drives on a simulated CAN bus + soft-PLC, and its faces.

Public API: `Machine` (lockstep `step` / `run_until`), `RealtimeRunner`, the axis layers
`CanopenAxes` and `IdealAxes`, and the fault specs (`parse_fault_spec`, `FaultSpec`,
`FaultSpecError`, `valid_specs`). See docs/machine.md.
"""

from cnc.machine.faults import (
    FaultSchedule,
    FaultSpec,
    FaultSpecError,
    parse_fault_spec,
    valid_specs,
)

__all__ = [
    "CanopenAxes",
    "FaultSchedule",
    "FaultSpec",
    "FaultSpecError",
    "IdealAxes",
    "Machine",
    "RealtimeRunner",
    "parse_fault_spec",
    "valid_specs",
]


def __getattr__(name: str):
    # drives, canopen and the PLC load on first use: `import cnc.machine` stays cheap
    if name == "Machine":
        from cnc.machine.machine import Machine  # deferred: start-up cost (above)

        return Machine
    if name == "RealtimeRunner":
        from cnc.machine.runner import RealtimeRunner  # deferred: start-up cost (above)

        return RealtimeRunner
    if name in ("CanopenAxes", "IdealAxes"):
        from cnc.machine import axes  # deferred: start-up cost (above)

        return getattr(axes, name)
    raise AttributeError(f"module 'cnc.machine' has no attribute {name!r}")
