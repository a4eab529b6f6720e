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

#: How each kind is detected on the default machine (what reports it, within which bound of
#: machine time from the injection, on a moving axis), or why it is not. Tested by
#: tests/cnc/test_recovery.py for every kind that a bound is given for; docs/recovery.md.
DETECTION: dict[str, str] = {
    "load_force": "above the drive's peak force: NC following error (3010) within 50 ms; "
    "a force the drive holds near its peak current: I2t 0x2350 within ~3 s",
    "blocked": "NC following error (3010) once the demand runs the NC's 1 mm limit past the "
    "jammed slide: within 50 ms on a moving axis, within 60 ms of the next move of a standing "
    "axis (a rapid from standstill); a standing axis is not detected until it is commanded to "
    "move",
    "encoder_break": "EMCY 0x7305 within 1 sub-step (< 10 ms at the NC)",
    "encoder_jump": "EMCY 0x7305 within 1 sub-step (< 10 ms at the NC)",
    "inverter_fault": "EMCY 0x2310 within 1 sub-step (< 10 ms at the NC)",
    "supply_loss": "EMCY 0x3130 after 20 ms (< 30 ms at the NC)",
    "mains_voltage": "swell above 420 V link: EMCY 0x3210 within 1 sub-step; sag: EMCY 0x3220 "
    "once the link has sagged below 200 V (seconds, with the load: < 3 s at 150 V)",
    "chopper_failure": "EMCY 0x7111 from the drive's brake check (every 100 ms): < 102 ms, "
    "before braking energy could lift the link to the 420 V trip (0x3210)",
    "ambient_temperature": "heat-sink sensor (5 s lag behind the cabinet air): warning bit 7 "
    "above 75 degC, EMCY 0x4210 above 85 degC: 11.5 s at 90 degC; the winding model's 0x4310 "
    "comes much later",
    "winding_temperature": "above 150 degC: EMCY 0x4310 within 1 sub-step; above 130 degC: "
    "statusword warning bit 7 only",
    "backlash": "UNDETECTABLE BY DESIGN in a semi-closed loop: the motor encoder does not see "
    "the dead band between nut and table; only a second (linear) encoder or a ballbar test "
    "shows it (larger contour error at reversals)",
    "drop": "the machine's master: no TPDO1 for 5 SYNC cycles -> 0x8100 cyclic feedback lost "
    "(12 ms at 2 ms); heartbeat lost 0x8130 after 3 x 100 ms; one lost frame is tolerated",
    "drop_rpdo": "the drive's RPDO deadline 0x1400:5 (the machine's master writes 50 ms): EMCY "
    "0x8250 RPDO timeout -> fault (0x6007 = 1) within 52 ms; one lost frame is tolerated",
    "corrupt": "the machine's master: the destroyed TPDO1s are missing -> 0x8100 cyclic "
    "feedback lost after 5 SYNC cycles (12 ms); one destroyed frame is tolerated",
    "delay": "the machine's master: no TPDO1 in its SYNC cycle for 5 cycles -> 0x8100 "
    "(12 ms) when the delay exceeds 5 cycles; a single late frame is tolerated",
    "bus_off": "the machine's master: no TPDO1 for 5 SYNC cycles -> 0x8100 (12 ms); heartbeat "
    "lost 0x8130 after 3 x 100 ms",
    "babble": "the machine's master: the starved axes' TPDO1s missing -> 0x8100 (12 ms); "
    "heartbeats lost 0x8130 after 3 x 100 ms",
    "power_cycle": "boot-up frame at the master: drive fault within one cycle (< 10 ms)",
}

#: What brings the machine back (docs/recovery.md): after the cause is gone, one RESET (the
#: fault reset edge 0x6040 bit 7, the master restarts a rebooted drive), then home.
RECOVERY: dict[str, str] = {
    "load_force": "remove the force; after I2t let the motor rest ~3 s; RESET; home (a force "
    "that outlasted the stop has pushed the unbraked table onto its hard stop, 20 mm past the "
    "limit switch: homing moves it off)",
    "blocked": "free the slide; RESET; home",
    "encoder_break": "repair the encoder cable; RESET; home (the position is lost)",
    "encoder_jump": "RESET; home (the position is lost)",
    "inverter_fault": "the drive needs service; RESET is refused while it is shorted",
    "supply_loss": "restore the mains; RESET; home",
    "mains_voltage": "restore the mains level; RESET; home",
    "chopper_failure": "replace the brake chopper / resistor; RESET; home",
    "ambient_temperature": "cool the cabinet; RESET when the winding is below 130 degC; home",
    "winding_temperature": "let the motor cool below 130 degC; RESET; home",
    "backlash": "re-preload or replace the nut; compensate backlash in the NC",
    "drop": "fix the cable / connector; RESET (the heartbeat is back); home",
    "drop_rpdo": "fix the cable; RESET; home",
    "corrupt": "fix the termination / cable; RESET; home",
    "delay": "reduce the bus load; RESET; home",
    "bus_off": "fix the line; RESET (the node recovers); home",
    "babble": "remove the babbling node; RESET; home",
    "power_cycle": "RESET (the master restarts the drive: NMT reset communication, PDO "
    "configuration, NMT start); home (the position is lost)",
}


def describe() -> list[dict]:
    """FAULT_KINDS as plain data (JSON for an endpoint)."""
    return [
        {
            "kind": k.name,
            "target": k.target,
            "description": k.description,
            "expect": k.expect,
            "detection": DETECTION.get(k.name, ""),
            "recovery": RECOVERY.get(k.name, ""),
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
