"""The drives' sections of a machine's configuration: `drives` (node-IDs, CAN lines, plant
overrides) and `can` (the bus). docs/configuration.md lists every key.

The drives package owns these sections: their schema (pydantic models, strict: YAML "5" is
not 5) and their rules across keys (`problems()`, paths relative to the section). The
machine's loader (`cnc.config`) places them under `machines.<NAME>` and reports each
problem with the file, line and key path; this package reads no files and knows no cell.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Sequence
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["CAN_BITRATES", "CanConfig", "DriveAxisConfig", "DrivesConfig", "Problem"]

# the bit rates a CiA 301 device supports (the config refuses any other)
CAN_BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)

#: One problem of a section: the key path below the section and the reason.
Problem = tuple[tuple[Any, ...], str]

PlantOverrides = dict[str, dict[str, Any]]  # values are checked against PlantParams


class _Section(BaseModel):
    # as every configuration section (cnc.config.Section, which drives may not import):
    # strict, unknown keys refused, a loaded section is a value
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class DriveAxisConfig(_Section):
    """One axis' drive (`drives.axes.<NAME>`)."""

    node_id: int = Field(ge=1, le=127, description="CANopen node-ID, 1..127.")
    line: int = Field(
        0,
        ge=0,
        le=3,
        description="CAN line of the drive (0 = `can.channel`, k = that channel + `.k`):"
        " a second line doubles the room for cyclic PDOs (5 axes at a 1 ms IPO cycle).",
    )
    plant: PlantOverrides = Field(
        default_factory=dict,
        description="Plant overrides for this axis, on top of `drives.plant`.",
    )


class DrivesConfig(_Section):
    """Virtual CiA 402 drives (`drives`). Plant overrides are `group: {field: value}` over
    the drives package's PlantParams groups (motor, screw, loops, encoder, dc_link,
    thermal, switches, monitor), SI units as PlantParams documents them."""

    plant: PlantOverrides = Field(
        default_factory=dict, description="Plant overrides applied to every axis."
    )
    axes: dict[str, DriveAxisConfig] = Field(
        default_factory=dict,
        description="Per-axis drive settings; node-IDs default to 1, 2, 3... in axis order.",
    )

    def node_id(self, axis: str, index: int) -> int:
        """The node-ID of `axis` (the `index`-th configured axis)."""
        entry = self.axes.get(axis)
        return entry.node_id if entry is not None else index + 1

    def line(self, axis: str) -> int:
        """The CAN line of `axis` (0 unless configured)."""
        entry = self.axes.get(axis)
        return entry.line if entry is not None else 0

    def plant_overrides(self, axis: str) -> dict[str, dict[str, Any]]:
        """Merged overrides for one axis: `PlantParams().with_(**overrides)`."""
        merged = {group: dict(values) for group, values in self.plant.items()}
        entry = self.axes.get(axis)
        if entry is not None:
            for group, values in entry.plant.items():
                merged.setdefault(group, {}).update(values)
        return merged

    def problems(self, axes: Sequence[str]) -> list[Problem]:
        """The rules across keys, for a machine with `axes` (in drive order): every drive
        names an axis of the machine, node-IDs are unique, plant overrides exist."""
        out: list[Problem] = []
        for axis in self.axes:
            if axis not in axes:
                out.append((("axes", axis), f"no such axis (axes: {' '.join(axes)})"))
        ids: dict[int, str] = {}
        for i, axis in enumerate(axes):
            nid = self.node_id(axis, i)
            if nid in ids:
                reason = f"node-ID {nid} already used by axis {ids[nid]}"
                out.append((("axes", axis, "node_id"), reason))
            ids[nid] = axis
        out.extend(_plant_problems(("plant",), self.plant))
        for axis, entry in self.axes.items():
            out.extend(_plant_problems(("axes", axis, "plant"), entry.plant))
        return out


class CanConfig(_Section):
    """The machine's CAN bus (`can`)."""

    interface: Literal["sim", "socketcan", "virtual"] = Field(
        "sim", description="`sim` (simulated bus), `socketcan` (real), `virtual` (python-can)."
    )
    channel: str | None = Field(
        None, description="Bus channel (`can0` for socketcan); null = the machine's name."
    )
    bitrate: int = Field(
        1_000_000, description="Bit rate, bit/s: one of the CiA 301 rates 10k … 1M."
    )

    def bus_config(self, machine: str) -> dict[str, Any]:
        """The mapping `drives.bus.open_bus` takes."""
        return {
            "interface": self.interface,
            "channel": self.channel or machine,
            "bitrate": self.bitrate,
        }

    def problems(self) -> list[Problem]:
        if self.bitrate in CAN_BITRATES:
            return []
        rates = ", ".join(str(r) for r in CAN_BITRATES)
        return [(("bitrate",), f"must be one of {rates}, got {self.bitrate}")]


def _plant_problems(path: tuple[Any, ...], plant: PlantOverrides) -> list[Problem]:
    """Override groups and fields must exist in PlantParams, with values of their type."""
    if not plant:
        return []
    # deferred: the plant model is imported only by configurations that override it (start-up
    # cost of the machine CLIs, which load a machine file first)
    from drives.plant.params import PlantParams

    out: list[Problem] = []
    defaults = PlantParams()
    groups = [f.name for f in dataclasses.fields(PlantParams)]
    for group, values in plant.items():
        if group not in groups:
            out.append(((*path, group), "unknown plant group" + _hint(group, groups)))
            continue
        current = getattr(defaults, group)
        names = [f.name for f in dataclasses.fields(current)]
        for key, value in values.items():
            if key not in names:
                out.append(((*path, group, key), "unknown plant parameter" + _hint(key, names)))
                continue
            default = getattr(current, key)
            if not isinstance(value, int | float) or (
                isinstance(value, float) and not math.isfinite(value)
            ):
                want = "true or false" if isinstance(default, bool) else "a finite number"
                out.append(((*path, group, key), f"must be {want}, got {_shown(value)}"))
            elif isinstance(default, bool) != isinstance(value, bool):
                want = "true or false" if isinstance(default, bool) else "a number"
                out.append(((*path, group, key), f"must be {want}, got {_shown(value)}"))
            elif isinstance(default, int) and not isinstance(value, int):
                out.append(((*path, group, key), f"must be an integer, got {_shown(value)}"))
    return out


def _hint(key: str, names: list[str]) -> str:
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
    hint = f"did you mean '{close[0]}'? " if close else ""
    return f" ({hint}known: {', '.join(names)})"


def _shown(value: Any) -> str:
    """A value as the YAML file wrote it (true, 1.5, inf, 'fine')."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return f"{value:g}"
    return "null" if value is None else repr(value)
