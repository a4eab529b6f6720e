"""Jerk-limited (S-curve) velocity changes along the path, in closed form.

Every speed change the planner makes starts and ends with zero path acceleration: the
path jerk is +-J or 0 and the path acceleration is clipped at +-A, the classic 7-phase
profile. These helpers answer the three questions the look-ahead asks: how long is a
change from `va` to `vb`, how fast can we be at most at one end of a stretch of length
`L`, and which (duration, jerk) phases realise a change.

Speeds in mm/s, accelerations mm/s^2, jerks mm/s^3, lengths mm.
"""

from __future__ import annotations

from math import pow as fpow
from math import sqrt


def change_distance(va: float, vb: float, a: float, j: float) -> float:
    """Path length used by a jerk-limited change va -> vb (zero acceleration at both ends)."""
    dv = vb - va if vb > va else va - vb
    if dv <= 0.0:
        return 0.0
    if dv * j >= a * a:
        return 0.5 * (va + vb) * (dv / a + a / j)
    return (va + vb) * sqrt(dv / j)


def change_time(va: float, vb: float, a: float, j: float) -> float:
    dv = vb - va if vb > va else va - vb
    if dv <= 0.0:
        return 0.0
    if dv * j >= a * a:
        return dv / a + a / j
    return 2.0 * sqrt(dv / j)


def reach(v1: float, length: float, a: float, j: float) -> float:
    """Highest speed v0 >= v1 such that change_distance(v0, v1) <= length.

    change_distance is symmetric, so this is also the highest speed reachable from v1
    by accelerating over `length`.
    """
    if length <= 0.0:
        return v1
    aj = a * a / j
    b = 2.0 * v1 + aj
    c = 2.0 * v1 * aj - 2.0 * a * length
    dv = 0.5 * (-b + sqrt(b * b - 4.0 * c))
    if dv >= aj:
        return v1 + dv
    # Short change, acceleration limit not reached: (2 v1 + x^2) x = L sqrt(J), x = sqrt(dv).
    p = 2.0 * v1
    q = length * sqrt(j)
    disc = sqrt(0.25 * q * q + p * p * p / 27.0)
    u = 0.5 * q + disc
    w = 0.5 * q - disc
    third = 1.0 / 3.0
    x = fpow(u, third) - fpow(-w, third) if w < 0.0 else fpow(u, third) + fpow(w, third)
    if x <= 0.0:
        x = q / p if p > 0.0 else 0.0
    for _ in range(3):  # Newton polish: Cardano cancels badly when p >> q
        f = x * x * x + p * x - q
        x -= f / (3.0 * x * x + p)
    dv = x * x
    if dv > aj:
        dv = aj
    return v1 + dv


def min_reach(v0: float, length: float, a: float, j: float) -> float:
    """Lowest speed reachable from v0 by braking over `length` (0 if it can stop)."""
    if change_distance(v0, 0.0, a, j) <= length:
        return 0.0
    lo, hi = 0.0, v0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if change_distance(v0, mid, a, j) > length:
            lo = mid
        else:
            hi = mid
    return hi


def change_phases(va: float, vb: float, a: float, j: float) -> list[tuple[float, float]]:
    """(duration, jerk) phases of the change va -> vb; empty when va == vb."""
    if vb == va:
        return []
    sj = j if vb > va else -j
    dv = vb - va if vb > va else va - vb
    if dv * j >= a * a:
        t1 = a / j
        t2 = dv / a - t1
        if t2 > 0.0:
            return [(t1, sj), (t2, 0.0), (t1, -sj)]
        return [(t1, sj), (t1, -sj)]
    t1 = sqrt(dv / j)
    return [(t1, sj), (t1, -sj)]
