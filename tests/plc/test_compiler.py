"""The compiler: one generated function, readable, cached by hash, failures traced back to
the source rung, and identical results to a plain tree-walking interpreter (differential)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plc.image import ProcessImage
from plc.ladder import compile_text, load_file
from plc.ladder.codegen import FUNC_NAME
from plc.runtime import Runtime

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_scan", ROOT / "bench" / "bench_scan.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_scan"] = module
    spec.loader.exec_module(module)
    return module


def test_one_function_with_rung_comments():
    program = load_file(str(ROOT / "tests/plc/programs/spindle.ld"))
    src = program.python_source
    assert src.count("\ndef ") == 0 and src.startswith(
        f"def {FUNC_NAME}(ix, qx, mx, iw, qw, mw, v, dt):"
    )
    for rung in program.rungs:
        assert f"# rung {rung.number} (line {rung.line}):" in src
    assert callable(program.scan_fn) and program.scan_fn.__name__ == FUNC_NAME
    compile(src, "again", "exec")  # the stored source is the compiled source


def test_cache_by_hash():
    text = "XIC %IX0.0 OTE %QX0.0\n"
    a = compile_text(text, "c.ld")
    assert compile_text(text, "c.ld") is a
    b = compile_text(text + "XIC %IX0.1 OTE %QX0.1\n", "c.ld")
    assert b is not a and b.hash != a.hash
    other = compile_text(text, "other.ld")  # diagnostics name the file: compiled apart
    assert other is not a and other.file == "other.ld"


def test_constant_presets_live_in_the_initial_values():
    program = compile_text("TAG T : TIMER\nXIC %IX0.0 TON T 1234\n", "p.ld")
    pre = program.tag("T").members["PRE"]
    assert program.v_init[pre] == 1234 and f"v[{pre}] = 1234" not in program.python_source
    shared = compile_text("TAG T : TIMER\nXIC %IX0.0 TON T 5\nXIC %IX0.1 TON T 7\n", "p.ld")
    assert f"v[{pre}] = 5" in shared.python_source  # two presets: set by each instruction


def test_online_change_takes_the_new_constant_preset():
    rt = Runtime(compile_text("TAG T : TIMER\nXIC %IX0.0 TON T 100\n", "p.ld"))
    rt.image.ix[0] = True
    rt.scan(0)
    rt.scan(50)
    rt.load_program(compile_text("TAG T : TIMER\nXIC %IX0.0 TON T 60\n", "p.ld"))
    rt.scan(60)
    assert rt.read("T.PRE") == 60 and rt.read("T.ACC") == 60 and rt.read("T.DN") is True


def test_failure_in_generated_code_points_to_the_source_rung():
    program = compile_text("TAG N : INT\nXIC %IX0.0 OTE %QX0.0\n\nXIC %IX0.1 ADD N 1 N\n", "f.ld")
    img = ProcessImage(program.size)
    v = list(program.v_init)
    v[program.tag("N").index] = None  # corrupt the slot: ADD raises TypeError
    img.ix[1] = True
    with pytest.raises(TypeError) as info:
        program.scan_fn(img.ix, img.qx, img.mx, img.iw, img.qw, img.mw, v, 0)
    rung = program.locate(info.value)
    assert rung is not None and (rung.number, rung.line) == (1, 4)
    assert program.describe_rung(rung) == "f.ld:4: rung 1"


@pytest.mark.parametrize("rungs, seed", [(50, 1), (300, 2), (300, 3)])
def test_differential_against_the_tree_interpreter(rungs, seed):
    bench = _bench()
    text = bench.generate(rungs, seed)
    program = compile_text(text, "diff.ld")
    a, b = ProcessImage(program.size), ProcessImage(program.size)
    v = list(program.v_init)
    interp = bench.TreeInterpreter(text, b)
    for k in range(300):
        bench._pattern(k, a.ix, a.iw)
        bench._pattern(k, b.ix, b.iw)
        program.scan_fn(a.ix, a.qx, a.mx, a.iw, a.qw, a.mw, v, 10)
        interp.scan(10)
        assert a.snapshot(k) == b.snapshot(k), f"scan {k}"
    for name, t in interp.timers.items():
        slots = program.tag(name).members
        assert {m: v[i] for m, i in slots.items()} == t


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=10**6))
def test_differential_property(seed):
    bench = _bench()
    text = bench.generate(40, seed)
    program = compile_text(text, "prop.ld")
    a, b = ProcessImage(program.size), ProcessImage(program.size)
    v = list(program.v_init)
    interp = bench.TreeInterpreter(text, b)
    for k in range(60):
        for img in (a, b):
            bench._pattern(k + seed, img.ix, img.iw)
        program.scan_fn(a.ix, a.qx, a.mx, a.iw, a.qw, a.mw, v, 10)
        interp.scan(10)
    assert a.snapshot(0) == b.snapshot(0)
