"""One fault-injection API for drive and bus faults, by axis name (the cell's fault endpoints).

`FAULT_KINDS` (the rows of `drives.fault_registry`) lists every kind with its parameters
(name, unit, default, range) so an HTTP endpoint can publish and validate them;
`FaultInjector(drives)` applies them to the `VirtualDrive` of an axis (physical faults go to
its Drive402, bus faults to its hub, through the row's handlers).
"""

from __future__ import annotations

import math

from drives.bus.hub import SimBus
from drives.cia402.faults import spec
from drives.fault_registry import FAULT_KINDS, FaultKind, FaultParam
from drives.virtual_drive import VirtualDrive

__all__ = [
    "DETECTION",
    "FAULT_KINDS",
    "RECOVERY",
    "FaultInjector",
    "FaultKind",
    "FaultParam",
    "describe",
    "error_register",
    "fault_types",
]


#: How each kind is detected on the default machine (what reports it, within which bound of
#: machine time from the injection, on a moving axis), or why it is not. Tested by
#: tests/cnc/test_recovery.py for every kind that a bound is given for; docs/recovery.md.
DETECTION: dict[str, str] = {k.name: k.detection for k in FAULT_KINDS.values()}

#: What brings the machine back (docs/recovery.md): after the cause is gone, one RESET (the
#: fault reset edge 0x6040 bit 7, the master restarts a rebooted drive), then home.
RECOVERY: dict[str, str] = {k.name: k.recovery for k in FAULT_KINDS.values()}


def error_register(kind: FaultKind) -> int:
    """The 0x1001 bits the kind's EMCY codes set (CiA 301), 0 for a kind without a code."""
    out = 0
    for code in kind.emcy:
        out |= spec(code).register
    return out


def describe() -> list[dict]:
    """FAULT_KINDS as plain data (JSON for an endpoint)."""
    return [
        {
            "kind": k.name,
            "target": k.target,
            "description": k.description,
            "expect": k.expect,
            "emcy": [f"0x{code:04X}" for code in k.emcy],
            "error_register": error_register(k),
            "detection": k.detection,
            "bound_s": k.bound_s,
            "detect_from": k.detect_from,
            "recovery_class": k.recovery_class,
            "recovery": k.recovery,
            "params": [
                {
                    "name": p.name,
                    "unit": p.unit,
                    "default": p.default,
                    "min": None if math.isinf(p.low) else p.low,  # None: unbounded
                    "max": None if math.isinf(p.high) else p.high,
                }
                for p in k.params
            ],
        }
        for k in FAULT_KINDS.values()
    ]


def fault_types() -> list[dict]:
    """The REST `/api/fault-types` rows of every drive, bus and node kind (`describe()` with
    the spec's words: `type`, and `target` as the spec writes the axis)."""
    out = []
    for row in describe():
        kind = row.pop("kind")
        target = "bus:<AXIS>" if row.pop("target") == "bus" else "drive:<AXIS>"
        out.append({"type": kind, "target": target, **row})
    return out


class FaultInjector:
    """Inject and clear faults by axis name: `FaultInjector({"X": vd_x, ...})`."""

    def __init__(self, drives: dict[str, VirtualDrive]) -> None:
        self.drives = dict(drives)
        self._bus_faults: dict[tuple[str, str], list] = {}
        self.active: dict[tuple[str, str], dict[str, float]] = {}

    def _drive(self, axis: str) -> VirtualDrive:
        try:
            return self.drives[axis]
        except KeyError:
            raise KeyError(f"unknown axis {axis!r}; axes: {', '.join(self.drives)}") from None

    def inject(self, axis: str, kind: str, **params: float) -> None:
        """Inject `kind` on `axis`; ValueError / KeyError name what is wrong."""
        spec = FAULT_KINDS.get(kind)
        if spec is None:
            raise ValueError(f"unknown fault kind {kind!r}; known: {', '.join(FAULT_KINDS)}")
        vd = self._drive(axis)
        values = spec.values(params)
        if spec.target == "drive":
            vd.inject(kind, **values)
        else:
            if spec.target == "bus" and not isinstance(vd.bus, SimBus):
                raise ValueError(f"fault {kind}: axis {axis} is not on a simulated bus")
            assert spec.on_site is not None
            made = spec.on_site(vd, values)
            if spec.target == "bus":
                self._bus_faults[(axis, kind)] = made
        if spec.target != "node":
            self.active[(axis, kind)] = values

    def clear(self, axis: str, kind: str) -> None:
        """Remove an injected fault (a tripped drive still needs a fault reset)."""
        spec = FAULT_KINDS.get(kind)
        if spec is None:
            raise ValueError(f"unknown fault kind {kind!r}; known: {', '.join(FAULT_KINDS)}")
        vd = self._drive(axis)
        self.active.pop((axis, kind), None)
        if spec.target == "drive":
            vd.clear_injection(kind)
        elif spec.target == "bus" and isinstance(vd.bus, SimBus):
            hub = vd.bus.hub
            for fault in self._bus_faults.pop((axis, kind), []):
                if fault in hub.faults:
                    hub.faults.remove(fault)
            if spec.off_site is not None:
                spec.off_site(vd)

    def clear_all(self) -> None:
        for axis, kind in list(self.active):
            self.clear(axis, kind)
