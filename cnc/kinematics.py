"""Kinematics: machine Cartesian poses <-> joint (axis) positions.

The interpreter and planner work on canonical `Pose` tuples (X, Y, Z in machine
coordinates, mm); drives move joints. A kinematics object maps between the two, Klipper
style: small, pluggable, chosen by the machine's `kind` (`kinematics_for(params)`), with
new kinds added through `register_kinematics`. All functions here are pure.

* `CartesianMill`: joints X Y Z (and rotary A/B/C of a 4th-axis table) are the pose itself.
* `MillBC45`: the `mill5` machine as the NC runs it (pose = joints X Y Z B C, posted
  programs are in joint coordinates) with the tool tip by forward kinematics.
* `Lathe`: joints X Z; Y is held at 0. X is the radius in machine coordinates (diameter
  programming is the interpreter's business).
* `TableTableBC45`: the seam for the 5-axis DMU-70-like machine of 002_postprocessor.md
  (B swivel axis inclined at 45 degrees carrying the C rotary table). Its pose is the tool
  tip plus the tool-axis direction cosines in the workpiece frame, (x, y, z, i, j, k); its
  joints are X Y Z B C (mm, degrees). The planner uses only three axes today; the inverse
  and forward transforms are ready for a 5-axis planner and for the post-processor.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

from cnc.canon import Pose
from cnc.errors import NcError
from cnc.params import MachineParams

__all__ = [
    "CartesianMill",
    "FiveAxisJoints",
    "Kinematics",
    "Lathe",
    "MillBC45",
    "TableTableBC45",
    "bc45_forward",
    "bc45_inverse",
    "bc45_rotary",
    "kinematics_for",
    "register_kinematics",
]

LATHE_Y_TOLERANCE = 1e-9  # mm; the interpreter writes exactly 0.0 for a lathe's Y


@runtime_checkable
class Kinematics(Protocol):
    """What the NC needs of a kinematics: joint names and the two transforms."""

    @property
    def axis_names(self) -> tuple[str, ...]:
        """Joint names in joint order (the drives' order)."""
        ...

    def to_joints(self, pose: Pose, previous: Sequence[float] | None = None) -> tuple[float, ...]:
        """Inverse kinematics. `previous` joints let a machine with rotary axes stay
        continuous (unwrap, singularity); Cartesian machines ignore it."""
        ...

    def to_pose(self, joints: Sequence[float]) -> Pose:
        """Forward kinematics."""
        ...


def _check_len(what: str, values: Sequence[float], n: int, names: str) -> None:
    if len(values) != n:
        raise NcError(f"{what} needs {n} values ({names}), got {len(values)}")


@dataclass(frozen=True, slots=True)
class CartesianMill:
    """Three orthogonal linear axes, optionally followed by rotary axes (a 4th-axis
    rotary table A: mill4): joint = pose, the rotary joints in degrees."""

    rotary: tuple[str, ...] = ()

    @property
    def axis_names(self) -> tuple[str, ...]:
        return ("X", "Y", "Z", *self.rotary)

    def to_joints(self, pose: Pose, previous: Sequence[float] | None = None) -> tuple[float, ...]:
        names = self.axis_names
        _check_len("mill pose", pose, len(names), " ".join(names))
        return tuple(float(v) for v in pose)

    def to_pose(self, joints: Sequence[float]) -> Pose:
        names = self.axis_names
        _check_len("mill joints", joints, len(names), " ".join(names))
        return tuple(float(v) for v in joints)


@dataclass(frozen=True, slots=True)
class Lathe:
    """Two linear axes X (radius) and Z; a pose's Y must be 0."""

    @property
    def axis_names(self) -> tuple[str, ...]:
        return ("X", "Z")

    def to_joints(self, pose: Pose, previous: Sequence[float] | None = None) -> tuple[float, ...]:
        _check_len("lathe pose", pose, 3, "X Y Z")
        if abs(pose[1]) > LATHE_Y_TOLERANCE:
            raise NcError(f"a lathe has no Y axis: Y must be 0, got {pose[1]:g}")
        return (float(pose[0]), float(pose[2]))

    def to_pose(self, joints: Sequence[float]) -> Pose:
        _check_len("lathe joints", joints, 2, "X Z")
        return (float(joints[0]), 0.0, float(joints[1]))


# --- 5-axis: B inclined 45 degrees carrying the C table (002_postprocessor.md §4) ---------

ORIENTATION_NORM_TOLERANCE = 1e-3  # CL data is printed to ~7 digits (Table 1 P3: |v| = 1.00009)
SINGULAR_K = 1e-12  # k0 this close to 1: tool parallel to C, C undefined


class FiveAxisJoints(NamedTuple):
    """Joint positions of the B45/C machine: mm and degrees. `singular` is True when the
    tool is parallel to the C axis (B = 0) and C was taken from the previous position."""

    x: float
    y: float
    z: float
    b: float
    c: float
    singular: bool = False


def _unit(orientation: Sequence[float]) -> tuple[float, float, float]:
    if len(orientation) != 3:
        raise NcError(f"tool orientation needs 3 direction cosines (i j k), got {len(orientation)}")
    i, j, k = (float(v) for v in orientation)
    norm = math.sqrt(i * i + j * j + k * k)
    if not math.isfinite(norm) or abs(norm - 1.0) > ORIENTATION_NORM_TOLERANCE:
        raise NcError(
            f"tool orientation ({i:g}, {j:g}, {k:g}) is not a unit vector (|v| = {norm:.6g})"
        )
    return i / norm, j / norm, k / norm


def _unwrap(angle_deg: float, previous_deg: float | None) -> float:
    if previous_deg is None:
        return angle_deg
    return angle_deg + 360.0 * round((previous_deg - angle_deg) / 360.0)


def bc45_rotary(
    orientation: Sequence[float], previous_c: float | None = None
) -> tuple[float, float, bool]:
    """(B, C, singular) in degrees for a tool-axis vector (i, j, k) in the workpiece frame.

    cos B = 2k - 1 (eq. 14, branch B in [0, 180]); C = atan2((k-1) i + S j, (k-1) j - S i)
    with S = sqrt(2 (k - k^2)) (eq. 13). k < 0 cannot be reached (the 45-degree swivel tilts
    the part by at most 90 degrees). At k = 1 C is undefined: the previous C (or 0) is kept
    and `singular` is True. With `previous_c` C is unwrapped to the nearest turn.
    """
    i, j, k = _unit(orientation)
    if k < -1e-12:
        raise NcError(
            f"tool orientation ({i:.6g}, {j:.6g}, {k:.6g}) unreachable: the B45/C table"
            " needs k >= 0"
        )
    k = min(max(k, 0.0), 1.0)
    b = math.degrees(math.acos(min(max(2.0 * k - 1.0, -1.0), 1.0)))
    if 1.0 - k <= SINGULAR_K:
        return 0.0, (previous_c if previous_c is not None else 0.0), True
    s = math.sqrt(2.0 * (k - k * k))
    c = math.degrees(math.atan2((k - 1.0) * i + s * j, (k - 1.0) * j - s * i))
    return b, _unwrap(c, previous_c), False


def bc45_inverse(
    tip: Sequence[float],
    orientation: Sequence[float],
    d: float = 0.0,
    *,
    tool_length: float = 0.0,
    z_offset: float = 0.0,
    previous_c: float | None = None,
) -> FiveAxisJoints:
    """Inverse kinematics of the B45/C table machine (002 eqs. 10-14).

    `tip` (x0, y0, z0) and `orientation` (i0, j0, k0) are the tool tip and tool axis in
    the workpiece frame (origin on the C table surface at B = C = 0). `d` is the distance
    from the table surface to the point where the B axis meets the C axis; `tool_length`
    is Z_T and `z_offset` the fixed offset z_OwOt between the workpiece and spindle frames
    (eq. 9: Z = z_w - z_OwOt + Z_T).
    """
    if len(tip) != 3:
        raise NcError(f"tool tip needs 3 coordinates (x y z), got {len(tip)}")
    x0, y0, z0 = (float(v) for v in tip)
    b, c, singular = bc45_rotary(orientation, previous_c)
    k0 = (1.0 + math.cos(math.radians(b))) / 2.0  # the normalised k, exactly as B saw it
    s = math.sqrt(max(2.0 * (k0 - k0 * k0), 0.0))
    m = 2.0 * k0 - 1.0
    cc, sc = math.cos(math.radians(c)), math.sin(math.radians(c))
    x = (m * x0 + s * y0) * cc + (s * x0 - m * y0) * sc + s * (d + z0)
    y = (k0 * y0 - s * x0) * cc + (k0 * x0 + s * y0) * sc + (k0 - 1.0) * (d + z0)
    z = ((k0 - 1.0) * y0 - s * x0) * cc + ((k0 - 1.0) * x0 + s * y0) * sc
    z += (k0 - 1.0) * d + k0 * z0
    return FiveAxisJoints(x, y, z - z_offset + tool_length, b, c, singular)


def _rx(a: float, p: tuple[float, float, float]) -> tuple[float, float, float]:
    ca, sa = math.cos(a), math.sin(a)
    return (p[0], ca * p[1] - sa * p[2], sa * p[1] + ca * p[2])


def _rz(a: float, p: tuple[float, float, float]) -> tuple[float, float, float]:
    ca, sa = math.cos(a), math.sin(a)
    return (ca * p[0] - sa * p[1], sa * p[0] + ca * p[1], p[2])


def bc45_forward(
    joints: Sequence[float],
    d: float = 0.0,
    *,
    tool_length: float = 0.0,
    z_offset: float = 0.0,
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Forward kinematics: joints (X, Y, Z, B, C) -> (tool tip, tool axis) in the
    workpiece frame. The point chain is P0 = Rz(-C) T(0,0,-d) Rx(45) Rz(B) Rx(-45)
    T(0,0,d) Pw (002 §4, derived); the tool axis is the same rotation of (0, 0, 1)."""
    if len(joints) < 5:
        raise NcError(f"B45/C joints need 5 values (X Y Z B C), got {len(joints)}")
    x, y, z, b_deg, c_deg = (float(v) for v in joints[:5])
    b, c, q = math.radians(b_deg), math.radians(c_deg), math.pi / 4
    p = (x, y, z + z_offset - tool_length + d)
    p = _rz(-c, _rx(q, _rz(b, _rx(-q, p))))
    tip = (p[0], p[1], p[2] - d)
    axis = _rz(-c, _rx(q, _rz(b, _rx(-q, (0.0, 0.0, 1.0)))))
    return tip, axis


@dataclass(frozen=True, slots=True)
class TableTableBC45:
    """The 5-axis seam: pose (x, y, z, i, j, k) <-> joints (X, Y, Z, B, C)."""

    d: float = 0.0
    tool_length: float = 0.0
    z_offset: float = 0.0

    @property
    def axis_names(self) -> tuple[str, ...]:
        return ("X", "Y", "Z", "B", "C")

    def to_joints(self, pose: Pose, previous: Sequence[float] | None = None) -> tuple[float, ...]:
        _check_len("B45/C pose", pose, 6, "x y z i j k")
        prev_c = float(previous[4]) if previous is not None and len(previous) >= 5 else None
        j = bc45_inverse(
            pose[:3],
            pose[3:],
            self.d,
            tool_length=self.tool_length,
            z_offset=self.z_offset,
            previous_c=prev_c,
        )
        return (j.x, j.y, j.z, j.b, j.c)

    def to_pose(self, joints: Sequence[float]) -> Pose:
        _check_len("B45/C joints", joints, 5, "X Y Z B C")
        tip, axis = bc45_forward(
            joints, self.d, tool_length=self.tool_length, z_offset=self.z_offset
        )
        return (*tip, *axis)


@dataclass(frozen=True, slots=True)
class MillBC45:
    """The NC's view of the `mill5` machine: a program for a table-table machine is
    written in joint coordinates (the post did the inverse kinematics), so pose = joints
    (X Y Z B C); `tool_tip` is the forward transform into the workpiece frame, the figure
    the tool-tip deviation and the dashboard's plot use."""

    d: float = 0.0
    tool_length: float = 0.0
    z_offset: float = 0.0

    @property
    def axis_names(self) -> tuple[str, ...]:
        return ("X", "Y", "Z", "B", "C")

    def to_joints(self, pose: Pose, previous: Sequence[float] | None = None) -> tuple[float, ...]:
        _check_len("mill5 pose", pose, 5, "X Y Z B C")
        return tuple(float(v) for v in pose)

    def to_pose(self, joints: Sequence[float]) -> Pose:
        _check_len("mill5 joints", joints, 5, "X Y Z B C")
        return tuple(float(v) for v in joints)

    def tool_tip(self, joints: Sequence[float]) -> tuple[float, float, float]:
        """The tool tip in the workpiece frame (forward kinematics of X Y Z B C)."""
        tip, _axis = bc45_forward(
            joints, self.d, tool_length=self.tool_length, z_offset=self.z_offset
        )
        return tip


def _mill(params: MachineParams) -> Kinematics:
    return CartesianMill(tuple(a.name for a in params.rotary_axes))


def _mill5(params: MachineParams) -> Kinematics:
    d, tool_length, z_offset = params.kinematics or (0.0, 0.0, 0.0)
    return MillBC45(d, tool_length, z_offset)


# --- selection by machine kind -----------------------------------------------------------

_FACTORIES: dict[str, Callable[[MachineParams], Kinematics]] = {
    "mill": _mill,
    "mill5": _mill5,
    "lathe": lambda _p: Lathe(),
}


def register_kinematics(kind: str, factory: Callable[[MachineParams], Kinematics]) -> None:
    """Make `kinematics_for` build `factory(params)` for machines of `kind`."""
    _FACTORIES[kind] = factory


def kinematics_for(params: MachineParams) -> Kinematics:
    """The kinematics of a machine, chosen by `params.kind`; its joint names must be the
    configured axes, in order."""
    try:
        factory = _FACTORIES[params.kind]
    except KeyError:
        known = ", ".join(sorted(_FACTORIES))
        raise NcError(f"no kinematics for machine kind {params.kind!r} (known: {known})") from None
    kin = factory(params)
    configured = tuple(a.name for a in params.axes)
    if configured != kin.axis_names:
        raise NcError(
            f"machine kind {params.kind!r} has axes {' '.join(kin.axis_names)},"
            f" configured {' '.join(configured) or 'none'}"
        )
    return kin
