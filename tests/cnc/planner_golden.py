"""Golden digests of the look-ahead planner and the interpolator, bit for bit.

The planner may run as mypyc-compiled extensions (cnc/planner/mypyc.list) or as the plain
Python sources; both must give exactly the same floats. Each scenario below reduces what
the planner produced (IPO samples, path pieces with their limits and junctions, planned
spans) to a SHA-256 of the `repr` of every value, so a single changed bit shows.

`GOLDEN` holds the digests recorded on the pure-Python sources. The module imports
nothing from tests/, so tests/cnc/test_planner_golden.py can run it on a copy of `cnc/`
without the compiled extensions: `python planner_golden.py` prints the digests as JSON
and where the planner modules were loaded from.
"""

from __future__ import annotations

import hashlib
import json
import math
import random
import sys

from cnc.canon import (
    ArcFeed,
    AuxFunction,
    Dwell,
    PathMode,
    Plane,
    SetPathMode,
    StraightFeed,
    StraightTraverse,
)
from cnc.interpolator import Motion
from cnc.params import MachineParams
from cnc.planner.profile import partition, solve

GOLDEN = {
    "events": "f690f32ea6ee1d6f359b65640ad97478a9a23b26be01905d9948598d699556e3",
    "bench_path_pieces": "4988196e4868d2367f40d68bf9542ffb27058635f1aa98173b92d220e407c3d5",
    "bench_path_plans": "b234321debfa75dbe2eea3e78d12c7bf55d08e447ea9c640fda15a4688f0cc0a",
    "bench_path_trace": "b935b41783971d3fd66b9aa0e3f385d5a583e040bf1712e54f630ed77a4f1287",
    "circle": "95b3e29ab6fd27d1788b2b00e8534b856a0af3e6842116b3e054aacfb96a488a",
    "mixed": "501fb9e5ff0224382c60692387c96383a1e82daf95720fadb514f261d723bfc7",
    "mixed_single_block": "42e3405c7d0c3c9b645ff2e08494724543ffd7eb71496bf1850de3faaec06c14",
    "hold_and_overrides": "388cf47a139246bcdf6feb5ca7693276476be2f131ffee5f623c4b96a7275fa9",
    "ipo_half_ms": "beef69378d8034570d050c897e070e5e546bd92a9bb0d3188817b4c99aaf7e35",
    "ipo_eight_ms": "c421dd70d48023e601ca2e82345e552df7c049e2cf0af071abca83f667c76afc",
    "random": "198c1119451ce76a4d8d9536ddf7c82e0c647eb47db5d11bbca66af3d54882cc",
}


class Digest:
    def __init__(self) -> None:
        self._h = hashlib.sha256()

    def add(self, *values: object) -> None:
        self._h.update(repr(values).encode())
        self._h.update(b"\n")

    def hexdigest(self) -> str:
        return self._h.hexdigest()


def run_trace(m: Motion, cmds: list, events: dict | None = None, max_cycles=200_000) -> str:
    """Push everything the look-ahead takes, step to idle, acknowledge sync points at once;
    `events` maps a cycle number to a callable run on the Motion before that cycle."""
    d = Digest()
    it = iter(cmds)
    pending = next(it, None)
    fed_all = False
    for k in range(max_cycles):
        while pending is not None and m.push(pending):
            pending = next(it, None)
        if pending is None and not fed_all:
            m.end_of_program()
            fed_all = True
        if events and k in events:
            events[k](m)
        s = m.step()
        d.add(s.t, s.pose, s.velocity, s.line, s.sync)
        if s.sync is not None:
            m.acknowledge()
        if fed_all and m.idle:
            d.add(m.replans, m.block, m.path_position)
            return d.hexdigest()
    raise AssertionError("motion did not finish")


def spiral_program() -> list:
    """Blended short lines, a rapid, helices and arcs in all three planes."""
    cmds = [SetPathMode(1, PathMode.CONTINUOUS, 0.02), StraightTraverse(2, (-5.0, -5.0, 0.0))]
    for i in range(60):
        a = 0.1 * i
        end = (-20.0 + 8 * math.cos(a), -20.0 + 8 * math.sin(a), -0.01 * i)
        cmds.append(StraightFeed(3 + i, end, 4000.0))
    cmds.append(ArcFeed(70, (-30.0, -20.0, -1.0), (-25.0, -20.0, -0.6), Plane.XY, True, 4000.0))
    return cmds


def mixed_program() -> list:
    """Everything a block can be: rapids, G9, G61, sync points, slow arcs, zero moves."""
    return [
        SetPathMode(1, PathMode.CONTINUOUS, 0.05),
        StraightTraverse(2, (-10.0, -10.0, -2.0)),
        StraightFeed(3, (-40.0, -10.0, -2.0), 3000.0),
        StraightFeed(4, (-40.0, -40.0, -2.0), 3000.0, True),  # G9
        StraightFeed(5, (-40.0, -40.0, -2.0), 3000.0),  # zero length: dropped
        ArcFeed(6, (-60.0, -40.0, -2.0), (-50.0, -40.0, -2.0), Plane.XY, False, 300.0),
        ArcFeed(7, (-60.0, -40.0, -6.0), (-55.0, -40.0, -4.0), Plane.ZX, True, 1200.0),
        ArcFeed(8, (-60.0, -30.0, -6.0), (-60.0, -35.0, -6.0), Plane.YZ, False, 2500.0, 1),
        Dwell(9, 0.5),
        AuxFunction(10, 8),
        SetPathMode(11, PathMode.CONTINUOUS, 0.0),
        StraightFeed(12, (-61.0, -31.0, -6.0), 5000.0),
        StraightFeed(13, (-61.0, -29.5, -6.1), 5000.0),
        StraightFeed(14, (-59.7, -29.5, -6.1), 5000.0),
        ArcFeed(15, (-49.7, -29.5, -9.1), (-54.7, -29.5, -6.1), Plane.XY, True, 9000.0, 2),
        SetPathMode(16, PathMode.EXACT_STOP),
        StraightFeed(17, (-45.0, -25.0, -9.0), 2000.0),
        StraightFeed(18, (-45.0, -20.0, -9.0), 2000.0),
        SetPathMode(19, PathMode.CONTINUOUS, 0.01),
        StraightTraverse(20, (-30.0, -20.0, -1.0)),
        StraightFeed(21, (-30.0, -5.0, -1.0), 6000.0),
        StraightTraverse(22, (-5.0, -5.0, 0.0)),
        StraightTraverse(23, (-1.0, -1.0, 0.0)),
    ]


def random_program(seed: int, n: int) -> list:
    """Seeded random blocks of every kind, with short and long moves and odd feeds."""
    rng = random.Random(seed)
    cmds: list = []
    x, y, z = 0.0, 0.0, 0.0
    for i in range(n):
        kind = rng.random()
        line = 10 + i
        if kind < 0.05:
            cmds.append(SetPathMode(line, PathMode.CONTINUOUS, rng.choice([0.0, 0.001, 0.05, 0.3])))
            continue
        if kind < 0.08:
            cmds.append(Dwell(line, 0.01))
            continue
        step = rng.choice([1e-4, 0.003, 0.1, 1.0, 20.0])
        nx = x + rng.uniform(-step, step)
        ny = y + rng.uniform(-step, step)
        nz = z + rng.uniform(-step, step) * 0.2
        feed = rng.choice([50.0, 700.0, 3000.0, 12000.0, 100000.0])
        if kind < 0.2:
            cmds.append(StraightTraverse(line, (nx, ny, nz), rng.random() < 0.1))
        elif kind < 0.35:
            r = rng.uniform(0.5, 2.0) * step
            cx, cy = x + r, y
            a = rng.uniform(0.1, 6.2)
            nx, ny = cx - r * math.cos(a), cy + r * math.sin(a)
            turns = 1 if rng.random() < 0.05 else 0
            cw = rng.random() < 0.5
            cmds.append(ArcFeed(line, (nx, ny, nz), (cx, cy, z), Plane.XY, cw, feed, turns))
        else:
            cmds.append(StraightFeed(line, (nx, ny, nz), feed, rng.random() < 0.03))
        x, y, z = nx, ny, nz
    return cmds


def bench_path(n: int) -> list:
    """The path of bench/bench_planner.py: 0.1 mm lines on a slowly bending curve with a
    tangent helix quarter every 50 blocks."""
    cmds = [SetPathMode(0, PathMode.CONTINUOUS, 0.01)]
    x, y, z = -100.0, -100.0, -10.0
    ang = 0.0
    for i in range(1, n + 1):
        if i % 50 == 0:
            cx, cy = x - 2.0 * math.sin(ang), y + 2.0 * math.cos(ang)
            ang += math.pi / 2
            x, y = cx + 2.0 * math.sin(ang), cy - 2.0 * math.cos(ang)
            z0 = z
            z -= 0.005 * math.pi
            cmds.append(ArcFeed(i, (x, y, z), (cx, cy, z0), Plane.XY, False, 6000.0))
            continue
        ang += 0.02 * math.sin(i * 0.01)
        x += 0.1 * math.cos(ang)
        y += 0.1 * math.sin(ang)
        z -= 0.0005
        cmds.append(StraightFeed(i, (x, y, z), 6000.0))
    return cmds


def piece_digest(segs: list) -> str:
    d = Digest()
    for g in segs:
        geom = g.geom
        d.add(type(geom).__name__, geom.start, geom.end, geom.length, geom.t0, geom.t1)
        d.add(geom.k0, geom.k1, g.s0, g.s1, g.line, g.block, g.block_last, g.feed)
        d.add(g.vphys, g.at, g.jt, g.limits_at(0.5 * g.vphys), g.vcap(1.3, 0.7))
        d.add(g.stop_end, g.jcap_end, g.jump_end, g.break_end, g.jdu, g.jdk)
        d.add(g.jcoast_end if g.jump_end and not g.stop_end else None)
    return d.hexdigest()


def part_rows(parts: list) -> list:
    """The parts of a partition as lists [s0, s1, vmax, vmax_hi, at, jt, end_cap, stop,
    coast_cap, coast_in, coast_out] (the planner's `Part.as_list`)."""
    return [p if isinstance(p, list) else p.as_list() for p in parts]


def span_rows(d: Digest, spans: list) -> None:
    for sp in spans:
        d.add(sp.s0, sp.s1, sp.dur, sp.v0, sp.v1, sp.stop, sp.vmax, sp.jerk_limit)
        d.add(sp.coast_in_t, sp.coast_out_t, sp.single_block_stop, sp.phases)


def digests() -> dict[str, str]:
    out = {}
    p = MachineParams(lookahead=25)

    def at(cycle_actions):
        return dict(cycle_actions)

    out["events"] = run_trace(
        Motion(p),
        spiral_program(),
        at(
            [
                (150, lambda m: m.set_feed_override(1.7)),
                (400, lambda m: m.feed_hold()),
                (700, lambda m: m.resume()),
                (800, lambda m: m.set_rapid_override(0.4)),
            ]
        ),
    )

    # the bench path: pieces and junctions, one plan per window, then the streaming run
    n = 1500
    pb = MachineParams(lookahead=n + 10)
    m = Motion(pb, start=(-100.0, -100.0, -10.0))
    for c in bench_path(n):
        m.push(c)
    segs = m.path.segs
    out["bench_path_pieces"] = piece_digest(segs)
    d = Digest()
    k = 0
    while k < len(segs):
        window = segs[k : k + 200]
        parts = partition(window, 0, window[0].s0, 1.0, 1.0, False, None, ipo=pb.ipo_cycle_s)
        d.add(part_rows(parts))
        spans, ok = solve(parts, 0.0, pb.ipo_cycle_s)
        d.add(ok)
        span_rows(d, spans)
        k += 100
    # a plan from a moving start with overrides, a stop point and a speed clamp
    parts = partition(segs, 3, segs[3].s0 + 0.01, 0.8, 0.5, False, segs[150].s1, 50.0, 0.002)
    d.add(part_rows(parts))
    spans, ok = solve(parts, 20.0, 0.002)
    d.add(ok)
    span_rows(d, spans)
    out["bench_path_plans"] = d.hexdigest()
    out["bench_path_trace"] = run_trace(
        Motion(MachineParams(lookahead=200), start=(-100.0, -100.0, -10.0)), bench_path(n)
    )

    # a circle of 0.01 mm segments at F10000
    radius, seg = 5.0, 0.01
    count = int(round(2 * math.pi * radius / seg))
    cmds: list = [SetPathMode(1, PathMode.CONTINUOUS, 0.01)]
    for k in range(1, count + 1):
        a = 2 * math.pi * k / count
        cmds.append(StraightFeed(2, (radius * math.cos(a), radius * math.sin(a), 0.0), 10000.0))
    out["circle"] = run_trace(Motion(MachineParams(lookahead=2000), start=(radius, 0.0, 0.0)), cmds)

    out["mixed"] = run_trace(Motion(MachineParams(lookahead=8)), mixed_program())
    m = Motion(MachineParams(lookahead=8))
    m.set_single_block(True)
    resume = {k: (lambda m: m.resume()) for k in range(0, 20_000, 97)}
    out["mixed_single_block"] = run_trace(m, mixed_program(), resume)

    out["hold_and_overrides"] = run_trace(
        Motion(MachineParams(lookahead=40)),
        spiral_program() + mixed_program()[1:],
        at(
            [
                (90, lambda m: m.set_feed_override(0.0)),
                (260, lambda m: m.set_feed_override(1.2)),
                (300, lambda m: m.set_single_block(True)),
                (420, lambda m: m.set_single_block(False)),
                (421, lambda m: m.resume()),
                (500, lambda m: m.feed_hold()),
                (530, lambda m: m.set_rapid_override(0.0)),
                (620, lambda m: m.resume()),
                (700, lambda m: m.set_rapid_override(1.0)),
                (1500, lambda m: m.feed_hold()),
                (1800, lambda m: m.resume()),
            ]
        ),
    )
    out["ipo_half_ms"] = run_trace(Motion(p, ipo_cycle_s=0.0005), spiral_program())
    out["ipo_eight_ms"] = run_trace(Motion(p, ipo_cycle_s=0.008), mixed_program())
    out["random"] = run_trace(
        Motion(MachineParams(lookahead=30)),
        random_program(11, 500),
        at([(300, lambda m: m.set_feed_override(0.6)), (900, lambda m: m.feed_hold())])
        | at([(1000, lambda m: m.resume())]),
        max_cycles=2_000_000,
    )
    return out


def planner_files() -> dict[str, str]:
    """Where each planner module was loaded from (an extension or a .py source)."""
    import cnc.interpolator.motion
    import cnc.planner.geometry
    import cnc.planner.limits
    import cnc.planner.path
    import cnc.planner.profile
    import cnc.planner.scurve

    mods = [
        cnc.planner.geometry,
        cnc.planner.limits,
        cnc.planner.path,
        cnc.planner.profile,
        cnc.planner.scurve,
        cnc.interpolator.motion,
    ]
    return {mod.__name__: str(mod.__file__) for mod in mods}


if __name__ == "__main__":
    json.dump({"digests": digests(), "files": planner_files()}, sys.stdout)
