"""Machine parameters the NC kernel needs: axes, limits and the number-format rules.

These are plain data. Loading them from the cell's YAML configuration (with key-naming
error messages) lives in cnc.config; tests build them directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from cnc.probe import ToolSetter


class DecimalStyle(Enum):
    """How a value written without a decimal point is read (003_dimensions.md)."""

    CALCULATOR = "calculator"  # X10 = 10 mm
    LEAST_INCREMENT = "least_increment"  # Fanuc: X10 = 10 x 0.001 mm = 0.010 mm


ROTARY_AXES = ("A", "B", "C")
LINEAR_POSE_AXES = ("X", "Y", "Z")


@dataclass(frozen=True, slots=True)
class AxisParams:
    name: str
    min_mm: float  # soft limits, machine coordinates
    max_mm: float
    max_velocity: float  # mm/min (rapid)
    max_accel: float  # mm/s^2
    max_jerk: float  # mm/s^3
    home_mm: float = 0.0  # G28 reference point, machine coordinates
    # a rotary axis (A, B, C) reads every figure above in degrees (deg, deg/min, deg/s^2,
    # deg/s^3); `continuous` makes it an endless axis: no soft limits, display mod 360
    continuous: bool = False

    @property
    def rotary(self) -> bool:
        return self.name in ROTARY_AXES


@dataclass(frozen=True, slots=True)
class MachineParams:
    kind: str = "mill"  # "mill" (X Y Z) or "lathe" (X Z)
    axes: tuple[AxisParams, ...] = field(
        default_factory=lambda: (
            AxisParams("X", -500.0, 0.0, 30000.0, 3000.0, 50000.0),
            AxisParams("Y", -400.0, 0.0, 30000.0, 3000.0, 50000.0),
            AxisParams("Z", -400.0, 0.0, 24000.0, 2500.0, 40000.0),
        )
    )
    decimal_style: DecimalStyle = DecimalStyle.CALCULATOR
    least_increment_mm: float = 0.001
    least_increment_inch: float = 0.0001
    lathe_diameter_mode: bool = True  # lathe X words are diameters
    max_feed: float = 15000.0  # mm/min, cap for programmed F
    default_path_tolerance: float = 0.01  # mm, G64 without P
    lookahead: int = 200  # blocks
    ipo_cycle_s: float = 0.002
    # G30 point, one figure per axis of `axes` in their order (a lathe: X Z); None = home
    second_reference_mm: tuple[float, ...] | None = None
    max_spindle_rpm: float | None = None  # the spindle's top speed: the G96 clamp; None = none
    lathe_gcode_system: str = "A"  # Fanuc T G-code system A, B or C (cnc.interp.codes)
    call_nesting: int = 10  # program levels called (M98, G65, G66): PS0077 beyond
    macro_nesting: int = 5  # of which G65/G66 macro levels: PS0122 beyond
    # whose macro system variables: "haas_ngc" (#10000-#10999 kept common variables, #4012
    # the G66/G67 group) or "kitamura" (#10001.. tool length offsets, #11001.. their wear,
    # #4012 the work coordinate system): cnc.interp.macro
    macro_variable_map: str = "haas_ngc"
    # M codes the machine's PLC handles besides the NC's own (its M-code table, plc.m_codes);
    # None: no table declared, every M code the NC does not know is handed to the PLC
    plc_m_codes: frozenset[int] | None = None
    # mill5: (d, tool length, z offset) mm of the B45/C table (cnc.kinematics); None = 0s
    kinematics: tuple[float, float, float] | None = None
    # the tool-length sensor a G31 skip move runs into (cnc.probe); None: none fitted,
    # a G31 then runs to its end point without a skip signal
    tool_setter: ToolSetter | None = None

    @property
    def rotary_axes(self) -> tuple[AxisParams, ...]:
        """The rotary axes (A, B, C) in configured order: a pose's components after Z."""
        return tuple(a for a in self.axes if a.name in ROTARY_AXES)

    @property
    def pose_axes(self) -> tuple[str, ...]:
        """Names of a canonical pose's components: X Y Z, then the rotary axes."""
        return LINEAR_POSE_AXES + tuple(a.name for a in self.axes if a.name in ROTARY_AXES)

    def axis(self, name: str) -> AxisParams:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(name)
