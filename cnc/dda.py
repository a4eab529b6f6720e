"""DDA reference interpolator: the digital differential analyser of the hardware NC era.

This is a teaching model and a test oracle, not the production interpolator (that one samples
the plan in closed form at the IPO cycle). It reproduces the worked examples of the seeds
step for step:

* 001_feed_drives.md ch. 7: the DDA integrator (Table 7-1), linear interpolation with two
  integrators on one clock (Table 7-2), the feed-rate registers (example 7-2), circular
  interpolation with two cross-coupled integrators (Table 7-3), the software iteration
  rate (example 7-4) and the chord count per quadrant (7.4).
* 000_nc_book.md §4.2: the linear DDA with N = the next power of ten above the minimum step
  count (Fig. 4-6) and the summation form of the circular DDA (explicit and sequential).

One integrator is a p register (the increment, in BLU) and a q register (the remainder) of
`capacity` states (2**n for an n-bit binary register, 10**k for a decimal one, any S in the
software DDA). Each clock q += p; when q reaches the capacity one output pulse is emitted and
q keeps the remainder. Everything is integer arithmetic, so the tables are exact.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from cnc.errors import NcError

__all__ = [
    "DdaRun",
    "DdaStep",
    "FeedRateRegisters",
    "LinePlan",
    "chord_segments_per_quadrant",
    "dda_circle",
    "dda_circle_sum",
    "dda_integrator",
    "dda_line",
    "feed_rate_registers",
    "line_plan",
    "software_iteration_rate",
    "step_table_markdown",
]

_MAX_CLOCKS = 10_000_000  # a run longer than this is a configuration mistake, not a teaching case


@dataclass(frozen=True, slots=True)
class DdaStep:
    """One row of a DDA step table.

    `clock` 0 is the loaded state before the first clock. `p` is the p register content the
    integrator used during this clock, `q` the remainder after it, `dz` the overflow pulses
    (0 or 1, unsigned, as the hardware emits them) and `total` the running pulse count; all
    per axis in the run's axis order.
    """

    clock: int
    p: tuple[int, ...]
    q: tuple[int, ...]
    dz: tuple[int, ...]
    total: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class DdaRun:
    """The result of a DDA run: the step table and the signed pulse train of every axis.

    `pulses[axis][k]` is +1, -1 or 0: the motion command sent to that axis's drive on clock
    k + 1 (the direction comes from the sign of the increment or the arc quadrant).
    `steps` is empty when the run was asked not to record it (long runs).
    """

    capacity: int
    steps: tuple[DdaStep, ...]
    pulses: tuple[tuple[int, ...], ...]

    @property
    def clocks(self) -> int:
        return len(self.pulses[0]) if self.pulses else 0

    @property
    def displacement(self) -> tuple[int, ...]:
        """Signed motion of every axis in BLU after the last clock."""
        return tuple(sum(train) for train in self.pulses)

    def position(self, clock: int) -> tuple[int, ...]:
        """Signed motion of every axis in BLU after `clock` clocks (0 = start)."""
        if not 0 <= clock <= self.clocks:
            raise ValueError(f"clock {clock} outside 0..{self.clocks}")
        return tuple(sum(train[:clock]) for train in self.pulses)

    def pulse_clocks(self, axis: int) -> tuple[int, ...]:
        """The 1-based clocks on which `axis` received a pulse."""
        return tuple(k + 1 for k, v in enumerate(self.pulses[axis]) if v)


def _capacity(n_bits: int | None, capacity: int | None) -> int:
    if n_bits is not None and capacity is not None:
        raise NcError("give either n_bits or capacity for the DDA register, not both")
    if n_bits is not None:
        if n_bits < 1 or n_bits > 62:
            raise NcError(f"DDA register length must be 1..62 bits, got {n_bits}")
        return 1 << n_bits
    if capacity is None:
        raise NcError("the DDA register needs n_bits or capacity")
    if capacity < 2:
        raise NcError(f"DDA register capacity must be >= 2, got {capacity}")
    return capacity


def dda_integrator(
    p: int,
    clocks: int,
    *,
    n_bits: int | None = None,
    capacity: int | None = None,
    q0: int = 0,
) -> DdaRun:
    """Run one DDA integrator with a constant p register for `clocks` clocks (Table 7-1).

    The mean output pulse rate is p * f / capacity (eq. 7-12).
    """
    cap = _capacity(n_bits, capacity)
    if not 0 <= p <= cap:
        raise NcError(f"p register {p} does not fit a register of capacity {cap}")
    if not 0 <= q0 < cap:
        raise NcError(f"q register start value {q0} outside 0..{cap - 1}")
    if not 0 <= clocks <= _MAX_CLOCKS:
        raise NcError(f"clock count must be 0..{_MAX_CLOCKS}, got {clocks}")
    q, total = q0, 0
    steps = [DdaStep(0, (p,), (q,), (0,), (0,))]
    train: list[int] = []
    for clock in range(1, clocks + 1):
        q += p
        dz = 1 if q >= cap else 0
        q -= dz * cap
        total += dz
        train.append(dz)
        steps.append(DdaStep(clock, (p,), (q,), (dz,), (total,)))
    return DdaRun(cap, tuple(steps), (tuple(train),))


def dda_line(
    deltas: Sequence[int],
    *,
    n_bits: int | None = None,
    capacity: int | None = None,
    record_steps: bool = True,
) -> DdaRun:
    """Linear interpolation: one integrator per axis on a common clock (Table 7-2).

    `deltas` are the signed increments of the axes in BLU; each p register is loaded with
    the magnitude and the sign selects the drive direction. After exactly `capacity` clocks
    every q register is back at 0 and every axis has received exactly |delta| pulses, so the
    end point is reached without error. Without `n_bits` or `capacity` the software DDA
    rule S := L applies (capacity = path length in BLU, rounded up: one iteration moves
    about one BLU along the path, 001 ch. 7.4).
    """
    if not deltas:
        raise NcError("a DDA line needs at least one axis")
    if n_bits is None and capacity is None:
        capacity = max(2, math.ceil(math.hypot(*deltas)))
    cap = _capacity(n_bits, capacity)
    mags = tuple(abs(int(d)) for d in deltas)
    for axis, m in enumerate(mags):
        if m > cap:
            raise NcError(
                f"axis {axis} increment {m} BLU does not fit a register of capacity {cap}"
                " (increase the register length)"
            )
    if cap > _MAX_CLOCKS:
        raise NcError(f"DDA line of {cap} clocks exceeds the {_MAX_CLOCKS} clock limit")
    signs = tuple(1 if d > 0 else -1 for d in deltas)
    n = len(mags)
    q = [0] * n
    total = [0] * n
    steps = [DdaStep(0, mags, tuple(q), (0,) * n, (0,) * n)] if record_steps else []
    trains: list[list[int]] = [[] for _ in range(n)]
    for clock in range(1, cap + 1):
        dz = [0] * n
        for a in range(n):
            q[a] += mags[a]
            if q[a] >= cap:
                q[a] -= cap
                dz[a] = 1
                total[a] += 1
            trains[a].append(dz[a] * signs[a])
        if record_steps:
            steps.append(DdaStep(clock, mags, tuple(q), tuple(dz), tuple(total)))
    return DdaRun(cap, tuple(steps), tuple(tuple(t) for t in trains))


# --- circular interpolation -------------------------------------------------------------


def _quadrant(x: float, y: float) -> int:
    """Quadrant 0..3 of a direction (x, y) that lies strictly inside one."""
    if x > 0 and y > 0:
        return 0
    if x < 0 < y:
        return 1
    if x < 0 and y < 0:
        return 2
    return 3


def _quadrant_pieces(
    start: tuple[int, int], end: tuple[int, int], clockwise: bool
) -> list[tuple[tuple[int, int], tuple[int, int], int]]:
    """Split an arc about the origin at the axes: (piece start, piece end, quadrant)."""
    a0 = math.atan2(start[1], start[0])
    a1 = math.atan2(end[1], end[0])
    sweep = (a0 - a1) if clockwise else (a1 - a0)
    sweep %= 2 * math.pi
    if sweep < 1e-12:
        sweep = 2 * math.pi  # start == end: a full circle, as G2/G3 read it
    direction = -1.0 if clockwise else 1.0
    # Axis crossings strictly inside the sweep, as angles travelled from the start.
    cuts: list[float] = []
    quarter = math.pi / 2
    k = math.ceil(a0 / quarter) if clockwise else math.floor(a0 / quarter)
    while True:
        k += -1 if clockwise else 1
        travelled = (k * quarter - a0) * direction
        if travelled >= sweep - 1e-12:
            break
        if travelled > 1e-12:
            cuts.append(travelled)
    # The cut points sit on the axes at the radius interpolated between the start and end
    # radii, but never inside the neighbouring end point's coordinate along that axis: on a
    # circle a coordinate is largest where the other one is zero.
    r0, r1 = math.hypot(*start), math.hypot(*end)
    points = [start]
    for i, t in enumerate(cuts):
        b = a0 + direction * t
        radius = round(r0 + (r1 - r0) * t / sweep)
        ux, uy = round(math.cos(b)), round(math.sin(b))  # the axis' unit vector
        if i == 0:
            radius = max(radius, abs(start[0] * ux + start[1] * uy))
        if i == len(cuts) - 1:
            radius = max(radius, abs(end[0] * ux + end[1] * uy))
        points.append((radius * ux, radius * uy))
    points.append(end)
    bounds = [0.0, *cuts, sweep]
    pieces = []
    for i in range(len(points) - 1):
        mid = a0 + direction * (bounds[i] + bounds[i + 1]) / 2
        pieces.append((points[i], points[i + 1], _quadrant(math.cos(mid), math.sin(mid))))
    return pieces


def dda_circle(
    start: tuple[int, int],
    end: tuple[int, int],
    *,
    clockwise: bool = False,
    n_bits: int | None = None,
    capacity: int | None = None,
    endpoint: Literal["register", "counters"] = "counters",
    record_steps: bool = True,
) -> DdaRun:
    """Circular interpolation with two cross-coupled integrators (001 ch. 7.3, Table 7-3).

    `start` and `end` are the arc's start and end relative to the centre, in BLU (the
    table's i = x - x0 and y - y0); start == end is a full circle. DDA-1 drives X and holds
    |y - y0|, DDA-2 drives Y and holds |x - x0|; each overflow of one integrator steps the
    other's p register by one BLU (+ when that coordinate's magnitude grows, - when it
    shrinks). Per clock DDA-2 adds first and its pulse updates p1 at once; DDA-1 adds next
    and its pulse updates p2 from the next clock. This sequential order is what keeps the
    radius from growing, and it is the order that reproduces Table 7-3.

    `endpoint` selects the end-point handling:

    * "register" (the hardware interpolator of the book): one quadrant only; stop when the
      p register of the coordinate that shrinks reaches its end value. The other axis is not
      counted, so it may overshoot by about one BLU: Table 7-3 ends with 15 X and 16 Y
      pulses.
    * "counters" (the software DDA): each axis has a pulse down-counter loaded with its
      travel; an axis whose counter is empty is gated off and the run stops when both are
      empty, so the end point is exact. Arcs crossing quadrant boundaries are split there
      (the software removes the hardware's one-quadrant limit); q registers carry over.
      End points may be off the start radius by up to one BLU (integer end points); when
      that leaves an axis owing pulses while its p register has run down to 0, the axis is
      fed one pulse per clock until it arrives (the explicit end-point condition, task 4 of
      000_nc_book.md §4.1).
    """
    if endpoint not in ("register", "counters"):
        raise NcError(f"unknown DDA end-point handling {endpoint!r}")
    cap = _capacity(n_bits, capacity)
    sx, sy = int(start[0]), int(start[1])
    ex, ey = int(end[0]), int(end[1])
    r_start, r_end = math.hypot(sx, sy), math.hypot(ex, ey)
    if r_start == 0:
        raise NcError("DDA arc start coincides with the centre")
    if abs(r_start - r_end) > 1.0 + 1e-9:
        raise NcError(
            f"DDA arc radii differ by more than 1 BLU: start {r_start:.3f}, end {r_end:.3f}"
        )
    if max(abs(sx), abs(sy), abs(ex), abs(ey)) > cap - 1:
        raise NcError(
            f"arc radius {r_start:.0f} BLU does not fit a register of capacity {cap}"
            f" (max {cap - 1})"
        )
    pieces = _quadrant_pieces((sx, sy), (ex, ey), clockwise)
    if endpoint == "register" and len(pieces) > 1:
        raise NcError(
            "the hardware DDA interpolates within one quadrant only; split the arc at the"
            " quadrant boundaries (or use endpoint='counters')"
        )
    if 2 * cap * len(pieces) > _MAX_CLOCKS:
        raise NcError(
            f"a DDA arc with a register of capacity {cap} takes more than {_MAX_CLOCKS} clocks"
        )

    software = endpoint == "counters"
    q1 = q2 = 0
    total = [0, 0]
    p1, p2 = abs(sy), abs(sx)
    steps = [DdaStep(0, (p1, p2), (q1, q2), (0, 0), (0, 0))] if record_steps else []
    tx: list[int] = []
    ty: list[int] = []
    clock = 0
    for (px, py), (qx, qy), quad in pieces:
        qsx = 1 if quad in (0, 3) else -1  # sign of x inside the quadrant
        qsy = 1 if quad in (0, 1) else -1
        # Direction of travel per axis: CCW velocity is (-y, x), CW is (y, -x). With end
        # points off the radius by up to a BLU the piece's own travel decides.
        dir_x = qsy if clockwise else -qsy
        dir_y = -qsx if clockwise else qsx
        if endpoint == "counters":
            dir_x = (1 if qx > px else -1) if qx != px else dir_x
            dir_y = (1 if qy > py else -1) if qy != py else dir_y
        d_abs_x = qsx * dir_x  # how |x| changes with an X pulse (+1 or -1)
        d_abs_y = qsy * dir_y
        p1, p2 = abs(py), abs(px)
        left_x, left_y = abs(qx - px), abs(qy - py)
        limit = clock + 4 * cap + 16
        while True:
            if endpoint == "register":
                if d_abs_x < 0 and p2 == abs(qx) and clock > 0:
                    break
                if d_abs_y < 0 and p1 == abs(qy) and clock > 0:
                    break
            elif left_x == 0 and left_y == 0:
                break
            clock += 1
            if clock > limit:
                raise NcError("DDA arc did not reach its end point (inconsistent arc data)")
            used_p2 = p2
            dz2 = 0
            if endpoint == "register" or left_y > 0:
                q2 += p2 if p2 or left_x or not software else cap  # end-point snap
                if q2 >= cap:
                    q2 -= cap
                    dz2 = 1
                    left_y -= 1
                    p1 = min(max(p1 + d_abs_y, 0), cap - 1)  # the register saturates
            dz1 = 0
            if endpoint == "register" or left_x > 0:
                q1 += p1 if p1 or left_y or not software else cap
                if q1 >= cap:
                    q1 -= cap
                    dz1 = 1
                    left_x -= 1
                    p2 = min(max(p2 + d_abs_x, 0), cap - 1)
            total[0] += dz1
            total[1] += dz2
            tx.append(dz1 * dir_x)
            ty.append(dz2 * dir_y)
            if record_steps:
                steps.append(
                    DdaStep(clock, (p1, used_p2), (q1, q2), (dz1, dz2), (total[0], total[1]))
                )
    return DdaRun(cap, tuple(steps), (tuple(tx), tuple(ty)))


def dda_circle_sum(
    start: tuple[float, float],
    steps_per_circle: int,
    steps: int,
    *,
    sequential: bool = True,
) -> list[tuple[float, float]]:
    """The summation form of the circular DDA of 000_nc_book.md §4.2.2 (CCW, centre 0).

    x <- x - (2 pi / N) y, y <- y + (2 pi / N) x. With `sequential` the y update uses the
    freshly updated x (the non-divergent "sequential DDA"); otherwise both use the old values
    (explicit Euler, as printed), whose radius grows by sqrt(1 + (2 pi / N)^2) per step.
    Returns the points after each step, the start first.
    """
    if steps_per_circle < 1 or steps < 0:
        raise NcError("the circular DDA needs N >= 1 steps per circle and steps >= 0")
    k = 2 * math.pi / steps_per_circle
    x, y = float(start[0]), float(start[1])
    out = [(x, y)]
    for _ in range(steps):
        if sequential:
            x = x - k * y
            y = y + k * x
        else:
            x, y = x - k * y, y + k * x
        out.append((x, y))
    return out


# --- the figures around the DDA ----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LinePlan:
    """The DDA line figures of 000_nc_book.md Fig. 4-6 (mm, s, Hz)."""

    length_mm: float  # L
    time_s: float  # T = L / u
    min_steps: int  # N_min: no per-step increment above one BLU
    steps: int  # N: N_min rounded up to a power of the register radix
    step_time_s: float  # dt = T / N
    clock_hz: float  # f = 1 / dt
    increments_mm: tuple[float, ...]  # per step and axis
    deltas_blu: tuple[int, ...]  # travel per axis in BLU (the p registers)


def line_plan(
    start: Sequence[float],
    end: Sequence[float],
    feed_mm_min: float,
    blu_mm: float = 0.001,
    radix: int = 10,
) -> LinePlan:
    """Step count and clock of a DDA line (000_nc_book.md §4.2.1, Fig. 4-6).

    N is the smallest power of `radix` (10 in the book; 2 for a binary register) with no
    per-step increment above one BLU. Run the line with `dda_line(plan.deltas_blu,
    capacity=plan.steps)`.
    """
    if len(start) != len(end) or not start:
        raise NcError("line start and end need the same, non-zero number of axes")
    if feed_mm_min <= 0 or blu_mm <= 0 or radix < 2:
        raise NcError("feed, BLU must be > 0 and the radix >= 2")
    deltas = [e - s for s, e in zip(start, end, strict=True)]
    length = math.hypot(*deltas)
    if length == 0:
        raise NcError("zero-length DDA line")
    t = length * 60.0 / feed_mm_min
    blus = tuple(round(d / blu_mm) for d in deltas)
    n_min = max(abs(b) for b in blus)
    n = 1
    while n < n_min:
        n *= radix
    return LinePlan(
        length_mm=length,
        time_s=t,
        min_steps=n_min,
        steps=n,
        step_time_s=t / n,
        clock_hz=n / t,
        increments_mm=tuple(d / n for d in deltas),
        deltas_blu=blus,
    )


@dataclass(frozen=True, slots=True)
class FeedRateRegisters:
    """Example 7-2: axis velocities in BLU/s and the p registers that produce them."""

    velocities_blu_s: tuple[float, ...]
    p: tuple[int, ...]


def feed_rate_registers(
    deltas_mm: Sequence[float],
    feed_mm_min: float,
    blu_mm: float,
    clock_hz: float,
    n_bits: int,
) -> FeedRateRegisters:
    """p_axis = round(f_axis * 2**n / f_clock), f_axis = V * delta / (L * BLU * 60)."""
    length = math.hypot(*deltas_mm)
    if length == 0 or feed_mm_min <= 0 or blu_mm <= 0 or clock_hz <= 0:
        raise NcError("feed-rate registers need a non-zero move, feed, BLU and clock")
    vel = tuple(feed_mm_min * d / (length * blu_mm * 60.0) for d in deltas_mm)
    p = tuple(round(abs(v) * (1 << n_bits) / clock_hz) for v in vel)
    for axis, value in enumerate(p):
        if value >= 1 << n_bits:
            raise NcError(
                f"axis {axis} needs p = {value}, which does not fit {n_bits} bits:"
                " raise the clock frequency"
            )
    return FeedRateRegisters(vel, p)


def software_iteration_rate(max_feed_mm_min: float, blu_mm: float) -> tuple[float, float]:
    """(iterations per second, period in s) so that one iteration moves one BLU at the
    maximum feed (example 7-4: 3600 mm/min, 0.01 mm -> 6000 Hz, 166.7 us)."""
    if max_feed_mm_min <= 0 or blu_mm <= 0:
        raise NcError("maximum feed and BLU must be > 0")
    f = max_feed_mm_min / (blu_mm * 60.0)
    return f, 1.0 / f


def chord_segments_per_quadrant(radius_mm: float, chord_error_mm: float) -> int:
    """Chords per quadrant so that the chord height stays within `chord_error_mm`
    (eqs. 7-49..7-51: alpha = 2 acos(1 - EH / R), N = ceil(pi / (2 alpha)))."""
    if radius_mm <= 0 or not 0 < chord_error_mm < radius_mm:
        raise NcError("chord count needs R > 0 and 0 < chord error < R")
    alpha = 2.0 * math.acos(1.0 - chord_error_mm / radius_mm)
    return math.ceil(math.pi / (2.0 * alpha))


def step_table_markdown(run: DdaRun, axis_names: Sequence[str] = ("X", "Y", "Z", "A")) -> str:
    """The step table of a run as a Markdown table (docs/dda.md is rendered with it)."""
    names = list(axis_names[: len(run.pulses)])
    head = ["clock"]
    for name in names:
        head += [f"p {name}", f"q {name}", f"Δz {name}", f"Σ {name}"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---:|" * len(head)]
    for s in run.steps:
        cells = [str(s.clock)]
        for a in range(len(names)):
            cells += [str(s.p[a]), str(s.q[a]), "1" if s.dz[a] else "", str(s.total[a])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
