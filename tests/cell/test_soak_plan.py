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
