"""The soak (bench/bench_soak.py) takes each fault's target and detection bound from the
/api/fault-types rows, so a kind added to the fault registry or the PLC's field faults is
injected at the right target and judged by its own bound, never defaulted to `plc`."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from server.cell import fault_types

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    path = ROOT / "bench" / "bench_soak.py"
    spec = importlib.util.spec_from_file_location("bench_soak", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_soak"] = module
    spec.loader.exec_module(module)
    return module


ROWS = [t for t in fault_types() if not t["description"].startswith("= ")]


@pytest.mark.parametrize("row", ROWS, ids=[t["type"] for t in ROWS])
def test_every_fault_type_gets_its_target_and_bound_from_the_fault_types_row(row):
    bench = _bench()
    plan = bench.fault_plan(row, bench.POLICY.get(row["type"]))
    kind, target = row["type"], plan["target"]
    if row["target"] == "plc":
        assert target == "plc"
    else:  # the row's target with a real axis
        prefix = row["target"].split(":")[0]
        assert target.startswith(prefix + ":") and target[-1] in "XYZ", (kind, target)
    if plan["undetectable"]:
        assert plan["bound"] is None
    else:
        assert plan["bound"] == row["bound_s"] and plan["bound"] > 0, kind
    assert plan["detect_from"] == row["detect_from"]
    # a parameter the row requires is given by the soak's policy
    required = {p["name"] for p in row["params"] if p.get("default") is None}
    assert required <= set(plan["params"]), (kind, required)


def test_a_new_kind_is_planned_from_its_row_alone():
    """The encoder_noise case: no policy entry, a drive target, its own bound."""
    bench = _bench()
    row = {
        "type": "new_kind",
        "target": "drive:<AXIS>",
        "params": [],
        "description": "x",
        "detection": "EMCY within 10 ms",
        "bound_s": 0.01,
        "detect_from": "injection",
    }
    plan = bench.fault_plan(row, bench.POLICY.get("new_kind"))
    assert plan["target"] == "drive:X" and plan["bound"] == 0.01 and not plan["undetectable"]


def test_the_clock_rate_turns_wall_time_into_machine_time():
    bench = _bench()
    assert bench.clock_rate((100.0, 50.0), (120.0, 65.0)) == pytest.approx(0.75)
    assert bench.clock_rate((100.0, 50.0), (110.0, 62.0)) == 1.0  # never ahead of the wall
    assert bench.clock_rate((100.0, None), (110.0, 60.0)) is None


# RSS (s, MB) every 5 s for an hour: the MTConnect buffer fills (+20 MB) for `fill_s`, then
# a leak of `leak` MB/h alone. The raw slope after a 10-minute warm-up counts the filling;
# the steady one, after the buffer was seen full, is the leak.
@pytest.mark.parametrize(
    ("fill_s", "leak", "steady_from", "steady"),
    [
        (1200, 0.0, 1200, 0.0),  # full at 20 min: flat after
        (1200, 3.0, 1200, 3.0),  # a leak is not hidden by the buffer
        (300, 2.0, 600, 2.0),  # full inside the warm-up: from the warm-up's end
        (3000, 0.0, 3000, None),  # full at 50 min: too few minutes left to judge
        (None, 0.0, None, None),  # never full: only the raw slope
    ],
)
def test_the_steady_rss_slope_starts_after_the_buffer_is_full(fill_s, leak, steady_from, steady):
    bench = _bench()
    end_fill = fill_s or 10_000

    def rss(t: float) -> float:
        return 300.0 + 20.0 * min(t, end_fill) / end_fill + leak * t / 3600

    samples = [(t, rss(t)) for t in range(0, 3600, 5)]
    start, slope = bench.steady_slope(samples, 600.0, fill_s)
    assert start == steady_from
    if steady is None:
        assert slope is None
    else:
        assert slope == pytest.approx(steady, abs=1e-6)
    raw = bench.slope_mb_per_h([(t, r) for t, r in samples if t >= 600])
    if fill_s is not None and fill_s > 600:
        assert raw > leak + 1.0, "the raw slope counts the buffer's filling"


def test_the_buffer_fill_from_the_agents_header():
    bench = _bench()
    assert bench.buffer_fill((0.0, 101, 1000, 1)) == 0.1
    assert bench.buffer_fill((0.0, 5001, 1000, 4001)) == 1.0
