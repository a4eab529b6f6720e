"""Contour error: the distance of the actual position from the commanded path.

The path is the polyline of the setpoints the NC sent; the axes lag behind the newest one,
so the nearest segment is found by walking back from it to the first local minimum of the
distance (a path that comes back on itself is not mistaken for it). Runs every IPO cycle
while a program is active: compiled with mypyc (cnc/machine/mypyc.list); this file is the
reference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def seg_dist(path: Sequence[tuple[float, ...]], j: int, p: tuple[float, ...]) -> float:
    """Distance from p to the path segment ending at point j (a point for j = 0)."""
    b = path[j]
    if j == 0:
        return math.dist(p, b)
    a = path[j - 1]
    if len(a) != len(p) or len(b) != len(p):
        raise ValueError(f"contour: points of {len(a)}, {len(b)} and {len(p)} axes")
    den = dot = ap2 = 0.0
    for i in range(len(p)):
        ai = a[i]
        d, e = b[i] - ai, p[i] - ai
        den += d * d
        dot += d * e
        ap2 += e * e
    if den == 0.0 or dot <= 0.0:
        return math.sqrt(ap2)
    if dot >= den:
        return math.dist(p, b)
    return math.sqrt(max(0.0, ap2 - dot * dot / den))


def contour_error(path: Sequence[tuple[float, ...]], actual: tuple[float, ...]) -> float:
    """Distance of `actual` from the nearest segment at the end of a non-empty path."""
    j = len(path) - 1
    best = seg_dist(path, j, actual)
    while j > 0:
        d = seg_dist(path, j - 1, actual)
        if d > best:
            break
        best, j = d, j - 1
    return best
