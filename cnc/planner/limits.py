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

from math import pow as fpow
from math import sqrt
from typing import Final

from cnc.params import MachineParams
from cnc.planner.geometry import Arc, Line, Piece, Vec3
from cnc.planner.native import mypyc_attr

RHO_KINK_A: Final = 0.01
RHO_JUMP: Final = 0.05
RHO_ARC_A: Final = 0.96
RHO_ARC_J: Final = 0.96
Q_TANGENT: Final = 0.98  # share of the plane jerk for the tangential component on arcs
POSE_AXES = ("X", "Y", "Z")
ROTARY_AXES = ("A", "B", "C")
INF: Final = float("inf")


@mypyc_attr(acyclic=True)
class AxisLimits:
    """Limits per pose index (X, Y, Z) in mm/s, mm/s^2, mm/s^3, plus the IPO cycle.

    Treat as immutable: the derived per-axis constants below are computed once from the
    limits when the object is made.
    """

    __slots__ = (
        "vel",
        "acc",
        "jerk",
        "ipo",
        "window",
        "dv3",
        "vtop",
        "acc_c",
        "jerk_c",
        "jerk_q",
        "jerk_qtt",
        "acc_qt",
        "jerk_k",
        "jerk_ktt",
        "acc_k",
        "acc_kt",
        "rot",
        "nrot",
    )

    vel: Vec3
    acc: Vec3
    jerk: Vec3
    ipo: float
    window: float  # path length that 3 IPO cycles can cover at most, mm
    dv3: float  # most the path speed can change within 3 IPO cycles, mm/s
    vtop: float  # no path speed exceeds this (all axes at their velocity limit)
    acc_c: Vec3  # continuous shares (see the module docstring)
    jerk_c: Vec3
    # derived per-axis constants of junction_cap (a quarter of the junction shares): they
    # are the same for every junction of the path
    jerk_q: Vec3
    jerk_qtt: Vec3  # jerk_q * T^2
    acc_qt: Vec3  # acc share * T
    # the same for coast_cap (the continuous budget)
    jerk_k: Vec3
    jerk_ktt: Vec3
    acc_k: Vec3
    acc_kt: Vec3
    # the rotary axes (A, B, C) of a mill4/mill5, up to three, as limits of their own in
    # deg/s, deg/s^2, deg/s^3 (padded with the first one's): a segment's rotary axes run
    # linearly with the path length s; junctions use the same budget rules per axis
    rot: AxisLimits | None
    nrot: int

    def __init__(
        self,
        vel: Vec3,
        acc: Vec3,
        jerk: Vec3,
        ipo: float,
        window: float,
        dv3: float,
        vtop: float,
        acc_c: Vec3,
        jerk_c: Vec3,
    ) -> None:
        self.vel = vel
        self.acc = acc
        self.jerk = jerk
        self.ipo = ipo
        self.window = window
        self.dv3 = dv3
        self.vtop = vtop
        self.acc_c = acc_c
        self.jerk_c = jerk_c
        t = ipo
        j0, j1, j2 = jerk
        a0, a1, a2 = acc
        q = 0.25 * RHO_JUMP
        jq0, jq1, jq2 = q * j0, q * j1, q * j2
        self.jerk_q = (jq0, jq1, jq2)
        self.jerk_qtt = (t * t * jq0, t * t * jq1, t * t * jq2)
        q = 0.25 * RHO_KINK_A
        self.acc_qt = (q * a0 * t, q * a1 * t, q * a2 * t)
        q = 1.0 - RHO_JUMP
        jk0, jk1, jk2 = q * j0, q * j1, q * j2
        q = 1.0 - RHO_KINK_A
        ak0, ak1, ak2 = q * a0, q * a1, q * a2
        self.jerk_k = (jk0, jk1, jk2)
        self.jerk_ktt = (t * t * jk0, t * t * jk1, t * t * jk2)
        self.acc_k = (ak0, ak1, ak2)
        self.acc_kt = (t * ak0, t * ak1, t * ak2)
        self.rot = None
        self.nrot = 0

    def __repr__(self) -> str:
        return f"AxisLimits(vel={self.vel}, acc={self.acc}, jerk={self.jerk}, ipo={self.ipo})"

    @classmethod
    def from_params(cls, params: MachineParams, ipo: float | None = None) -> AxisLimits:
        by_name = {a.name.upper(): a for a in params.axes}
        if not by_name:
            raise ValueError("machine has no axes")
        fallback = min(params.axes, key=lambda a: a.max_accel)
        axes = [by_name.get(n, fallback) for n in POSE_AXES]
        t = params.ipo_cycle_s if ipo is None else ipo
        vel = [a.max_velocity / 60.0 for a in axes]
        acc = [float(a.max_accel) for a in axes]
        jerk = [float(a.max_jerk) for a in axes]
        out = cls._of(vel, acc, jerk, t)
        rotary = [a for a in params.axes if a.name in ROTARY_AXES]
        if rotary:
            if len(rotary) > 3:
                raise ValueError("at most three rotary axes (A, B, C)")
            pad = rotary + [rotary[0]] * (3 - len(rotary))
            rot = cls._of(
                [a.max_velocity / 60.0 for a in pad],
                [float(a.max_accel) for a in pad],
                [float(a.max_jerk) for a in pad],
                t,
            )
            # a junction's share of the budget depends on how much *path* a 3-cycle window
            # holds: the path's own figures, not the rotary axes'
            rot.window, rot.dv3, rot.vtop = out.window, out.dv3, out.vtop
            out.rot = rot
            out.nrot = len(rotary)
        return out

    @classmethod
    def _of(cls, vel: list[float], acc: list[float], jerk: list[float], t: float) -> AxisLimits:
        return cls(
            vel=(vel[0], vel[1], vel[2]),
            acc=(acc[0], acc[1], acc[2]),
            jerk=(jerk[0], jerk[1], jerk[2]),
            ipo=t,
            window=3.0 * t * sqrt(sum(v * v for v in vel)),
            dv3=3.0 * t * sqrt(sum(a**2 for a in acc)),
            vtop=sqrt(sum(v * v for v in vel)),
            acc_c=(
                acc[0] * (1.0 - RHO_KINK_A),
                acc[1] * (1.0 - RHO_KINK_A),
                acc[2] * (1.0 - RHO_KINK_A),
            ),
            jerk_c=(
                jerk[0] * (1.0 - RHO_JUMP),
                jerk[1] * (1.0 - RHO_JUMP),
                jerk[2] * (1.0 - RHO_JUMP),
            ),
        )


def line_limits(lim: AxisLimits, u: Vec3) -> tuple[float, float, float]:
    """(speed cap, tangential accel, tangential jerk) of a line with unit direction u."""
    # written out for the three axes (in axis order): every line of the path runs this
    v = a = j = INF
    lv0, lv1, lv2 = lim.vel
    la0, la1, la2 = lim.acc_c
    lj0, lj1, lj2 = lim.jerk_c
    c0, c1, c2 = u
    if c0 < 0.0:
        c0 = -c0
    if c0 > 0.0:
        v = lv0 / c0
        a = la0 / c0
        j = lj0 / c0
    if c1 < 0.0:
        c1 = -c1
    if c1 > 0.0:
        x = lv1 / c1
        if x < v:
            v = x
        x = la1 / c1
        if x < a:
            a = x
        x = lj1 / c1
        if x < j:
            j = x
    if c2 < 0.0:
        c2 = -c2
    if c2 > 0.0:
        x = lv2 / c2
        if x < v:
            v = x
        x = la2 / c2
        if x < a:
            a = x
        x = lj2 / c2
        if x < j:
            j = x
    return v, a, j


def rotary_caps(
    lim: AxisLimits, q: Vec3, v: float, a: float, j: float
) -> tuple[float, float, float]:
    """(speed cap, accel, jerk) of a line once its rotary axes, turning q_i degrees per
    unit of path length, are counted: each rotary axis' limit over |q_i|, as a linear
    axis' over its direction cosine (joint space: every axis within its own limits)."""
    r = lim.rot
    if r is None:
        return v, a, j
    rv, ra, rj = line_limits(r, q)
    return (v if v < rv else rv), (a if a < ra else ra), (j if j < rj else rj)


def arc_limits(
    lim: AxisLimits, arc: Arc, normal_axis: int, vmax: float = INF
) -> tuple[float, float, float]:
    v, at, jt, _at, _jt = arc_limits_at(lim, arc, normal_axis, vmax, -1.0)
    return v, at, jt


def arc_limits_at(
    lim: AxisLimits, arc: Arc, normal_axis: int, vmax: float, vslow: float
) -> tuple[float, float, float, float, float]:
    """(speed cap, tangential accel, tangential jerk) of an arc or helix.

    In-plane speed is c*sdot (c = cos of the helix angle). The in-plane acceleration
    vector is (c*sddot, c^2 sdot^2 / r) and the jerk vector (c*s''' - c^3 sdot^3/r^2,
    3 c^2 sdot sddot / r); any axis sees at most their length. With `vmax` below the
    arc's own cap the tangential limits are those left over at vmax (larger).
    """
    # axis i sees at most |e_i| of an in-plane vector, |e_i| = sqrt(e1_i^2 + e2_i^2).
    # Written out with comparisons instead of min()/max() (same values): every G64
    # blend runs this once.
    ap = jp = vp = INF
    a0, a1, a2 = arc.e1
    b0, b1, b2 = arc.e2
    acc, jerk, vel = lim.acc, lim.jerk, lim.vel
    # the three axes in order (x ** 2 is pow(x, 2.0) in Python too)
    e = sqrt(fpow(a0, 2.0) + fpow(b0, 2.0))
    if e > 1e-12:
        x = acc[0] * (1.0 - RHO_KINK_A) / e
        if x < ap:
            ap = x
        x = jerk[0] * (1.0 - RHO_JUMP) / e
        if x < jp:
            jp = x
        x = vel[0] / e
        if x < vp:
            vp = x
    e = sqrt(fpow(a1, 2.0) + fpow(b1, 2.0))
    if e > 1e-12:
        x = acc[1] * (1.0 - RHO_KINK_A) / e
        if x < ap:
            ap = x
        x = jerk[1] * (1.0 - RHO_JUMP) / e
        if x < jp:
            jp = x
        x = vel[1] / e
        if x < vp:
            vp = x
    e = sqrt(fpow(a2, 2.0) + fpow(b2, 2.0))
    if e > 1e-12:
        x = acc[2] * (1.0 - RHO_KINK_A) / e
        if x < ap:
            ap = x
        x = jerk[2] * (1.0 - RHO_JUMP) / e
        if x < jp:
            jp = x
        x = vel[2] / e
        if x < vp:
            vp = x
    r0, r1 = arc.r0, arc.r1
    r = r1 if r1 < r0 else r0
    length = arc.length
    c = 0.5 * (r0 + r1) * arc.sweep / length  # Arc.plane_fraction
    rise = arc.rise
    sa = (rise if rise >= 0.0 else -rise) / length  # Arc.rise_fraction
    v = vp / c
    x = sqrt(RHO_ARC_A * ap * r) / c
    if x < v:
        v = x
    x = fpow(RHO_ARC_J * jp * r * r, 1.0 / 3.0) / c
    if x < v:
        v = x
    if vmax < v:
        v = vmax
    if sa > 0.0:
        x = _axis(vel, normal_axis) / sa
        if x < v:
            v = x
    if v <= 0.0:  # blocked (zero override): whatever tangential limits, no motion
        return 0.0, ap / c, Q_TANGENT * jp / c, 0.0, 0.0
    if sa > 0.0:
        an_ = _axis(acc, normal_axis) * (1.0 - RHO_KINK_A) / sa
        jn_ = _axis(jerk, normal_axis) * (1.0 - RHO_JUMP) / sa
    else:
        an_ = jn_ = INF
    at, jt = _arc_tangential(ap, jp, c, r, v, an_, jn_)
    # also at the slower speed vslow (a programmed feed below the cap): the planner asks
    # for both, and everything above is shared
    if 0.0 < vslow < v:
        at2, jt2 = _arc_tangential(ap, jp, c, r, vslow, an_, jn_)
    else:
        at2, jt2 = at, jt
    return v, at, jt, at2, jt2


def _axis(x: Vec3, i: int) -> float:
    """x[i] of a pose-axis triple, indexed as a Python tuple (-1 is the last)."""
    if i < 0:
        i += 3
    if i == 0:
        return x[0]
    if i == 1:
        return x[1]
    if i == 2:
        return x[2]
    raise IndexError(f"pose axis index {i} out of range")


def _arc_tangential(
    ap: float, jp: float, c: float, r: float, v: float, an_: float, jn_: float
) -> tuple[float, float]:
    """Tangential (accel, jerk) on an arc at path speed v, from the plane budgets."""
    an = c * c * v * v / r
    x = ap * ap - an * an
    at = sqrt(x if x >= 0.0 else 0.0) / c
    # in-plane jerk: (c*s3 - c^3 sdot^3/r^2) along the tangent, 3 c^2 sdot sddot / r along
    # the normal; the tangent part gets Q_TANGENT of the plane jerk, the normal the rest
    k = c * c * c * v * v * v / (r * r)
    q = Q_TANGENT * jp
    if k > q:
        q = k
    jt = (q - k) / c
    x = jp * jp - q * q
    x = sqrt(x if x >= 0.0 else 0.0) * r / (3.0 * c * c * v)
    if x < at:
        at = x
    if an_ < at:
        at = an_
    if jn_ < jt:
        jt = jn_
    return at, jt


def junction_cap(
    lim: AxisLimits,
    du: Vec3,
    dk: Vec3,
    gap: float,
    at_max: float,
    inside_span: bool,
) -> float:
    """Highest path speed at a junction with tangent jump du and curvature-vector jump dk.

    Passing the junction at speed v adds to the sampled jerk of axis i at most
    0.75/T * |dk_i| v^2 (acceleration step) + |du_i| v / T^2 (velocity step), and to the
    sampled acceleration at most |du_i| v / T. A junction may use the share
    w = min(1, gap / (3T (v + dv3))) of a quarter of the junction budget, `gap` being the
    length of one of its two pieces (the caller passes the longer one, counting only
    what can never be trimmed away): a 3-cycle window covers at most 3T (v + dv3) of path
    around a junction passed at v; the pieces between its first and last junction lie
    inside it and each is the gap of at most two junctions, so with the two outermost
    junctions the shares of one window sum to <= 4 quarters.
    """
    if not (du[0] or du[1] or du[2] or dk[0] or dk[1] or dk[2]):
        return INF
    t = lim.ipo
    c = lim.dv3
    # one conservative constraint for all axes: each coefficient normalised by the axis'
    # budget, then the largest of each taken (so every axis' own constraint holds);
    # written out for the three pose axes: this runs for every junction of the path
    k75 = 0.75 / t
    j0, j1, j2 = lim.jerk_q
    b0, b1, b2 = lim.jerk_qtt
    g0, g1, g2 = lim.acc_qt
    u0, u1, u2 = du
    if u0 < 0.0:
        u0 = -u0
    if u1 < 0.0:
        u1 = -u1
    if u2 < 0.0:
        u2 = -u2
    d0, d1, d2 = dk
    if d0 < 0.0:
        d0 = -d0
    if d1 < 0.0:
        d1 = -d1
    if d2 < 0.0:
        d2 = -d2
    alpha = beta = lose = gam = 0.0
    x = k75 * d0 / j0
    if x > alpha:
        alpha = x
    x = k75 * d1 / j1
    if x > alpha:
        alpha = x
    x = k75 * d2 / j2
    if x > alpha:
        alpha = x
    if u0 or u1 or u2:
        x = u0 / b0
        if x > beta:
            beta = x
        x = u1 / b1
        if x > beta:
            beta = x
        x = u2 / b2
        if x > beta:
            beta = x
        if inside_span:
            x = k75 * u0 * at_max / j0
            if x > lose:
                lose = x
            x = k75 * u1 * at_max / j1
            if x > lose:
                lose = x
            x = k75 * u2 * at_max / j2
            if x > lose:
                lose = x
        x = u0 / g0
        if x > gam:
            gam = x
        x = u1 / g1
        if x > gam:
            gam = x
        x = u2 / g2
        if x > gam:
            gam = x
    cap = _jerk_cap(alpha, beta, 1.0, lose, gap, t, c, lim.vtop)
    if gam > 0.0:
        # acceleration share: gam v <= w(v) = min(1, gap / (3T (v + c)))
        va = 1.0 / gam
        if gap < 3.0 * t * (va + c):
            k = gap / (3.0 * t * gam)  # v (v + c) = k
            va = 2.0 * k / (c + sqrt(c * c + 4.0 * k))
        if va < cap:
            cap = va
    return cap if cap > 0.0 else 0.0


def coast_cap(lim: AxisLimits, du: Vec3, dk: Vec3, kacc: Vec3, kjerk: Vec3) -> float:
    """Highest speed for a junction passed in a *coast*: 3 IPO cycles of constant path
    speed on both sides (no path acceleration or jerk), so within its sampling window the
    only continuous terms are the centripetal ones of the two pieces (kacc_i v^2 and
    kjerk_i v^3, per axis). The junction may then use the continuous budget
    ((1 - RHO_JUMP) J, (1 - RHO_KINK_A) A); the junction shares stay for the junctions
    inside spans that may fall in the same window.
    """
    t = lim.ipo
    k75 = 0.75 / t
    # normalised coefficients, the largest over the three pose axes (written out: this
    # runs for every junction a plan passes in a coast)
    bj0, bj1, bj2 = lim.jerk_k
    tj0, tj1, tj2 = lim.jerk_ktt
    ba0, ba1, ba2 = lim.acc_k
    ta0, ta1, ta2 = lim.acc_kt
    u0, u1, u2 = du
    if u0 < 0.0:
        u0 = -u0
    if u1 < 0.0:
        u1 = -u1
    if u2 < 0.0:
        u2 = -u2
    d0, d1, d2 = dk
    if d0 < 0.0:
        d0 = -d0
    if d1 < 0.0:
        d1 = -d1
    if d2 < 0.0:
        d2 = -d2
    # normalised jerk coefficients of v^3, v^2, v and acceleration coefficients of v^2, v
    # (each the largest over the axes; all are >= 0, as the zero start was)
    kj0, kj1, kj2 = kjerk
    ka0, ka1, ka2 = kacc
    a3 = _max3(kj0 / bj0, kj1 / bj1, kj2 / bj2)
    a2 = _max3(k75 * d0 / bj0, k75 * d1 / bj1, k75 * d2 / bj2)
    a1 = _max3(u0 / tj0, u1 / tj1, u2 / tj2)
    b2 = _max3(ka0 / ba0, ka1 / ba1, ka2 / ba2)
    b1 = _max3(u0 / ta0, u1 / ta1, u2 / ta2)
    v = lim.vtop
    # acceleration: b2 v^2 + b1 v <= 1
    if b2 > 0.0:
        x = 2.0 / (b1 + sqrt(b1 * b1 + 4.0 * b2))
        if x < v:
            v = x
    elif b1 > 0.0:
        x = 1.0 / b1
        if x < v:
            v = x
    # jerk: a3 v^3 + a2 v^2 + a1 v <= 1, Newton from an upper bound (convex, increasing)
    if a3 > 0.0:
        x = fpow(a3, -1.0 / 3.0)
        if x < v:
            v = x
    if a2 > 0.0:
        x = fpow(a2, -0.5)
        if x < v:
            v = x
    if a1 > 0.0:
        x = 1.0 / a1
        if x < v:
            v = x
    for _ in range(40):
        h = ((a3 * v + a2) * v + a1) * v - 1.0
        if h <= 0.0:
            return v
        nv = v - h / ((3.0 * a3 * v + 2.0 * a2) * v + a1)
        if nv >= v * (1.0 - 1e-14):
            break
        v = nv
    v *= 1.0 - 1e-10
    while v > 0.0 and ((a3 * v + a2) * v + a1) * v > 1.0:
        v *= 0.5
    return v


ZERO3: Vec3 = (0.0, 0.0, 0.0)
NO_CENTRIPETAL: tuple[Vec3, Vec3] = (ZERO3, ZERO3)


def centripetal(lim: AxisLimits, geom: Piece) -> tuple[Vec3, Vec3]:
    """Per-axis (accel / v^2, jerk / v^3) of constant-speed motion on a piece.

    Kept on the arc once computed: each arc meets two junctions.
    """
    if not isinstance(geom, Arc):
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)  # NO_CENTRIPETAL
    got = geom.cent
    if got is not None:
        return got
    r0, r1 = geom.r0, geom.r1
    c = 0.5 * (r0 + r1) * geom.sweep / geom.length  # Arc.plane_fraction
    r = r1 if r1 < r0 else r0
    (a0, a1, a2), (b0, b1, b2) = geom.e1, geom.e2
    e0 = sqrt(a0 * a0 + b0 * b0)
    e1 = sqrt(a1 * a1 + b1 * b1)
    e2 = sqrt(a2 * a2 + b2 * b2)
    geom.cent = got = (
        (e0 * c * c / r, e1 * c * c / r, e2 * c * c / r),
        (e0 * c * c * c / (r * r), e1 * c * c * c / (r * r), e2 * c * c * c / (r * r)),
    )
    return got


def _max3(x: float, y: float, z: float) -> float:
    """max(0.0, x, y, z) for non-negative x, y, z (comparisons, no builtin call)."""
    m = 0.0
    if x > m:
        m = x
    if y > m:
        m = y
    if z > m:
        m = z
    return m


def _jerk_cap(
    alpha: float,
    beta: float,
    full: float,
    lose: float,
    gap: float,
    t: float,
    c: float,
    vtop: float,
) -> float:
    """Largest v <= vtop with alpha v^2 + beta v + lose <= full * min(1, gap / (3T (v + c))).

    Returns INF when even vtop (no path speed can exceed it) qualifies.
    """
    w = gap / (3.0 * t * (vtop + c))
    if (alpha * vtop + beta) * vtop + lose <= full * (w if w < 1.0 else 1.0):
        return INF
    b = full - lose
    if b <= 0.0:
        return 0.0
    if alpha > 0.0:
        v = 2.0 * b / (beta + sqrt(beta * beta + 4.0 * alpha * b))
    else:
        v = b / beta
    if gap >= 3.0 * t * (v + c):
        return v
    # w < 1: h(v) = (alpha v^2 + beta v + lose)(v + c) - k, increasing and convex for
    # v >= 0; Newton from an upper bound of the root converges monotonically from above
    k = full * gap / (3.0 * t)
    if lose * c >= k:
        return 0.0
    # upper bounds of the root (comparisons rather than min(): same values, runs per block)
    if alpha > 0.0:
        x = fpow(k / alpha, 1.0 / 3.0)
        if x < v:
            v = x
        if c > 0.0:
            x = sqrt(k / (alpha * c))
            if x < v:
                v = x
    if beta > 0.0:
        x = sqrt(k / beta)
        if x < v:
            v = x
        if c > 0.0:
            x = k / (beta * c)
            if x < v:
                v = x
    for _ in range(40):
        q = (alpha * v + beta) * v + lose
        h = q * (v + c) - k
        if h <= 0.0:
            return v
        nv = v - h / ((2.0 * alpha * v + beta) * (v + c) + q)
        if nv >= v * (1.0 - 1e-14):
            break
        v = nv
    v *= 1.0 - 1e-10
    if ((alpha * v + beta) * v + lose) * (v + c) > k:  # not expected; bisect
        lo, hi = 0.0, v
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if ((alpha * mid + beta) * mid + lose) * (mid + c) > k:
                hi = mid
            else:
                lo = mid
        v = lo
    return v if v > 0.0 else 0.0


def piece_limits(lim: AxisLimits, geom: Piece, normal_axis: int) -> tuple[float, float, float]:
    if isinstance(geom, Line):
        return line_limits(lim, geom.u)
    if not isinstance(geom, Arc):
        raise TypeError(f"not a path piece: {geom!r}")
    return arc_limits(lim, geom, normal_axis)
