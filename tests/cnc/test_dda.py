"""DDA reference interpolator against the seeds' worked examples, step for step."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cnc.dda import (
    chord_segments_per_quadrant,
    dda_circle,
    dda_circle_sum,
    dda_integrator,
    dda_line,
    feed_rate_registers,
    line_plan,
    software_iteration_rate,
)
from cnc.errors import NcError

# --- 001_feed_drives.md Table 7-1: one integrator, n = 3, p = 5, q0 = 0 ------------------
# (clock, p, q, dz, sum dz), row 0 is the loaded state.
TABLE_7_1 = [
    (0, 5, 0, 0, 0),
    (1, 5, 5, 0, 0),
    (2, 5, 2, 1, 1),
    (3, 5, 7, 0, 1),
    (4, 5, 4, 1, 2),
    (5, 5, 1, 1, 3),
    (6, 5, 6, 0, 3),
    (7, 5, 3, 1, 4),
    (8, 5, 0, 1, 5),
    (9, 5, 5, 0, 5),
    (10, 5, 2, 1, 6),
    (11, 5, 7, 0, 6),
    (12, 5, 4, 1, 7),
    (13, 5, 1, 1, 8),
    (14, 5, 6, 0, 8),
    (15, 5, 3, 1, 9),
    (16, 5, 0, 1, 10),
]


@pytest.mark.parametrize("row", TABLE_7_1, ids=lambda r: f"clock{r[0]}")
def test_table_7_1_integrator_row(row):
    run = dda_integrator(5, 16, n_bits=3)
    step = run.steps[row[0]]
    assert (step.clock, step.p[0], step.q[0], step.dz[0], step.total[0]) == row


def test_table_7_1_pulse_pattern_and_rate():
    run = dda_integrator(5, 16, n_bits=3)
    assert "".join(map(str, run.pulses[0])) == "0101101101011011"
    assert run.displacement == (10,)  # 5/8 of 16 clocks (eq. 7-12)
    assert len(run.steps) == 17


# --- Table 7-2: line A(0,0) -> B(15,9), BLU 3 -> a = 5, b = 3, n = 3 ---------------------
# (clock, q1, dz1, q2, dz2)
TABLE_7_2 = [
    (0, 0, 0, 0, 0),
    (1, 5, 0, 3, 0),
    (2, 2, 1, 6, 0),
    (3, 7, 0, 1, 1),
    (4, 4, 1, 4, 0),
    (5, 1, 1, 7, 0),
    (6, 6, 0, 2, 1),
    (7, 3, 1, 5, 0),
    (8, 0, 1, 0, 1),
]


@pytest.mark.parametrize("row", TABLE_7_2, ids=lambda r: f"clock{r[0]}")
def test_table_7_2_line_row(row):
    run = dda_line((15 // 3, 9 // 3), n_bits=3)
    step = run.steps[row[0]]
    assert (step.clock, step.q[0], step.dz[0], step.q[1], step.dz[1]) == row
    assert step.p == (5, 3)


def test_table_7_2_pulse_clocks_and_exact_end():
    run = dda_line((5, 3), n_bits=3)
    assert run.clocks == 8
    assert run.pulse_clocks(0) == (2, 4, 5, 7, 8)
    assert run.pulse_clocks(1) == (3, 6, 8)
    assert run.displacement == (5, 3)
    assert run.steps[-1].q == (0, 0)


def test_line_negative_increment_sets_direction():
    run = dda_line((-5, 3), n_bits=3)
    assert run.displacement == (-5, 3)
    assert set(run.pulses[0]) == {0, -1}
    assert run.steps[1].p == (5, 3)  # the register holds the magnitude


# --- 000_nc_book.md §4.2.1 Fig. 4-6: X10 Z80 -> X30 Z50 at 120 mm/min, BLU 1 um ---------


def test_fig_4_6_line_figures():
    plan = line_plan((10.0, 80.0), (30.0, 50.0), 120.0, blu_mm=0.001)
    assert plan.length_mm == pytest.approx(36.056, abs=5e-4)
    assert plan.time_s == pytest.approx(18.028, abs=5e-4)
    assert plan.min_steps == 30_000
    assert plan.steps == 100_000
    assert plan.step_time_s == pytest.approx(0.18028e-3, abs=1e-8)
    assert plan.clock_hz == pytest.approx(5547.0, abs=0.5)  # the book rounds to 5.556 kHz
    assert plan.increments_mm == pytest.approx((0.0002, -0.0003))
    assert plan.deltas_blu == (20_000, -30_000)


def test_fig_4_6_line_run_reaches_end_exactly_and_tracks_the_line():
    plan = line_plan((10.0, 80.0), (30.0, 50.0), 120.0)
    run = dda_line(plan.deltas_blu, capacity=plan.steps, record_steps=False)
    assert run.clocks == 100_000
    assert run.displacement == (20_000, -30_000)  # x = 30, z = 50 exactly
    assert run.steps == ()
    # x_n = x_A + n (x_E - x_A) / N: the pulse count never lags it by a whole BLU.
    x = z = 0
    for n in range(1, run.clocks + 1, 997):
        x, z = run.position(n)
        assert 0 <= n * 0.2 - x < 1.0
        assert 0 <= n * 0.3 + z < 1.0


def test_line_plan_binary_radix():
    plan = line_plan((0.0, 0.0), (15.0, 9.0), 60.0, blu_mm=3.0, radix=2)
    assert plan.deltas_blu == (5, 3)
    assert plan.steps == 8  # 2**3, the register of Table 7-2


# --- Example 7-2: feed-rate registers ---------------------------------------------------


def test_example_7_2_feed_rate_registers():
    regs = feed_rate_registers((2.0, 3.0), 60.0, 0.01, 1000.0, 10)
    assert regs.velocities_blu_s == pytest.approx((55.47, 83.21), abs=0.005)
    assert regs.p == (57, 85)


def test_feed_rate_register_overflow_is_refused():
    with pytest.raises(NcError, match="does not fit 4 bits"):
        feed_rate_registers((2.0, 3.0), 60.0, 0.01, 10.0, 4)


# --- Table 7-3: circle i = R = 15, j = 0, n = 4, hardware end-point ---------------------
# (clock, p2, q2, dz2, p1, q1, dz1) as printed (row 0 p2 corrected from the OCR "5").
TABLE_7_3 = [
    (0, 15, 0, 0, 0, 0, 0),
    (1, 15, 15, 0, 0, 0, 0),
    (2, 15, 14, 1, 1, 1, 0),
    (3, 15, 13, 1, 2, 3, 0),
    (4, 15, 12, 1, 3, 6, 0),
    (5, 15, 11, 1, 4, 10, 0),
    (6, 15, 10, 1, 5, 15, 0),
    (7, 15, 9, 1, 6, 5, 1),
    (8, 14, 7, 1, 7, 12, 0),
    (9, 14, 5, 1, 8, 4, 1),
    (10, 13, 2, 1, 9, 13, 0),
    (11, 13, 15, 0, 9, 6, 1),
    (12, 12, 11, 1, 10, 0, 1),
    (13, 11, 6, 1, 11, 11, 0),
    (14, 11, 1, 1, 12, 7, 1),
    (15, 10, 11, 0, 12, 3, 1),
    (16, 9, 4, 1, 13, 0, 1),
    (17, 8, 12, 0, 13, 13, 0),
    (18, 8, 4, 1, 14, 11, 1),
    (19, 7, 11, 0, 14, 9, 1),
    (20, 6, 1, 1, 15, 8, 1),
    (21, 5, 6, 0, 15, 7, 1),
    (22, 4, 10, 0, 15, 6, 1),
    (23, 3, 13, 0, 15, 5, 1),
    (24, 2, 15, 0, 15, 4, 1),
    (25, 1, 0, 1, 15, 3, 1),
]


@pytest.mark.parametrize("row", TABLE_7_3, ids=lambda r: f"clock{r[0]}")
def test_table_7_3_circle_row(row):
    run = dda_circle((15, 0), (0, 15), n_bits=4, endpoint="register")
    s = run.steps[row[0]]
    assert (s.clock, s.p[1], s.q[1], s.dz[1], s.p[0], s.q[0], s.dz[0]) == row


def test_table_7_3_hardware_end_point_error_of_one_blu():
    run = dda_circle((15, 0), (0, 15), n_bits=4, endpoint="register")
    assert run.clocks == 25
    assert run.steps[-1].total == (15, 16)
    assert run.displacement == (-15, 16)  # CCW from (15, 0): X runs negative, Y positive


def test_table_7_3_software_counters_end_exactly():
    run = dda_circle((15, 0), (0, 15), n_bits=4, endpoint="counters")
    assert run.clocks == 25
    assert run.displacement == (-15, 15)
    # Same trace as the hardware up to clock 20, where Y has its 15th pulse and is gated off.
    hw = dda_circle((15, 0), (0, 15), n_bits=4, endpoint="register")
    assert run.pulses[0] == hw.pulses[0]
    assert run.pulses[1][:20] == hw.pulses[1][:20]
    assert set(run.pulses[1][20:]) == {0}


def test_circle_is_ccw_for_g3_in_the_right_handed_plane():
    # TV-IPO-3: dx/dt = -(2 pi / T) y, dy/dt = +(2 pi / T) x; first motion from (R, 0) is +Y.
    run = dda_circle((15, 0), (0, 15), n_bits=4)
    first = next(k for k, v in enumerate(run.pulses[1]) if v)
    assert run.pulses[1][first] == 1
    cw = dda_circle((0, 15), (15, 0), n_bits=4, clockwise=True)
    assert cw.displacement == (15, -15)


def test_hardware_mode_refuses_arcs_across_quadrants():
    with pytest.raises(NcError, match="one quadrant only"):
        dda_circle((15, 0), (-15, 0), n_bits=5, endpoint="register")


@pytest.mark.parametrize(
    ("start", "end", "kwargs", "message"),
    [
        ((20, 0), (0, 20), {"n_bits": 4}, "does not fit"),
        ((15, 0), (0, 10), {"n_bits": 5}, "radii differ"),
        ((0, 0), (0, 0), {"n_bits": 5}, "centre"),
        ((15, 0), (0, 15), {}, "needs n_bits or capacity"),
        ((15, 0), (0, 15), {"n_bits": 4, "capacity": 16}, "not both"),
        ((15, 0), (0, 15), {"n_bits": 4, "endpoint": "magic"}, "unknown DDA end-point"),
        ((15, 0), (0, 15), {"n_bits": 40}, "more than 10000000 clocks"),
    ],
)
def test_circle_bad_input(start, end, kwargs, message):
    with pytest.raises(NcError, match=message):
        dda_circle(start, end, **kwargs)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: dda_line((9, 1), n_bits=3), "does not fit"),
        (lambda: dda_line(()), "at least one axis"),
        (lambda: dda_integrator(9, 4, n_bits=3), "does not fit"),
        (lambda: dda_integrator(1, 4, n_bits=0), "1..62 bits"),
        (lambda: dda_integrator(1, 4, capacity=1), ">= 2"),
        (lambda: line_plan((0, 0), (0, 0), 100), "zero-length"),
        (lambda: line_plan((0, 0), (1, 0), 0), "must be > 0"),
        (lambda: software_iteration_rate(0, 0.01), "must be > 0"),
        (lambda: chord_segments_per_quadrant(10, 20), "chord error < R"),
    ],
)
def test_bad_input_gets_nc_error(call, message):
    with pytest.raises(NcError, match=message):
        call()


def test_full_circle_in_software_mode_closes_exactly():
    run = dda_circle((15, 0), (15, 0), n_bits=4)
    assert run.displacement == (0, 0)
    assert sum(abs(v) for v in run.pulses[0]) == 60  # 4 quadrants x 15 BLU per axis
    assert sum(abs(v) for v in run.pulses[1]) == 60


@settings(max_examples=60, deadline=None)
@given(
    radius=st.integers(3, 200),
    a0=st.floats(0, 2 * math.pi),
    sweep=st.floats(0.05, 2 * math.pi - 0.05),
    clockwise=st.booleans(),
)
def test_software_circle_ends_exactly_and_stays_on_the_radius(radius, a0, sweep, clockwise):
    a1 = a0 - sweep if clockwise else a0 + sweep
    start = (round(radius * math.cos(a0)), round(radius * math.sin(a0)))
    end = (round(radius * math.cos(a1)), round(radius * math.sin(a1)))
    r_start = math.hypot(*start)
    if start == end or abs(math.hypot(*end) - r_start) > 1.0:
        return
    run = dda_circle(start, end, clockwise=clockwise, n_bits=9, record_steps=False)
    assert run.displacement == (end[0] - start[0], end[1] - start[1])
    # Every point stays within 2 BLU of the band between the start and end radii.
    low = min(r_start, math.hypot(*end)) - 2.0
    high = max(r_start, math.hypot(*end)) + 2.0
    x, y = start
    for dx, dy in zip(*run.pulses, strict=True):
        x += dx
        y += dy
        assert low <= math.hypot(x, y) <= high


@settings(max_examples=60, deadline=None)
@given(
    deltas=st.lists(st.integers(-500, 500), min_size=1, max_size=4),
    n_bits=st.integers(9, 12),
)
def test_line_totals_equal_increments_after_capacity_clocks(deltas, n_bits):
    run = dda_line(deltas, n_bits=n_bits)
    assert run.clocks == 1 << n_bits
    assert run.displacement == tuple(deltas)
    assert run.steps[-1].q == (0,) * len(deltas)


def test_software_line_capacity_is_path_length():
    run = dda_line((3, 4))
    assert run.capacity == 5
    assert run.displacement == (3, 4)


# --- 000_nc_book.md §4.2.2 summation form (TV-IPO-2) ------------------------------------


@pytest.mark.parametrize(
    ("n", "explicit_radius"), [(100, 12.177), (1000, 10.199), (10_000, 10.020)]
)
def test_tv_ipo_2_explicit_sum_diverges_and_sequential_does_not(n, explicit_radius):
    explicit = dda_circle_sum((10.0, 0.0), n, n, sequential=False)[-1]
    assert math.hypot(*explicit) == pytest.approx(explicit_radius, abs=5e-4)
    sequential = dda_circle_sum((10.0, 0.0), n, n, sequential=True)[-1]
    assert abs(math.hypot(*sequential) - 10.0) < (5e-4 if n == 100 else 1e-6)
    assert math.hypot(sequential[0] - 10.0, sequential[1]) < 0.011 * 100 / n  # closes at 360


def test_tv_ipo_3_summation_runs_ccw():
    pts = dda_circle_sum((10.0, 0.0), 360, 1)
    assert pts[1][1] > 0


# --- Example 7-4 and 7.4 chord counts ---------------------------------------------------


def test_example_7_4_software_iteration_rate():
    f, period = software_iteration_rate(3600.0, 0.01)
    assert f == pytest.approx(6000.0)
    assert period == pytest.approx(166.7e-6, abs=0.05e-6)


@pytest.mark.parametrize(("r", "eh", "n"), [(100, 0.01, 56), (10, 0.01, 18), (50, 0.001, 125)])
def test_chord_segments_per_quadrant(r, eh, n):
    assert chord_segments_per_quadrant(r, eh) == n


def test_docs_tables_are_rendered_by_the_code():
    from pathlib import Path

    from cnc.dda import step_table_markdown

    doc = (Path(__file__).resolve().parents[2] / "docs" / "dda.md").read_text(encoding="utf-8")
    assert step_table_markdown(dda_line((5, 3), n_bits=3)) in doc
    hw = dda_circle((15, 0), (0, 15), n_bits=4, endpoint="register")
    assert step_table_markdown(hw) in doc
