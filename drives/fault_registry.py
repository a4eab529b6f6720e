"""The one table of injectable drive, bus and node faults: every other list is derived from it.

One `FaultKind` row per kind says what it is (target, parameters with units, defaults and
ranges, the EMCY codes it raises, description), how the default machine detects it (bound,
or why it cannot) and how the machine comes back (recovery class and procedure), and carries
the small handlers that put the fault into the simulation and take it out again.

Derived from it: `Drive402.inject` / `clear_injection` (a dict lookup of the handlers, at
injection time only), `drives.faults.FaultInjector` and `describe()`, the machine's fault
specs (`cnc.machine.faults`), the REST `/api/fault-types` list (and so the dashboard's fault
panel), `drives.cia402.faults.INJECT_KINDS` and the generated tables in docs/drives.md,
docs/cia402.md and docs/recovery.md (`python -m drives.fault_docgen`).

Adding a kind: one row here, one small handler (plus, if the physics is new, the plant
attribute it sets); docs/drives.md "Worked example: a new drive fault kind".

The module imports only the plant (not drives.cia402 nor drives.bus): the compiled drive
application imports it, and the bus handlers reach the hub through the VirtualDrive they get.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drives.plant import Plant

if TYPE_CHECKING:  # annotations only: importing the bus would pull python-can into the drive
    from drives.virtual_drive import VirtualDrive

#: targets: "drive" (physics in the plant, `Drive402.inject`), "bus" (the axis's CAN hub),
#: "node" (the drive as a CAN node: power cycle)
TARGETS = ("drive", "bus", "node")
#: what a detection bound is counted from: the injection, or the next time the machine does
#: what shows the fault (a standing axis shows a jam at its next move; a tool changer fault
#: at the next tool change; a coolant fault while the pump runs; a stall while the spindle
#: turns; a door lock fault while the lock is commanded)
DETECT_FROM = ("injection", "next_move", "tool_change", "coolant_on", "spindle_on", "door_lock")


@dataclass(frozen=True)
class FaultParam:
    name: str
    unit: str
    default: float | None = None  # None: required
    low: float = -math.inf
    high: float = math.inf


PlantAction = Callable[[Plant, dict[str, float]], None]
PlantClear = Callable[[Plant], None]
SiteAction = Callable[["VirtualDrive", dict[str, float]], list]
SiteClear = Callable[["VirtualDrive"], None]


@dataclass(frozen=True)
class FaultKind:
    name: str
    target: str  # one of TARGETS
    description: str
    expect: str  # what the master sees
    detection: str  # how the default machine detects it, within which bound, or why it cannot
    recovery_class: str  # the row of docs/recovery.md's procedure table ("undetected": none)
    recovery: str  # what brings the machine back
    params: tuple[FaultParam, ...] = ()
    emcy: tuple[int, ...] = ()  # the drive's EMCY / 0x603F codes it can raise
    # target "drive": what the fault does to the plant, and how clearing undoes it
    on_plant: PlantAction | None = None
    off_plant: PlantClear | None = None
    # targets "bus" / "node": applied at the axis's VirtualDrive (its hub, its node); the
    # inject handler returns the hub faults it made, which clearing removes
    on_site: SiteAction | None = None
    off_site: SiteClear | None = None
    # the detection bound in seconds of machine time on the default mill (mill3), counted
    # from `detect_from`, for the parameters the `detection` text says are detected (the
    # worst of its cases); None: undetectable by design. Benches and tests judge by it.
    bound_s: float | None = None
    detect_from: str = "injection"  # one of DETECT_FROM

    @property
    def detectable(self) -> bool:
        return not self.detection.startswith("UNDETECTABLE BY DESIGN")

    def values(self, given: dict[str, float]) -> dict[str, float]:
        """The parameters with defaults filled in; ValueError says which one is wrong and why."""
        known = {p.name for p in self.params}
        extra = set(given) - known
        if extra:
            raise ValueError(
                f"fault {self.name}: unknown parameter(s) {sorted(extra)}; takes {sorted(known)}"
            )
        out: dict[str, float] = {}
        for p in self.params:
            if p.name in given:
                value = given[p.name]
            elif p.default is not None:
                value = p.default
            else:
                raise ValueError(f"fault {self.name}: parameter {p.name} ({p.unit}) is required")
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"fault {self.name}: {p.name} must be a number, got {value!r}")
            if math.isnan(value) or not (p.low <= value <= p.high):
                raise ValueError(
                    f"fault {self.name}: {p.name} = {number(value)} outside "
                    f"{number(p.low)}..{number(p.high)} {p.unit}"
                )
            out[p.name] = float(value)
        return out


def number(v: float) -> str:
    """A parameter value as people write it: 1048576, not 1.04858e+06; 0.01, -inf."""
    return str(int(v)) if math.isfinite(v) and float(v).is_integer() else f"{v:g}"


# ---------------------------------------------------------------------------- drive handlers
def _set_load_force(p: Plant, v: dict[str, float]) -> None:
    p.load_force = v["newtons"]


def _clear_load_force(p: Plant) -> None:
    p.load_force = 0.0


def _block(p: Plant, v: dict[str, float]) -> None:
    p.blocked = True


def _unblock(p: Plant) -> None:
    p.blocked = False


def _break_encoder(p: Plant, v: dict[str, float]) -> None:
    p.encoder_broken = True


def _repair_encoder(p: Plant) -> None:
    p.encoder_broken = False


def _jump_encoder(p: Plant, v: dict[str, float]) -> None:
    p.encoder_offset += int(v["counts"])


def _keep(p: Plant) -> None:
    """Nothing to undo: the effect stays (a lost count) or fades through the model (heat)."""


def _short_inverter(p: Plant, v: dict[str, float]) -> None:
    p.inverter_fault = True


def _repair_inverter(p: Plant) -> None:
    p.inverter_fault = False


def _remove_supply(p: Plant, v: dict[str, float]) -> None:
    p.supply_on = False


def _restore_supply(p: Plant) -> None:
    p.supply_on = True


def _set_mains(p: Plant, v: dict[str, float]) -> None:
    p.mains_voltage = v["volts"]


def _nominal_mains(p: Plant) -> None:
    p.mains_voltage = p.params.dc_link.mains_voltage


def _open_chopper(p: Plant, v: dict[str, float]) -> None:
    p.chopper_failed = True


def _repair_chopper(p: Plant) -> None:
    p.chopper_failed = False


def _set_ambient(p: Plant, v: dict[str, float]) -> None:
    p.ambient = v["celsius"]


def _nominal_ambient(p: Plant) -> None:
    p.ambient = p.params.thermal.ambient


def _set_winding(p: Plant, v: dict[str, float]) -> None:
    p.winding_temp = v["celsius"]


def _set_backlash(p: Plant, v: dict[str, float]) -> None:
    p.backlash = v["metres"]


def _nominal_backlash(p: Plant) -> None:
    p.backlash = p.params.screw.backlash


def _add_encoder_noise(p: Plant, v: dict[str, float]) -> None:
    p.set_encoder_noise(v["counts"])


def _remove_encoder_noise(p: Plant) -> None:
    p.set_encoder_noise(0.0)


# ---------------------------------------------------------------------------- bus handlers
def _count(v: dict[str, float]) -> int | None:
    n = int(v["count"])
    return None if n == 0 else n  # 0 = until cleared


def _drop(vd: VirtualDrive, v: dict[str, float]) -> list:
    return [vd.bus.hub.drop(None, count=_count(v), sender=vd.bus)]


def _drop_rpdo(vd: VirtualDrive, v: dict[str, float]) -> list:
    return [vd.bus.hub.drop(0x200 + vd.node_id, count=_count(v))]


def _corrupt(vd: VirtualDrive, v: dict[str, float]) -> list:
    return [vd.bus.hub.corrupt(0x180 + vd.node_id, count=_count(v))]


def _delay(vd: VirtualDrive, v: dict[str, float]) -> list:
    return [vd.bus.hub.delay(0x180 + vd.node_id, v["delay_ms"] / 1000.0, count=_count(v))]


def _bus_off(vd: VirtualDrive, v: dict[str, float]) -> list:
    vd.bus.hub.bus_off(vd.bus)
    return []


def _bus_on(vd: VirtualDrive) -> None:
    vd.bus.hub.recover(vd.bus)


def _babble(vd: VirtualDrive, v: dict[str, float]) -> list:
    vd.bus.hub.babble(int(v["can_id"]))
    return []


def _stop_babble(vd: VirtualDrive) -> None:
    vd.bus.hub.stop_babble()


def _power_cycle(vd: VirtualDrive, v: dict[str, float]) -> list:
    vd.power_cycle()
    return []


_FRAMES = FaultParam("count", "frames", 1.0, 0.0, 1e9)  # 0 = until cleared
_SUB_STEP = "1 sub-step (< 10 ms at the NC)"

_KINDS = (
    FaultKind(
        "load_force",
        "drive",
        "external force on the table (cutting force, collision; + pushes toward +x)",
        "EMCY 0x8611 / 0x2350 / 0x7121 if large",
        "above the drive's peak force: NC following error (3010) within 50 ms; "
        "a force the drive holds near its peak current: I2t 0x2350 within ~3 s",
        "overload",
        "remove the force; after I2t let the motor rest ~3 s; RESET; home (a force "
        "that outlasted the stop has pushed the unbraked table onto its hard stop, 20 mm past "
        "the limit switch: homing moves it off)",
        (FaultParam("newtons", "N", None, -1e6, 1e6),),
        (0x8611, 0x2350, 0x7121),
        _set_load_force,
        _clear_load_force,
        bound_s=3.5,
    ),
    FaultKind(
        "blocked",
        "drive",
        "mechanical jam (1000 N·m of friction)",
        "EMCY 0x8611 or 0x7121",
        "NC following error (3010) once the demand runs the NC's 1 mm limit past the jammed "
        "slide: within 50 ms on a moving axis, within 60 ms of the next move of a standing "
        "axis (a rapid from standstill); a standing axis is not detected until it is "
        "commanded to move",
        "jam",
        "free the slide; RESET; home",
        (),
        (0x8611, 0x7121),
        _block,
        _unblock,
        bound_s=0.06,
        detect_from="next_move",
    ),
    FaultKind(
        "encoder_break",
        "drive",
        "encoder signal lost",
        "EMCY 0x7305",
        f"EMCY 0x7305 within {_SUB_STEP}",
        "encoder",
        "repair the encoder cable; RESET; home (the position is lost)",
        (),
        (0x7305,),
        _break_encoder,
        _repair_encoder,
        bound_s=0.01,
    ),
    FaultKind(
        "encoder_jump",
        "drive",
        "the encoder count jumps once (clearing does not undo it)",
        "EMCY 0x7305",
        f"EMCY 0x7305 within {_SUB_STEP}",
        "encoder",
        "RESET; home (the position is lost)",
        (FaultParam("counts", "increments", float(1 << 18), -(2**31), 2**31 - 1),),
        (0x7305,),
        _jump_encoder,
        _keep,
        bound_s=0.01,
    ),
    FaultKind(
        "encoder_noise",
        "drive",
        "noise on the encoder signal (a motor cable beside an unshielded encoder cable): "
        "each reading is off by up to ±counts (uniform, pseudo-random), the position is "
        "not lost",
        "EMCY 0x7305 for large noise, following error for medium, current ripple for small",
        "large (above half the encoder plausibility step of 1.5 x max speed per sub-step, "
        "16 386 counts at 8 kHz on the default axis; the default 32 768): EMCY 0x7305 within "
        "10 ms at the NC; medium (2 000..7 000 counts, 20..70 um): the velocity loop "
        "saturates on the noisy speed and the axis lags: NC following error (3010) within 1 s; "
        "small (1 500 counts, 15 um, and less): UNDETECTABLE by the drive: no two readings "
        "differ by more than a moving axis can and the axis still follows; it shows as "
        "current ripple (the motor runs hotter, audible) and a noisy 0x60F4",
        "encoder",
        "shield and ground the encoder cable, route it away from the motor cable; RESET "
        "(refused while the noise is there); home",
        (FaultParam("counts", "increments", float(1 << 15), 0.0, float(1 << 20)),),
        (0x7305,),
        _add_encoder_noise,
        _remove_encoder_noise,
        bound_s=1.0,
    ),
    FaultKind(
        "inverter_fault",
        "drive",
        "a shorted power switch: full link voltage on the winding",
        "EMCY 0x2310",
        f"EMCY 0x2310 within {_SUB_STEP}",
        "power stage",
        "the drive needs service; RESET is refused while it is shorted",
        (),
        (0x2310,),
        _short_inverter,
        _repair_inverter,
        bound_s=0.01,
    ),
    FaultKind(
        "supply_loss",
        "drive",
        "mains removed",
        "EMCY 0x3130, then 0x3220 under load",
        "EMCY 0x3130 after 20 ms (< 30 ms at the NC)",
        "supply",
        "restore the mains; RESET; home",
        (),
        (0x3130, 0x3220),
        _remove_supply,
        _restore_supply,
        bound_s=0.03,
    ),
    FaultKind(
        "mains_voltage",
        "drive",
        "mains level (clear restores the nominal 325 V)",
        "EMCY 0x3220 (sag) / 0x3210 (swell)",
        "swell above 420 V link: EMCY 0x3210 within 1 sub-step; sag: EMCY 0x3220 "
        "once the link has sagged below 200 V (seconds, with the load: < 3 s at 150 V)",
        "supply",
        "restore the mains level; RESET; home",
        (FaultParam("volts", "V", None, 0.0, 1000.0),),
        (0x3220, 0x3210),
        _set_mains,
        _nominal_mains,
        bound_s=3.0,
    ),
    FaultKind(
        "chopper_failure",
        "drive",
        "brake chopper open",
        "EMCY 0x7111 from the drive's brake check; 0x3210 when braking lifts the link",
        "EMCY 0x7111 from the drive's brake check (every 100 ms): < 102 ms, "
        "before braking energy could lift the link to the 420 V trip (0x3210)",
        "brake chopper",
        "replace the brake chopper / resistor; RESET; home",
        (),
        (0x7111, 0x3210),
        _open_chopper,
        _repair_chopper,
        bound_s=0.102,
    ),
    FaultKind(
        "ambient_temperature",
        "drive",
        "cabinet temperature (the winding model and the heat-sink sensor)",
        "heat sink: warning bit 7 above 75 degC, EMCY 0x4210 above 85 degC; 0x4310 sooner",
        "heat-sink sensor, a first-order lag (tau = 5 s) behind the cabinet air: warning bit "
        "7 above 75 degC, EMCY 0x4210 above 85 degC after tau x ln((T - 40) / (T - 85)) from "
        "the nominal 40 degC: 11.5 s at 90 degC (machine time: a realtime cell behind its "
        "clock shows it later in wall time); the winding model's 0x4310 comes much later",
        "temperature",
        "cool the cabinet; RESET when the winding is below 130 degC; home",
        (FaultParam("celsius", "degC", None, -40.0, 200.0),),
        (0x4210, 0x4310),
        _set_ambient,
        _nominal_ambient,
        bound_s=11.6,
    ),
    FaultKind(
        "winding_temperature",
        "drive",
        "set the motor winding temperature now (it then follows the model)",
        "warning bit 7 above 130 degC, EMCY 0x4310 above 150 degC",
        "above 150 degC: EMCY 0x4310 within 1 sub-step; above 130 degC: "
        "statusword warning bit 7 only",
        "temperature",
        "let the motor cool below 130 degC; RESET; home",
        (FaultParam("celsius", "degC", None, -40.0, 300.0),),
        (0x4310,),
        _set_winding,
        _keep,
        bound_s=0.01,
    ),
    FaultKind(
        "backlash",
        "drive",
        "nut preload lost: a dead band",
        "larger contour error, no EMCY",
        "UNDETECTABLE BY DESIGN in a semi-closed loop: the motor encoder does not see "
        "the dead band between nut and table; only a second (linear) encoder or a ballbar test "
        "shows it (larger contour error at reversals)",
        "undetected",
        "re-preload or replace the nut; compensate backlash in the NC",
        (FaultParam("metres", "m", None, 0.0, 0.01),),
        (),
        _set_backlash,
        _nominal_backlash,
        bound_s=None,
    ),
    FaultKind(
        "drop",
        "bus",
        "the axis's frames are lost (its TPDOs, EMCYs, heartbeats)",
        "stale feedback, heartbeat lost (master)",
        "the machine's master: no TPDO1 for 5 SYNC cycles -> 0x8100 cyclic feedback lost "
        "(12 ms at 2 ms); heartbeat lost 0x8130 after 3 x 100 ms; one lost frame is tolerated",
        "lost feedback",
        "fix the cable / connector; RESET (the heartbeat is back); home",
        (_FRAMES,),
        on_site=_drop,
        bound_s=0.012,
    ),
    FaultKind(
        "drop_rpdo",
        "bus",
        "the master's RPDOs to the axis are lost",
        "drive holds its last target; following error, 0x8250 RPDO timeout",
        "the drive's RPDO deadline 0x1400:5 (the machine's master writes 50 ms): EMCY "
        "0x8250 RPDO timeout -> fault (0x6007 = 1) within 52 ms; one lost frame is tolerated",
        "lost commands",
        "fix the cable; RESET; home",
        (_FRAMES,),
        (0x8250,),
        on_site=_drop_rpdo,
        bound_s=0.052,
    ),
    FaultKind(
        "corrupt",
        "bus",
        "the axis's TPDO1 frames are destroyed (error frames)",
        "stale feedback",
        "the machine's master: the destroyed TPDO1s are missing -> 0x8100 cyclic "
        "feedback lost after 5 SYNC cycles (12 ms); one destroyed frame is tolerated",
        "lost feedback",
        "fix the termination / cable; RESET; home",
        (_FRAMES,),
        on_site=_corrupt,
        bound_s=0.012,
    ),
    FaultKind(
        "delay",
        "bus",
        "the axis's TPDO1 frames arrive late",
        "stale feedback",
        "the machine's master: no TPDO1 in its SYNC cycle for 5 cycles -> 0x8100 "
        "(12 ms) when the delay exceeds 5 cycles; a single late frame is tolerated",
        "lost feedback",
        "reduce the bus load; RESET; home",
        (FaultParam("delay_ms", "ms", 1.0, 0.0, 10_000.0), _FRAMES),
        on_site=_delay,
        bound_s=0.012,
    ),
    FaultKind(
        "bus_off",
        "bus",
        "the axis's CAN controller goes bus-off",
        "heartbeat lost",
        "the machine's master: no TPDO1 for 5 SYNC cycles -> 0x8100 (12 ms); heartbeat "
        "lost 0x8130 after 3 x 100 ms",
        "lost feedback",
        "fix the line; RESET (the node recovers); home",
        on_site=_bus_off,
        off_site=_bus_on,
        bound_s=0.012,
    ),
    FaultKind(
        "babble",
        "bus",
        "a babbling node floods the line with a high-priority identifier",
        "late / missing PDOs on the whole line",
        "the machine's master: the starved axes' TPDO1s missing -> 0x8100 (12 ms); "
        "heartbeats lost 0x8130 after 3 x 100 ms",
        "lost feedback",
        "remove the babbling node; RESET; home",
        (FaultParam("can_id", "", 0x001, 0x001, 0x7FF),),
        on_site=_babble,
        off_site=_stop_babble,
        bound_s=0.012,
    ),
    FaultKind(
        "power_cycle",
        "node",
        "the drive is switched off and on (boot-up, objects reset, position lost)",
        "boot-up fault at the master, axis disabled and unreferenced",
        "boot-up frame at the master: drive fault within one cycle (< 10 ms)",
        "drive reboot",
        "RESET (the master restarts the drive: NMT reset communication, PDO "
        "configuration, NMT start); home (the position is lost)",
        on_site=_power_cycle,
        bound_s=0.01,
    ),
)


def _checked(kinds: tuple[FaultKind, ...]) -> dict[str, FaultKind]:
    """The rows by name, refusing a row whose handlers do not fit its target."""
    out: dict[str, FaultKind] = {}
    for k in kinds:
        where = f"drives/fault_registry.py: fault kind {k.name!r}"
        if k.name in out:
            raise ValueError(f"{where} is listed twice")
        if k.target not in TARGETS:
            raise ValueError(f"{where}: target {k.target!r} is not one of {TARGETS}")
        if (k.target == "drive") != (k.on_plant is not None and k.off_plant is not None):
            raise ValueError(f"{where}: a drive fault has on_plant and off_plant, others not")
        if (k.target != "drive") != (k.on_site is not None):
            raise ValueError(f"{where}: a bus or node fault has on_site")
        if k.detect_from not in DETECT_FROM:
            raise ValueError(f"{where}: detect_from {k.detect_from!r} is not one of {DETECT_FROM}")
        if (k.bound_s is None) == k.detectable or (k.bound_s is not None and k.bound_s <= 0):
            raise ValueError(
                f"{where}: a detectable kind has a positive bound_s, an undetectable one None"
            )
        out[k.name] = k
    return out


#: Every injectable kind by name, in the order of the table.
FAULT_KINDS: dict[str, FaultKind] = _checked(_KINDS)
#: The physical kinds `Drive402.inject` applies to its plant.
DRIVE_FAULTS: dict[str, FaultKind] = {n: k for n, k in FAULT_KINDS.items() if k.target == "drive"}
