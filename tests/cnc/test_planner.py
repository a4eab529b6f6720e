"""Table tests of the look-ahead planner through the Motion API."""

from __future__ import annotations

import math

import pytest

from cnc.canon import (
    ArcFeed,
    AuxFunction,
    Coolant,
    Dwell,
    PathMode,
    Plane,
    ProgramStop,
    SetPathMode,
    StopKind,
    StraightFeed,
    StraightTraverse,
    ToolChange,
)
from cnc.errors import NcError
from cnc.interpolator import Motion
from cnc.params import MachineParams
from tests.cnc.test_planner_helpers import (
    assert_within_limits,
    circle_allowed,
    max_deviation,
    programmed_pieces,
    run,
)

P = MachineParams()
ORIGIN = (0.0, 0.0, 0.0)


def corner(mode_cmd, g9=False):
    return [
        mode_cmd,
        StraightFeed(2, (-40.0, 0.0, 0.0), 6000.0, g9),
        StraightFeed(3, (-40.0, -40.0, 0.0), 6000.0),
    ]


def test_g61_stops_exactly_at_the_corner():
    samples, _ = run(P, corner(SetPathMode(1, PathMode.EXACT_STOP)))
    hits = [s for s in samples if s.pose == (-40.0, 0.0, 0.0)]
    assert hits and hits[0].velocity == 0.0
    assert_within_limits(P, samples, ORIGIN)
    assert max_deviation(samples, programmed_pieces(corner(None)[1:], ORIGIN)) < 1e-12


def test_g9_stops_one_block_only():
    cmds = corner(SetPathMode(1, PathMode.CONTINUOUS, 0.05), g9=True)
    samples, _ = run(P, cmds)
    assert any(s.pose == (-40.0, 0.0, 0.0) and s.velocity == 0.0 for s in samples)


@pytest.mark.parametrize("tol", [0.002, 0.05, 0.5])
def test_g64_blends_the_corner_within_p(tol):
    cmds = corner(SetPathMode(1, PathMode.CONTINUOUS, tol))
    samples, _ = run(P, cmds)
    dev = max_deviation(samples, programmed_pieces(cmds, ORIGIN))
    assert 0.2 * tol < dev <= tol + 1e-9  # it does cut the corner, but no more than P
    near = [s.velocity for s in samples if abs(s.pose[0] + 40.0) < 2 * tol and s.pose[1] > -1]
    assert min(near) > 0.0  # no stop at the corner
    assert_within_limits(P, samples, ORIGIN)
    assert samples[-1].pose == (-40.0, -40.0, 0.0)


def test_g64_without_p_uses_the_default_tolerance():
    cmds = corner(SetPathMode(1, PathMode.CONTINUOUS, 0.0))
    samples, _ = run(P, cmds)
    dev = max_deviation(samples, programmed_pieces(cmds, ORIGIN))
    assert 0.002 < dev <= P.default_path_tolerance + 1e-9


def test_bigger_tolerance_passes_the_corner_faster():
    speeds = []
    for tol in (0.001, 0.01, 0.1, 1.0):
        samples, _ = run(P, corner(SetPathMode(1, PathMode.CONTINUOUS, tol)))
        near = min(samples, key=lambda s: (s.pose[0] + 40.0) ** 2 + s.pose[1] ** 2)
        speeds.append(near.velocity)
    assert 0.0 < speeds[0] < speeds[1] < speeds[2] < speeds[3]


def test_sync_points_in_order_at_rest_and_wait_for_acknowledge():
    cmds = [
        StraightFeed(1, (-10.0, 0.0, 0.0), 3000.0),
        Dwell(2, 0.5),
        Coolant(3, False, True),
        StraightFeed(4, (-10.0, -10.0, 0.0), 3000.0),
        ToolChange(5, 2),
        AuxFunction(6, 8),
        ProgramStop(7, StopKind.PROGRAM_END),
    ]
    m = Motion(P)
    for c in cmds:
        assert m.push(c)
    m.end_of_program()
    seen = []
    for _ in range(20000):
        s = m.step()
        if s.sync is not None:
            seen.append((s.sync, s.pose, s.velocity, s.line))
            held = [m.step() for _ in range(5)]
            assert all(h.pose == s.pose and h.velocity == 0.0 and h.sync is None for h in held)
            m.acknowledge()
        if m.idle:
            break
    assert [x[0] for x in seen] == [cmds[i] for i in (1, 2, 4, 5, 6)]
    assert seen[0][1] == (-10.0, 0.0, 0.0) and seen[0][2] == 0.0 and seen[0][3] == 2
    assert seen[2][1] == (-10.0, -10.0, 0.0)


def test_sync_before_any_motion_comes_first():
    samples, syncs = run(P, [ToolChange(1, 5), StraightFeed(2, (-1.0, 0.0, 0.0), 1000.0)])
    assert syncs[0][0] == 0 and samples[0].pose == ORIGIN


def long_line(feed=6000.0):
    return [StraightFeed(1, (-400.0, 0.0, 0.0), feed)]


@pytest.mark.parametrize("ovr", [0.25, 0.5, 1.0, 1.5, 2.0])
def test_feed_override_scales_the_cruise_speed(ovr):
    m = Motion(P)
    m.set_feed_override(ovr)
    samples, _ = run(P, long_line(), motion=m)
    assert max(s.velocity for s in samples) == pytest.approx(100.0 * ovr, rel=1e-9)
    assert_within_limits(P, samples, ORIGIN)


def test_feed_override_never_exceeds_axis_velocity():
    m = Motion(P)
    m.set_feed_override(2.0)
    samples, _ = run(P, [StraightFeed(1, (-400.0, 0.0, 0.0), 15000.0)], motion=m)
    # F15000 x 200 % would be 500 mm/s; X allows 30000 mm/min = 500 mm/s
    assert max(s.velocity for s in samples) == pytest.approx(500.0, rel=1e-12)
    m = Motion(P)
    m.set_feed_override(2.0)
    samples, _ = run(P, [StraightFeed(1, (0.0, 0.0, -300.0), 15000.0)], motion=m)
    assert max(s.velocity for s in samples) <= 400.0 * (1 + 1e-12)  # Z: 24000 mm/min
    assert_within_limits(P, samples, ORIGIN)


def test_rapid_override_scales_rapids_only():
    m = Motion(P)
    m.set_rapid_override(0.25)
    samples, _ = run(P, [StraightTraverse(1, (-400.0, 0.0, 0.0))], motion=m)
    assert max(s.velocity for s in samples) == pytest.approx(500.0 * 0.25, rel=1e-9)


def drive(m, cycles):
    return [m.step() for _ in range(cycles)]


@pytest.mark.parametrize("change_at", [30, 80, 200, 400])
@pytest.mark.parametrize("new", [0.1, 0.6, 2.0])
def test_override_change_mid_move_stays_within_limits(change_at, new):
    cmds = [
        SetPathMode(0, PathMode.CONTINUOUS, 0.02),
        StraightFeed(1, (-60.0, 0.0, 0.0), 6000.0),
        ArcFeed(2, (-80.0, -20.0, 0.0), (-60.0, -20.0, 0.0), Plane.XY, False, 6000.0),
        StraightFeed(3, (-80.0, -60.0, -5.0), 6000.0),
    ]
    m = Motion(P)
    for c in cmds:
        m.push(c)
    m.end_of_program()
    samples = drive(m, change_at)
    m.set_feed_override(new)
    while not m.idle:
        samples.append(m.step())
    assert_within_limits(P, samples, ORIGIN)
    assert max_deviation(samples, programmed_pieces(cmds, ORIGIN)) <= 0.02 + 1e-9
    assert samples[-1].pose == (-80.0, -60.0, -5.0)


@pytest.mark.parametrize("hold_at", [10, 60, 150, 300])
def test_feed_hold_decelerates_on_the_path_and_resume_lands_exactly(hold_at):
    cmds = [
        SetPathMode(0, PathMode.CONTINUOUS, 0.01),
        StraightFeed(1, (-30.0, 0.0, 0.0), 9000.0),
        StraightFeed(2, (-30.0, -30.0, 0.0), 9000.0),
        ArcFeed(3, (-30.0, -50.0, 0.0), (-30.0, -40.0, 0.0), Plane.XY, True, 9000.0),
    ]
    m = Motion(P)
    for c in cmds:
        m.push(c)
    m.end_of_program()
    samples = drive(m, hold_at)
    m.feed_hold()
    for _ in range(3000):
        samples.append(m.step())
        if samples[-1].velocity == 0.0:
            break
    stopped = samples[-1].pose
    assert m.holding
    still = drive(m, 50)
    assert all(s.pose == stopped and s.velocity == 0.0 for s in still)
    samples += still
    m.resume()
    while not m.idle:
        samples.append(m.step())
    assert_within_limits(P, samples, ORIGIN)
    assert max_deviation(samples, programmed_pieces(cmds, ORIGIN)) <= 0.01 + 1e-9
    assert samples[-1].pose == (-30.0, -50.0, 0.0)
    # the held run reaches the same end as an uninterrupted run
    ref, _ = run(P, cmds)
    assert ref[-1].pose == samples[-1].pose


def test_feed_override_zero_stops_and_restarts():
    m = Motion(P)
    m.push(StraightFeed(1, (-100.0, 0.0, 0.0), 6000.0))
    m.end_of_program()
    s = drive(m, 100)
    m.set_feed_override(0.0)
    s += drive(m, 400)
    assert s[-1].velocity == 0.0 and s[-1].pose[0] > -100.0
    m.set_feed_override(1.0)
    while not m.idle:
        s.append(m.step())
    assert s[-1].pose == (-100.0, 0.0, 0.0)
    assert_within_limits(P, s, ORIGIN)


def test_single_block_stops_at_every_block_end():
    cmds = [
        SetPathMode(0, PathMode.CONTINUOUS, 0.05),
        StraightFeed(1, (-10.0, 0.0, 0.0), 3000.0),
        StraightFeed(2, (-10.0, -10.0, 0.0), 3000.0),
        StraightFeed(3, (0.0, -10.0, 0.0), 3000.0),
    ]
    m = Motion(P)
    m.set_single_block(True)
    for c in cmds:
        m.push(c)
    m.end_of_program()
    stops = []
    samples = []
    for _ in range(20000):
        s = m.step()
        samples.append(s)
        if m.holding:
            stops.append(s.pose)
            assert drive(m, 10)[-1].pose == s.pose  # waits for cycle start
            m.resume()
        if m.idle:
            break
    assert stops == [(-10.0, 0.0, 0.0), (-10.0, -10.0, 0.0), (0.0, -10.0, 0.0)]
    assert_within_limits(P, samples, ORIGIN)


def test_lookahead_full_refuses_push():
    params = MachineParams(lookahead=3)
    m = Motion(params)
    assert all(m.push(StraightFeed(i, (-float(i), 0.0, 0.0), 1000.0)) for i in range(1, 4))
    assert m.space() == 0
    assert not m.push(StraightFeed(9, (-9.0, 0.0, 0.0), 1000.0))
    while m.space() == 0:
        m.step()
    assert m.push(StraightFeed(9, (-9.0, 0.0, 0.0), 1000.0))


def test_lookahead_depth_200_is_used():
    m = Motion(MachineParams(lookahead=200))
    n = 0
    while m.push(StraightFeed(n, (-0.1 * (n + 1), 0.0, 0.0), 6000.0)):
        n += 1
    assert n == 200


def test_feed_move_without_f_is_an_error():
    m = Motion(P)
    with pytest.raises(NcError) as e:
        m.push(StraightFeed(7, (-1.0, 0.0, 0.0), 0.0))
    assert e.value.line == 7 and "feed" in e.value.message


def test_ipo_cycle_out_of_range_is_refused():
    with pytest.raises(NcError):
        Motion(MachineParams(ipo_cycle_s=0.02))


def polygon_circle(radius, seg, feed, turns):
    n = int(round(2 * math.pi * radius / seg))
    cmds = [SetPathMode(1, PathMode.CONTINUOUS, 0.01)]
    for t in range(turns):
        for k in range(1, n + 1):
            a = 2 * math.pi * k / n
            cmds.append(
                StraightFeed(2 + t, (radius * math.cos(a), radius * math.sin(a), 0.0), feed)
            )
    return cmds, n


@pytest.mark.parametrize("radius", [5.0, 8.0])
def test_small_segment_circle_runs_at_95_percent_of_what_curvature_allows(radius):
    params = MachineParams(lookahead=100_000)
    cmds, n = polygon_circle(radius, 0.01, 10000.0, 6)
    start = (radius, 0.0, 0.0)
    samples, _ = run(params, cmds, start)
    allowed = circle_allowed(params, radius, 10000.0)
    third = [s.velocity for s in samples if s.line == 4]  # the third turn
    assert min(third) >= 0.95 * allowed
    # several 0.01 mm segments are consumed per IPO cycle: no L/T cap
    assert max(third) * params.ipo_cycle_s > 10 * 0.01
    assert_within_limits(params, samples, start)


def test_single_block_switched_on_while_running_stops_at_a_reachable_block_end():
    cmds = [
        SetPathMode(0, PathMode.CONTINUOUS, 0.05),
        StraightFeed(1, (-30.0, 0.0, 0.0), 6000.0),
        StraightFeed(2, (-30.0, -30.0, 0.0), 6000.0),
        StraightFeed(3, (0.0, -30.0, 0.0), 6000.0),
        StraightFeed(4, (0.0, -60.0, 0.0), 6000.0),
    ]
    m = Motion(P)
    for c in cmds:
        m.push(c)
    m.end_of_program()
    samples = drive(m, 150)  # well into block 1, at speed
    m.set_single_block(True)
    stops = []
    for _ in range(40000):
        s = m.step()
        samples.append(s)
        if m.holding:
            stops.append(s)
            assert drive(m, 5)[-1].pose == s.pose
            m.resume()
        if m.idle:
            break
    assert len(stops) >= 2 and all(s.velocity == 0.0 for s in stops)
    # every stop is a block end: on a blended corner the end of its blend (within P)
    corners = [(-30.0, 0.0, 0.0), (-30.0, -30.0, 0.0), (0.0, -30.0, 0.0), (0.0, -60.0, 0.0)]
    for s in stops:
        assert min(math.dist(s.pose, c) for c in corners) < 0.2
    assert samples[-1].pose == (0.0, -60.0, 0.0)
    assert_within_limits(P, samples, ORIGIN)


@pytest.mark.parametrize(
    "cmd",
    [
        StraightFeed(5, (math.nan, 0.0, 0.0), 1000.0),
        StraightFeed(5, (-1.0, 0.0, 0.0), math.inf),
        StraightTraverse(5, (-1.0, math.inf, 0.0)),
        ArcFeed(5, (-2.0, 0.0, 0.0), (-1.0, math.nan, 0.0), Plane.XY, True, 1000.0),
        ArcFeed(5, (-2.0, 0.0, 0.0), (0.0, 0.0, 0.0), Plane.XY, True, 1000.0),  # radius 0
    ],
)
def test_bad_motion_commands_are_nc_errors_with_the_line(cmd):
    m = Motion(P)
    with pytest.raises(NcError) as e:
        m.push(cmd)
    assert e.value.line == 5


def test_a_piece_ending_at_minus_113_is_read_back() -> None:
    # -113.0 is mypyc's float error value: a tuple attribute starting with it was taken for
    # "never set" when read through the base class (compiled build only)
    from cnc.planner.geometry import Line, Piece, arc_from_canon

    def ends(p: Piece) -> tuple:
        return p.start, p.end

    line = Line((-113.0, -113.0, -113.0), (-113.0, 5.0, 0.0))
    assert ends(line) == ((-113.0, -113.0, -113.0), (-113.0, 5.0, 0.0))
    arc = arc_from_canon((-113.0, 0.0, 0.0), (-103.0, 10.0, 0.0), (-103.0, 0.0, 0.0), 2, True, 1)
    assert ends(arc)[0] == (-113.0, 0.0, 0.0) and ends(arc)[1][0] == pytest.approx(-103.0)
