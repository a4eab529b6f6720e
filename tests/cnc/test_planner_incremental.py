"""The planner's work-saving paths give exactly what the full computation gives.

* `solve(..., memo)` takes spans (and S-curve reach results) from the previous plan when
  their inputs are the same, and `partition_again` the parts of the previous cut where
  nothing they depend on changed: a streaming re-plan must equal a plan from scratch.
* `Path` computes the junction into the last piece only when it survives (the next G64
  blend usually replaces it): the junctions must equal those computed at every push.
"""

from __future__ import annotations

import math
import random

from cnc.canon import ArcFeed, PathMode, Plane, SetPathMode, StraightFeed, StraightTraverse
from cnc.interpolator import Motion
from cnc.params import MachineParams
from cnc.planner.profile import INF, PlanMemo, partition, partition_again, solve

IPO = 0.002


def cam_path(n: int, seed: int) -> list:
    """Short G1 segments along a bending curve, arcs, rapids, G61 stretches, tolerances."""
    rnd = random.Random(seed)
    cmds: list = [SetPathMode(1, PathMode.CONTINUOUS, 0.01)]
    x = y = z = 0.0
    ang = 0.0
    for i in range(2, n + 2):
        r = rnd.random()
        if r < 0.05:
            x, y = rnd.uniform(-20, 20), rnd.uniform(-20, 20)
            cmds.append(StraightTraverse(i, (x, y, z)))
        elif r < 0.1:
            cmds.append(
                SetPathMode(
                    i,
                    PathMode.EXACT_STOP if rnd.random() < 0.3 else PathMode.CONTINUOUS,
                    rnd.choice([0.0, 0.005, 0.05]),
                )
            )
        elif r < 0.15:
            cx, cy = x - 2.0 * math.sin(ang), y + 2.0 * math.cos(ang)
            ang += math.pi / 2
            x, y = cx + 2.0 * math.sin(ang), cy - 2.0 * math.cos(ang)
            z0 = z
            z -= 0.01
            cmds.append(ArcFeed(i, (x, y, z), (cx, cy, z0), Plane.XY, False, 3000.0))
        else:
            ang += rnd.uniform(-0.3, 0.3)
            step = rnd.choice([0.05, 0.1, 0.5, 2.0])
            x += step * math.cos(ang)
            y += step * math.sin(ang)
            cmds.append(StraightFeed(i, (x, y, z), rnd.choice([1200.0, 6000.0])))
    return cmds


def span_data(spans) -> list:
    return [
        (
            sp.s0,
            sp.s1,
            sp.phases,
            sp.dur,
            sp.v0,
            sp.v1,
            sp.stop,
            sp.vmax,
            sp.jerk_limit,
            sp.coast_in_t,
            sp.coast_out_t,
        )
        for sp in spans
    ]


def test_streaming_plans_with_memo_equal_plans_from_scratch():
    params = MachineParams(lookahead=400)
    m = Motion(params)
    memo = PlanMemo()
    hits = 0
    v0 = 0.0
    for count, cmd in enumerate(cam_path(300, 7)):
        m.push(cmd)
        segs = m.path.segs
        if count % 3 or not segs:
            continue
        # start a little further along each time (at a piece start or inside a piece)
        k = min(count // 6, len(segs) - 1)
        s0 = segs[k].s0 + (0.4 * (segs[k].s1 - segs[k].s0) if count % 2 else 0.0)
        again = partition_again(segs, k, s0, 1.0, 1.0, IPO, memo, m.path.changed_s)
        m.path.changed_s = INF
        parts = partition(segs, k, s0, 1.0, 1.0, False, None, ipo=IPO)
        assert again == parts
        before = set(map(id, memo.spans.values()))
        with_memo, ok1 = solve(again, v0, IPO, memo)
        scratch, ok2 = solve(parts, v0, IPO)
        assert ok1 == ok2
        assert span_data(with_memo) == span_data(scratch)
        hits += sum(id(sp) in before for sp in with_memo)
        v0 = with_memo[0].v1 if len(with_memo) > 1 else 0.0
    assert hits > 100  # the memo is actually used


def junction_fields(segs) -> list:
    """What the planner reads of each junction (nothing but the stop when it is one)."""
    return [
        (s.s0, s.s1, s.block, True)
        if s.stop_end
        else (s.s0, s.s1, s.block, False, s.jcap_end, s.break_end, s.jump_end, s.jdu, s.jdk)
        for s in segs
    ]


def test_deferred_last_junction_equals_computing_it_at_every_push():
    params = MachineParams(lookahead=1000)
    lazy = Motion(params)
    eager = Motion(params)
    for cmd in cam_path(400, 11):
        lazy.push(cmd)
        eager.push(cmd)
        _ = eager.path.segs  # looking settles the last junction at once, as before
    lazy.end_of_program()
    eager.end_of_program()
    assert junction_fields(lazy.path.segs) == junction_fields(eager.path.segs)


def test_motion_traces_are_unchanged_by_the_memo():
    """The same program through Motion, once with the memo emptied before every plan."""
    params = MachineParams(lookahead=60)
    cmds = cam_path(150, 3)

    def trace(forget: bool) -> list:
        m = Motion(params)
        out = []
        it = iter(cmds)
        pending = next(it, None)
        for _ in range(200_000):
            while pending is not None and m.push(pending):
                pending = next(it, None)
            if pending is None:
                m.end_of_program()
            if forget:
                m._memo = PlanMemo()
            s = m.step()
            out.append((s.pose, s.velocity, s.line))
            if pending is None and m.idle:
                break
        return out

    assert trace(False) == trace(True)
