"""Plain data the interpreter takes in (tool offsets) and gives out (modal state snapshots)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class ToolOffset:
    """One entry of the tool offset memory, in mm.

    Mills: `length` is applied by G43 (+) / G44 (-) H<n> along the tool axis (Z) and
    `radius` by G41/G42 D<n>. Lathes: T<tt><oo> applies offset number <oo>; `x` (radius
    value) and `z` shift the tool tip, `radius` is the nose radius for G41/G42.
    """

    length: float = 0.0
    radius: float = 0.0
    x: float = 0.0
    z: float = 0.0


@dataclass(frozen=True, slots=True)
class ModalState:
    """A snapshot of the interpreter for status displays.

    `gcodes` maps each modal group name to its active code ("motion": "G1", "plane": "G17",
    ...). Positions: `work_position` is in program units (mm or inch) in the active work
    coordinate system, the lathe X as a diameter in diameter mode; `machine_position` is
    machine coordinates in mm. `feed` is the programmed F in program units (per minute or
    per revolution, see gcodes["feed_mode"]).
    """

    file: str
    line: int
    block_number: int | None
    program: int | None
    subprogram_depth: int
    gcodes: dict[str, str] = field(default_factory=dict)
    units: str = "mm"
    work_offset: str = "G54"
    tool_selected: int = 0
    tool_in_spindle: int = 0
    length_offset: int = 0
    radius_offset: int = 0
    feed: float | None = None
    spindle_rpm: float = 0.0
    spindle: str = "M5"
    surface_speed: float | None = None
    coolant_mist: bool = False
    coolant_flood: bool = False
    work_position: tuple[float, ...] = ()
    machine_position: tuple[float, ...] = ()
    ended: bool = False
