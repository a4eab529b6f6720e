"""The machine's contour-error measure: point-to-segment distance (property tests) and its
use on a running machine (ideal axes: exact on lines, the chord error on an arc)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cnc.machine import Machine
from cnc.machine.contour import seg_dist
from tests.cnc.setups import machine_coordinates

coord = st.floats(-1000, 1000, allow_nan=False)
point = st.tuples(coord, coord, coord)


@given(point, point, point)
def test_segment_distance_is_at_most_the_distance_to_either_end(a, b, p):
    d = seg_dist([a, b], 1, p)
    assert d <= math.dist(p, a) + 1e-9 and d <= math.dist(p, b) + 1e-9
    assert d >= 0.0


@given(point, point, st.floats(0.0, 1.0))
def test_points_on_the_segment_are_at_distance_zero(a, b, u):
    p = tuple(ai + u * (bi - ai) for ai, bi in zip(a, b, strict=True))
    assert seg_dist([a, b], 1, p) <= 1e-6 * (1.0 + math.dist(a, b))


@given(point, point, point)
def test_the_first_point_is_a_point(a, b, p):
    assert seg_dist([a, b], 0, p) == math.dist(p, a)


def run(text: str) -> Machine:
    m = Machine(machine_coordinates("mill3"), "mill3", ideal=True)
    m.run_until(lambda x: x.axes.feedback().enabled, 2.0)
    m.step(2)
    m.command("mode", mode="REF")
    m.command("home")
    m.run_until(lambda x: all(x.controller.referenced.values()), 5.0)
    m.command("mode", mode="AUTO")
    m.command("select_program", number=m.load_program(text))
    m.command("cycle_start")
    m.run_until(lambda x: x.status.execution == "PROGRAM_COMPLETED" or bool(x.alarms), 60.0)
    m.close()
    return m


def test_contour_error_of_ideal_axes_is_the_chord_error_only():
    lines = run("%\nO1\nG90 G1 X-100 Y-50 F6000\nX-200 Y-50\nM30\n%\n")
    # lines: only the chord of the corner blend (G64 P0.01) at one cycle of lag
    assert lines.max_contour_error < 1e-3
    # an arc R10 at 100 mm/s: one 2 ms cycle of lag spans 0.2 mm of arc; the actual point
    # lies on the arc, the polyline of setpoints is a chord: sagitta r(1-cos(s/2r))
    arc = run("%\nO2\nG90 G1 X-100 Y-50 F6000\nG2 X-120 Y-50 I-10 J0\nM30\n%\n")
    assert 0.0 < arc.max_contour_error < 10 * (1 - math.cos(0.2 / 20)) + 1e-6


def test_the_compiled_contour_module_computes_what_its_source_computes():
    """cnc/machine/contour.py is compiled with mypyc (cnc/machine/mypyc.list): the source,
    loaded as plain Python, must give bit-identical distances."""
    import importlib.util
    import random

    import cnc.machine.contour as loaded

    if Path(loaded.__file__).suffix != ".so":
        pytest.skip("contour.py runs as plain Python in this build: nothing to compare")
    spec = importlib.util.spec_from_file_location(
        "contour_source", Path(loaded.__file__).with_name("contour.py")
    )
    assert spec is not None and spec.loader is not None
    source = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(source)
    rng = random.Random(7)
    for _ in range(2000):
        path = [tuple(rng.uniform(-100, 100) for _ in range(3)) for _ in range(rng.randint(1, 6))]
        p = tuple(rng.uniform(-100, 100) for _ in range(3))
        assert loaded.contour_error(path, p) == source.contour_error(path, p)
        j = rng.randrange(len(path))
        assert loaded.seg_dist(path, j, p) == source.seg_dist(path, j, p)
