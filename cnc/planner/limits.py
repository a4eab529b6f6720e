"""Per-axis limits turned into path limits for one piece and one junction.

The budget split (documented in docs/motion.md):

* continuous motion on a piece may use (1 - RHO_KINK_A) of each axis acceleration and
  (1 - RHO_JUMP) of each axis jerk;
* junctions (tangent kinks and curvature jumps, which the IPO samples see as short
  bursts) share the rest: RHO_KINK_A * A and RHO_JUMP * J, split so that all junctions
  inside one 3-cycle window together stay within it;
* on arcs the centripetal part may use RHO_ARC_A of the plane acceleration and RHO_ARC_J
  of the plane jerk; what is left is the tangential budget for speed changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import sqrt

from cnc.params import MachineParams
from cnc.planner.geometry import Arc, Line

RHO_KINK_A = 0.01
RHO_JUMP = 0.05
RHO_ARC_A = 0.96
RHO_ARC_J = 0.96
Q_TANGENT = 0.98  # share of the plane jerk for the tangential component on arcs
POSE_AXES = ("X", "Y", "Z")
INF = float("inf")


@dataclass(frozen=True, slots=True)
class AxisLimits:
    """Limits per pose index in mm/s, mm/s^2, mm/s^3, plus the IPO cycle."""

    vel: tuple[float, ...]
    acc: tuple[float, ...]
    jerk: tuple[float, ...]
    ipo: float
    window: float  # path length that 3 IPO cycles can cover at most, mm

    @classmethod
    def from_params(cls, params: MachineParams, ipo: float | None = None) -> AxisLimits:
        by_name = {a.name.upper(): a for a in params.axes}
        if not by_name:
            raise ValueError("machine has no axes")
        fallback = min(params.axes, key=lambda a: a.max_accel)
        axes = [by_name.get(n, fallback) for n in POSE_AXES]
        t = params.ipo_cycle_s if ipo is None else ipo
        vel = tuple(a.max_velocity / 60.0 for a in axes)
        return cls(
            vel=vel,
            acc=tuple(float(a.max_accel) for a in axes),
            jerk=tuple(float(a.max_jerk) for a in axes),
            ipo=t,
            window=3.0 * t * sqrt(sum(v * v for v in vel)),
        )


def line_limits(lim: AxisLimits, u: tuple[float, ...]) -> tuple[float, float, float]:
    """(speed cap, tangential accel, tangential jerk) of a line with unit direction u."""
    v = a = j = INF
    ka = 1.0 - RHO_KINK_A
    kj = 1.0 - RHO_JUMP
    for i, ui in enumerate(u):
        c = abs(ui)
        if c > 0.0:
            v = min(v, lim.vel[i] / c)
            a = min(a, ka * lim.acc[i] / c)
            j = min(j, kj * lim.jerk[i] / c)
    return v, a, j


def arc_limits(lim: AxisLimits, arc: Arc, normal_axis: int) -> tuple[float, float, float]:
    """(speed cap, tangential accel, tangential jerk) of an arc or helix.

    In-plane speed is c*sdot (c = cos of the helix angle). The in-plane acceleration
    vector is (c*sddot, c^2 sdot^2 / r) and the jerk vector (c*s''' - c^3 sdot^3/r^2,
    3 c^2 sdot sddot / r); any axis sees at most their length.
    """
    # axis i sees at most |e_i| of an in-plane vector, |e_i| = sqrt(e1_i^2 + e2_i^2)
    ap = jp = vp = INF
    for i in range(len(lim.acc)):
        e = sqrt(arc.e1[i] ** 2 + arc.e2[i] ** 2)
        if e > 1e-12:
            ap = min(ap, lim.acc[i] * (1.0 - RHO_KINK_A) / e)
            jp = min(jp, lim.jerk[i] * (1.0 - RHO_JUMP) / e)
            vp = min(vp, lim.vel[i] / e)
    r = min(arc.r0, arc.r1)
    c = arc.plane_fraction
    sa = arc.rise_fraction
    v = min(vp / c, sqrt(RHO_ARC_A * ap * r) / c, (RHO_ARC_J * jp * r * r) ** (1.0 / 3.0) / c)
    an_ = lim.acc[normal_axis] * (1.0 - RHO_KINK_A)
    jn_ = lim.jerk[normal_axis] * (1.0 - RHO_JUMP)
    if sa > 0.0:
        v = min(v, lim.vel[normal_axis] / sa)
    an = c * c * v * v / r
    at = sqrt(max(ap * ap - an * an, 0.0)) / c
    # in-plane jerk: (c*s3 - c^3 sdot^3/r^2) along the tangent, 3 c^2 sdot sddot / r along
    # the normal; the tangent part gets Q_TANGENT of the plane jerk, the normal the rest
    k = c * c * c * v * v * v / (r * r)
    q = max(Q_TANGENT * jp, k)
    jt = (q - k) / c
    at = min(at, sqrt(max(jp * jp - q * q, 0.0)) * r / (3.0 * c * c * v))
    if sa > 0.0:
        at = min(at, an_ / sa)
        jt = min(jt, jn_ / sa)
    return v, at, jt


def junction_cap(
    lim: AxisLimits,
    du: tuple[float, ...],
    dk: tuple[float, ...],
    gap: float,
    at_max: float,
    inside_span: bool,
) -> float:
    """Highest path speed at a junction with tangent jump du and curvature-vector jump dk.

    `gap` is the length of the piece before the junction: a junction gets the share
    min(1, gap/window) of half the junction budget, so that any 3-cycle window (path
    length <= window) holds junctions whose shares sum to at most 2 halves.
    """
    t = lim.ipo
    w = gap / lim.window
    if w > 1.0:
        w = 1.0
    cap = INF
    for i in range(len(du)):
        dui = abs(du[i])
        dki = abs(dk[i])
        if dui == 0.0 and dki == 0.0:
            continue
        budget = 0.5 * RHO_JUMP * lim.jerk[i] * w
        if inside_span:
            budget -= 0.75 / t * dui * at_max
        if budget <= 0.0:
            return 0.0
        alpha = 0.75 / t * dki
        beta = dui / (t * t)
        if alpha > 0.0:
            v = (-beta + sqrt(beta * beta + 4.0 * alpha * budget)) / (2.0 * alpha)
        else:
            v = budget / beta
        if dui > 0.0:
            v = min(v, 0.5 * RHO_KINK_A * lim.acc[i] * t * w / dui)
        if v < cap:
            cap = v
    return cap


def piece_limits(lim: AxisLimits, geom: Line | Arc, normal_axis: int) -> tuple[float, float, float]:
    if isinstance(geom, Line):
        return line_limits(lim, geom.u)
    return arc_limits(lim, geom, normal_axis)
