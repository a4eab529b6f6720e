"""Fault specs: `target:kind@time`, parsed, scheduled in virtual time, applied to a machine.

Grammar (one spec, no spaces)::

    drive:<AXIS>:<kind>[:<param>=<value>[,<param>=<value>...]]@<time>
    bus:<kind>:<AXIS>[:<param>=<value>...]@<time>
    plc:<kind>@<time>

`<time>` is seconds of machine time since power-on: `1.5s`, `1500ms` or a bare number
(seconds). Examples: `drive:X:encoder@1.5s`, `drive:Y:following_error@2s`,
`drive:Z:mains_voltage:volts=250@1s`, `bus:bus_off:X@3s`, `bus:drop:Y:count=0@2s`,
`plc:door_open@2s`, `plc:estop@4s`, `plc:air_pressure_loss@1s`.

Drive and bus kinds are the rows of `drives.fault_registry.FAULT_KINDS` plus the aliases
below; plc kinds are those of `plc.machine_io.FAULTS` plus `estop` (= `estop_button`).
Parsing is pure; `FaultSchedule` hands out the specs that are due at a machine time.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from cnc.errors import CncError

# Short names in the operator's words -> (drives.faults kind, default parameters).
DRIVE_ALIASES: dict[str, tuple[str, dict[str, float]]] = {
    "encoder": ("encoder_break", {}),
    "following_error": ("blocked", {}),
    "overcurrent": ("inverter_fault", {}),
    "undervoltage": ("supply_loss", {}),
    "overtemperature": ("winding_temperature", {"celsius": 160.0}),
}
PLC_ALIASES = {"estop": "estop_button"}

_TIME = re.compile(r"^(?P<num>[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?P<unit>s|ms)?$")
_AXIS = re.compile(r"^[XYZABCUVW]$")


class FaultSpecError(CncError, ValueError):
    """A spec that does not parse or names an unknown kind; the message lists the valid ones."""


@dataclass(frozen=True)
class FaultSpec:
    """One parsed spec. `kind` is the underlying kind (aliases resolved)."""

    target: str  # "drive" | "bus" | "node" | "plc"
    kind: str
    axis: str | None
    params: dict[str, float] = field(default_factory=dict)
    at_s: float = 0.0
    text: str = ""

    def __str__(self) -> str:
        return self.text or f"{self.target}:{self.kind}@{self.at_s}s"


def _drive_kinds() -> dict:
    # deferred: `cnc` does not load the drive package until a fault names one
    from drives.fault_registry import FAULT_KINDS

    return FAULT_KINDS


def _plc_faults() -> dict[str, str]:
    from plc.machine_io import FAULTS  # deferred: nor the PLC (its runtime), as above

    return FAULTS


def valid_specs() -> list[str]:
    """Every accepted spec form, one per kind (for error messages and `--help`)."""
    kinds = _drive_kinds()
    out: list[str] = []
    for name, kind in kinds.items():
        params = "".join(f":{p.name}=<{p.unit or 'n'}>" for p in kind.params if p.default is None)
        if kind.target == "bus":
            out.append(f"bus:{name}:<AXIS>{params}@<t>")
        else:
            out.append(f"drive:<AXIS>:{name}{params}@<t>")
    out += [f"drive:<AXIS>:{alias}@<t>" for alias in DRIVE_ALIASES]
    out += [f"plc:{name}@<t>" for name in (*_plc_faults(), *PLC_ALIASES)]
    return out


def _fail(text: str, why: str) -> FaultSpecError:
    return FaultSpecError(f"fault spec {text!r}: {why}\n  valid specs: " + ", ".join(valid_specs()))


def parse_time(text: str, spec: str = "") -> float:
    m = _TIME.match(text.strip())
    if not m:
        raise _fail(spec or text, f"time {text!r} is not a number of s or ms (e.g. 1.5s, 200ms)")
    value = float(m["num"]) / (1000.0 if m["unit"] == "ms" else 1.0)
    if not math.isfinite(value):
        raise _fail(spec or text, f"time {text!r} is not finite")
    return value


def _params(spec: str, parts: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for part in ",".join(parts).split(","):
        if not part:
            continue
        name, eq, value = part.partition("=")
        if not eq or not name:
            raise _fail(spec, f"parameter {part!r} is not name=value")
        try:
            out[name] = float(value)
        except ValueError:
            raise _fail(spec, f"parameter {name} = {value!r} is not a number") from None
    return out


def parse_fault_spec(text: str, axes: tuple[str, ...] | None = None) -> FaultSpec:
    """Parse one spec; `axes` (the machine's) makes unknown axis names an error too."""
    spec = text.strip()
    if "@" in spec:
        body, _, when = spec.rpartition("@")
        at_s = parse_time(when, spec)
    else:
        body, at_s = spec, 0.0
    fields = body.split(":")
    target = fields[0]
    if target == "plc":
        if len(fields) != 2:
            raise _fail(spec, "a PLC fault is plc:<kind>@<time>")
        kind = PLC_ALIASES.get(fields[1], fields[1])
        if kind not in _plc_faults():
            raise _fail(spec, f"unknown PLC fault {fields[1]!r}")
        return FaultSpec("plc", kind, None, {}, at_s, spec)
    if target in ("drive", "bus"):
        if len(fields) < 3:
            raise _fail(spec, f"a {target} fault names an axis and a kind")
        axis, kind = (fields[1], fields[2]) if target == "drive" else (fields[2], fields[1])
        params = _params(spec, fields[3:])
        if not _AXIS.match(axis):
            raise _fail(spec, f"{axis!r} is not an axis name")
        if axes is not None and axis not in axes:
            raise _fail(spec, f"axis {axis} is not on this machine (axes: {', '.join(axes)})")
        if target == "drive" and kind in DRIVE_ALIASES:
            kind, defaults = DRIVE_ALIASES[kind]
            params = {**defaults, **params}
        known = _drive_kinds().get(kind)
        if known is None:
            raise _fail(spec, f"unknown {target} fault {kind!r}")
        if (known.target == "bus") != (target == "bus"):
            raise _fail(
                spec,
                f"{kind} is a {known.target} fault: write it as "
                + (f"bus:{kind}:{axis}" if known.target == "bus" else f"drive:{axis}:{kind}"),
            )
        declared = {p.name: p for p in known.params}
        for name, value in params.items():
            p = declared.get(name)
            if p is None:
                raise _fail(spec, f"{kind} takes no parameter {name!r} (takes {sorted(declared)})")
            if not p.low <= value <= p.high:
                raise _fail(spec, f"{name} = {value:g} outside {p.low:g}..{p.high:g} {p.unit}")
        missing = [p.name for p in known.params if p.default is None and p.name not in params]
        if missing:
            raise _fail(spec, f"{kind} needs {', '.join(missing)}")
        return FaultSpec(known.target, kind, axis, params, at_s, spec)
    raise _fail(spec, f"unknown target {target!r} (drive, bus or plc)")


class FaultSchedule:
    """Specs ordered by time; `due(t)` returns (once) those whose time has come."""

    def __init__(self, specs: list[FaultSpec] | tuple[FaultSpec, ...] = ()) -> None:
        self._pending = sorted(specs, key=lambda s: s.at_s)

    def add(self, spec: FaultSpec) -> None:
        self._pending.append(spec)
        self._pending.sort(key=lambda s: s.at_s)

    @property
    def pending(self) -> tuple[FaultSpec, ...]:
        return tuple(self._pending)

    def due(self, t_s: float) -> list[FaultSpec]:
        pending = self._pending
        # half a microsecond of slack: t is a multiple of the IPO cycle in floating point
        if not pending or pending[0].at_s > t_s + 5e-7:
            return []  # every cycle but the one a fault is due in: no list slicing
        n = 0
        while n < len(self._pending) and self._pending[n].at_s <= t_s + 5e-7:
            n += 1
        out, self._pending = self._pending[:n], self._pending[n:]
        return out
