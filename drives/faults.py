"""One fault-injection API for drive and bus faults, by axis name (the cell's fault endpoints).

`FAULT_KINDS` lists every kind with its parameters (name, unit, default, range) so an HTTP
endpoint can publish and validate them; `FaultInjector(drives)` applies them to the
`VirtualDrive` of an axis (physical faults go to its Drive402, bus faults to its hub).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from drives.bus.hub import SimBus
from drives.virtual_drive import VirtualDrive


@dataclass(frozen=True)
class FaultParam:
    name: str
    unit: str
    default: float | None = None  # None: required
    low: float = -math.inf
    high: float = math.inf


@dataclass(frozen=True)
class FaultKind:
    name: str
    target: str  # "drive" (physical, Drive402.inject) | "bus" (the axis's CAN hub) | "node"
    description: str
    expect: str  # what the master should see
    params: tuple[FaultParam, ...] = ()


_KINDS = (
    FaultKind(
        "load_force",
        "drive",
        "external force on the table (cutting force, collision)",
        "EMCY 0x8611 / 0x2350 / 0x7121 if large",
        (FaultParam("newtons", "N", None, -1e6, 1e6),),
    ),
    FaultKind("blocked", "drive", "mechanical jam", "EMCY 0x8611 or 0x7121"),
    FaultKind("encoder_break", "drive", "encoder signal lost", "EMCY 0x7305"),
    FaultKind(
        "encoder_jump",
        "drive",
        "encoder count jumps once",
        "EMCY 0x7305",
        (FaultParam("counts", "increments", float(1 << 18), -(2**31), 2**31 - 1),),
    ),
    FaultKind("inverter_fault", "drive", "shorted power switch", "EMCY 0x2310"),
    FaultKind("supply_loss", "drive", "mains removed", "EMCY 0x3130, then 0x3220 under load"),
    FaultKind(
        "mains_voltage",
        "drive",
        "mains level",
        "EMCY 0x3220 (sag) / 0x3210 (swell)",
        (FaultParam("volts", "V", None, 0.0, 1000.0),),
    ),
    FaultKind("chopper_failure", "drive", "brake chopper open", "EMCY 0x3210 when braking"),
    FaultKind(
        "ambient_temperature",
        "drive",
        "cabinet temperature",
        "EMCY 0x4310 sooner",
        (FaultParam("celsius", "degC", None, -40.0, 200.0),),
    ),
    FaultKind(
        "winding_temperature",
        "drive",
        "set the motor winding temperature now",
        "warning bit 7 above 130 degC, EMCY 0x4310 above 150 degC",
        (FaultParam("celsius", "degC", None, -40.0, 300.0),),
    ),
    FaultKind(
        "backlash",
        "drive",
        "nut preload lost: a dead band",
        "larger contour error, no EMCY",
        (FaultParam("metres", "m", None, 0.0, 0.01),),
    ),
    FaultKind(
        "drop",
        "bus",
        "the axis's frames are lost (its TPDOs, EMCYs, heartbeats)",
        "stale feedback, heartbeat lost (master)",
        (FaultParam("count", "frames", 1.0, 0.0, 1e9),),
    ),
    FaultKind(
        "drop_rpdo",
        "bus",
        "the master's RPDOs to the axis are lost",
        "drive holds its last target; following error",
        (FaultParam("count", "frames", 1.0, 0.0, 1e9),),
    ),
    FaultKind(
        "corrupt",
        "bus",
        "the axis's TPDO1 frames are destroyed (error frames)",
        "stale feedback",
        (FaultParam("count", "frames", 1.0, 0.0, 1e9),),
    ),
    FaultKind(
        "delay",
        "bus",
        "the axis's TPDO1 frames arrive late",
        "stale feedback",
        (
            FaultParam("delay_ms", "ms", 1.0, 0.0, 10_000.0),
            FaultParam("count", "frames", 1.0, 0.0, 1e9),
        ),
    ),
    FaultKind("bus_off", "bus", "the axis's CAN controller goes bus-off", "heartbeat lost"),
    FaultKind(
        "babble",
        "bus",
        "a babbling node floods the line with a high-priority identifier",
        "late / missing PDOs on the whole line",
        (FaultParam("can_id", "", 0x001, 0x001, 0x7FF),),
    ),
    FaultKind(
        "power_cycle",
        "node",
        "the drive is switched off and on (boot-up, objects reset, position lost)",
        "boot-up fault at the master, axis disabled and unreferenced",
    ),
)

#: Every fault kind by name, for the cell's fault endpoints.
FAULT_KINDS: dict[str, FaultKind] = {k.name: k for k in _KINDS}


def describe() -> list[dict]:
    """FAULT_KINDS as plain data (JSON for an endpoint)."""
    return [
        {
            "kind": k.name,
            "target": k.target,
            "description": k.description,
            "expect": k.expect,
            "params": [
                {"name": p.name, "unit": p.unit, "default": p.default, "min": p.low, "max": p.high}
                for p in k.params
            ],
        }
        for k in _KINDS
    ]


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

    @staticmethod
    def _params(kind: FaultKind, given: dict[str, float]) -> dict[str, float]:
        known = {p.name for p in kind.params}
        extra = set(given) - known
        if extra:
            raise ValueError(
                f"fault {kind.name}: unknown parameter(s) {sorted(extra)}; takes {sorted(known)}"
            )
        out: dict[str, float] = {}
        for p in kind.params:
            if p.name in given:
                value = given[p.name]
            elif p.default is not None:
                value = p.default
            else:
                raise ValueError(f"fault {kind.name}: parameter {p.name} ({p.unit}) is required")
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"fault {kind.name}: {p.name} must be a number, got {value!r}")
            if not (p.low <= value <= p.high) or math.isnan(value):
                raise ValueError(
                    f"fault {kind.name}: {p.name} = {value} outside {p.low}..{p.high} {p.unit}"
                )
            out[p.name] = value
        return out

    def inject(self, axis: str, kind: str, **params: float) -> None:
        """Inject `kind` on `axis`; ValueError / KeyError name what is wrong."""
        spec = FAULT_KINDS.get(kind)
        if spec is None:
            raise ValueError(f"unknown fault kind {kind!r}; known: {', '.join(FAULT_KINDS)}")
        vd = self._drive(axis)
        values = self._params(spec, params)
        if spec.target == "drive":
            vd.inject(kind, **values)
        elif spec.target == "node":
            vd.power_cycle()
        else:
            self._inject_bus(axis, vd, kind, values)
        if spec.target != "node":
            self.active[(axis, kind)] = values

    def _inject_bus(self, axis: str, vd: VirtualDrive, kind: str, p: dict[str, float]) -> None:
        if not isinstance(vd.bus, SimBus):
            raise ValueError(f"fault {kind}: axis {axis} is not on a simulated bus")
        hub, node = vd.bus.hub, vd.node_id
        count = None if p.get("count", 1) == 0 else int(p.get("count", 1))  # 0 = until cleared
        made = []
        if kind == "drop":
            made.append(hub.drop(None, count=count, sender=vd.bus))
        elif kind == "drop_rpdo":
            made.append(hub.drop(0x200 + node, count=count))
        elif kind == "corrupt":
            made.append(hub.corrupt(0x180 + node, count=count))
        elif kind == "delay":
            made.append(hub.delay(0x180 + node, p["delay_ms"] / 1000.0, count=count))
        elif kind == "bus_off":
            hub.bus_off(vd.bus)
        elif kind == "babble":
            hub.babble(int(p["can_id"]))
        self._bus_faults[(axis, kind)] = made

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
            if kind == "bus_off":
                hub.recover(vd.bus)
            elif kind == "babble":
                hub.stop_babble()

    def clear_all(self) -> None:
        for axis, kind in list(self.active):
            self.clear(axis, kind)
