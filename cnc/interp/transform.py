"""Programmable coordinate transforms: mirror (G51.1), scaling (G51), rotation (G68).

Applied in that order to a programmed point (Fanuc: programmable mirror image, then
scaling, then coordinate rotation), all in program coordinates before work offsets.
Polar coordinates (G16) are resolved earlier, when the words are read.
"""

from __future__ import annotations

import math


class Transform:
    """The active mirror/scale/rotation, as plain floats for a fast per-point apply."""

    __slots__ = ("mirror", "mirror_c", "scale", "scale_c", "rot", "rot_c", "rot_uv", "cos", "sin")

    def __init__(self) -> None:
        self.mirror = [False, False, False]
        self.mirror_c = [0.0, 0.0, 0.0]
        self.scale: list[float] | None = None  # per-axis factors when G51 is active
        self.scale_c = [0.0, 0.0, 0.0]
        self.rot = False
        self.rot_c = (0.0, 0.0)
        self.rot_uv = (0, 1)
        self.cos = 1.0
        self.sin = 0.0

    @property
    def active(self) -> bool:
        return self.rot or self.scale is not None or any(self.mirror)

    def _pre(self, p: list[float]) -> list[float]:
        m = self.mirror
        for i in range(3):
            if m[i]:
                p[i] = 2.0 * self.mirror_c[i] - p[i]
        s = self.scale
        if s is not None:
            c = self.scale_c
            for i in range(3):
                p[i] = c[i] + s[i] * (p[i] - c[i])
        return p

    def apply(self, p: tuple[float, ...] | list[float]) -> tuple[float, float, float]:
        q = self._pre([p[0], p[1], p[2]])
        if self.rot:
            u, v = self.rot_uv
            cu, cv = self.rot_c
            du, dv = q[u] - cu, q[v] - cv
            q[u] = cu + du * self.cos - dv * self.sin
            q[v] = cv + du * self.sin + dv * self.cos
        return (q[0], q[1], q[2])

    def inverse(self, t: tuple[float, ...] | list[float]) -> tuple[float, float, float]:
        q = [t[0], t[1], t[2]]
        if self.rot:
            u, v = self.rot_uv
            cu, cv = self.rot_c
            du, dv = q[u] - cu, q[v] - cv
            q[u] = cu + du * self.cos + dv * self.sin
            q[v] = cv - du * self.sin + dv * self.cos
        s = self.scale
        if s is not None:
            c = self.scale_c
            for i in range(3):
                q[i] = c[i] + (q[i] - c[i]) / s[i]
        m = self.mirror
        for i in range(3):
            if m[i]:
                q[i] = 2.0 * self.mirror_c[i] - q[i]
        return (q[0], q[1], q[2])

    def handedness(self, u: int, v: int) -> float:
        """-1 when the transform mirrors the (u, v) plane (arcs and G41/G42 swap), else 1."""
        sign = 1.0
        if self.mirror[u] != self.mirror[v]:
            sign = -sign
        if self.scale is not None and self.scale[u] * self.scale[v] < 0:
            sign = -sign
        return sign

    def plane_scale(self, u: int, v: int) -> float | None:
        """The in-plane scale factor magnitude, or None when it differs between u and v."""
        if self.scale is None:
            return 1.0
        a, b = abs(self.scale[u]), abs(self.scale[v])
        if abs(a - b) > 1e-12 * max(a, b, 1.0):
            return None
        return a

    def set_rotation(self, uv: tuple[int, int], center: tuple[float, float], deg: float) -> None:
        self.rot = True
        self.rot_uv = uv
        self.rot_c = center
        a = math.radians(deg)
        self.cos = math.cos(a)
        self.sin = math.sin(a)
