"""Ladder scan time: the generated one-function scan vs a plain tree-walking interpreter.

Generated mixed programs of 100, 1000 and 5000 rungs (10 % TON/TOF, 10 % one-shots, 10 %
latch/unlatch, 10 % compare + MOV/ADD, 60 % series-parallel contacts) are solved by
    compiled     plc.ladder's generated function (what the runtime runs)
    interpreter  a tree walker over the same parsed rungs, written here the way the Python
                 anchors (pyrung, pyladdersim) evaluate rungs: a node at a time, dispatch on
                 the instruction, operand look-ups per evaluation
Both see the same input pattern and must end with identical images (checked). Also
measured: a full `Runtime.scan` (queued writes, inputs, solve, Snapshot) and compile time.
Prints one JSON object. Target: <= 100 us per scan for 1000 rungs (pyrung: 8.9 ms).
"""

from __future__ import annotations

import json
import os
import platform
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from plc.image import ProcessImage  # noqa: E402
from plc.ladder import compile_text, parse_program  # noqa: E402
from plc.ladder.ast import Branch  # noqa: E402
from plc.ladder.instructions import MEMBER_ALIASES  # noqa: E402
from plc.ladder.symbols import parse_address  # noqa: E402
from plc.runtime import Runtime  # noqa: E402

TARGET_US_1000 = 100.0
PYRUNG_MS_1000 = 8.9  # anchor measurement (softplc_modbus.md), not re-run here


def generate(n: int, seed: int = 1) -> str:
    """A mixed program of n rungs over %IX0..%IX31, markers, outputs and timers."""
    rnd = random.Random(seed)
    timers = max(1, n // 10)
    lines = [f"PROGRAM mixed{n}"]
    lines += [f"TAG T{i} : TIMER" for i in range(timers)]
    lines += ["TAG Cnt : COUNTER"]

    def bit_in() -> str:
        r = rnd.random()
        if r < 0.5:
            return f"%IX{rnd.randrange(4)}.{rnd.randrange(8)}"
        if r < 0.85:
            return f"%MX{rnd.randrange(64)}.{rnd.randrange(8)}"
        return f"T{rnd.randrange(timers)}.DN"

    def contacts(k: int) -> str:
        return " ".join(f"{rnd.choice(('XIC', 'XIC', 'XIO'))} {bit_in()}" for _ in range(k))

    for r in range(n):
        kind = r % 10
        out = f"%MX{64 + r // 8 % 36}.{r % 8}" if r % 3 else f"%QX{r // 8 % 64}.{r % 8}"
        if kind == 0:
            timer = f"T{(r // 10) % timers}"
            op = "TON" if r % 20 == 0 else "TOF"
            lines.append(f"{contacts(2)} {op} {timer} {rnd.choice((50, 100, 250))}")
        elif kind == 1:
            lines.append(f"{contacts(1)} ONS %MX{100 + r // 8 % 28}.{r % 8} OTE {out}")
        elif kind == 2:
            lines.append(f"{contacts(2)} {'OTL' if r % 4 == 2 else 'OTU'} {out}")
        elif kind == 3:
            w = rnd.randrange(32)
            lines.append(
                f"GRT %IW{w} {rnd.randrange(100)} {contacts(1)} "
                f"BST MOV %IW{w} %MW{r % 512} NXB ADD %MW{r % 512} 1 %MW{512 + r % 256} BND"
            )
        elif kind in (4, 5, 6):
            lines.append(f"BST {contacts(1)} NXB {contacts(1)} BND {contacts(2)} OTE {out}")
        else:
            lines.append(f"{contacts(3)} OTE {out}")
    lines.append("XIC %IX0.0 CTU Cnt 1000")
    return "\n".join(lines) + "\n"


class TreeInterpreter:
    """Walks the parsed rungs every scan (no code generation)."""

    def __init__(self, text: str, image: ProcessImage) -> None:
        self.program, sink = parse_program(text, "bench.ld")
        assert not sink.has_errors
        self.img = image
        self.timers: dict[str, dict] = {}
        self.counters: dict[str, dict] = {}
        for t in self.program.tags:
            if t.type == "TIMER":
                self.timers[t.name.upper()] = {
                    "EN": False,
                    "TT": False,
                    "DN": False,
                    "ACC": 0,
                    "PRE": 0,
                }
            elif t.type == "COUNTER":
                self.counters[t.name.upper()] = {
                    "CU": False,
                    "CD": False,
                    "DN": False,
                    "OV": False,
                    "UN": False,
                    "ACC": 0,
                    "PRE": 0,
                }
        self.dt = 0
        self._locs: dict[str, tuple] = {}

    def _loc(self, text: str):
        """Operand -> (container, key), looked up once per operand text."""
        hit = self._locs.get(text)
        if hit is None:
            hit = self._locs[text] = self._resolve(text)
        return hit

    def _resolve(self, text: str):
        if text.startswith("%"):
            area, index = parse_address(text)
            return self.img.area(area), index
        base, _, member = text.partition(".")
        m = MEMBER_ALIASES.get(member.upper(), member.upper())
        store = self.timers.get(base.upper()) or self.counters.get(base.upper())
        return store, m

    def get(self, op):
        if op.value is not None:
            return op.value
        area, index = self._loc(op.text)
        return area[index]

    def set(self, op, value) -> None:
        area, index = self._loc(op.text)
        area[index] = value

    def scan(self, dt: int) -> None:
        self.dt = dt
        for rung in self.program.rungs:
            self.run(rung.elements, True)

    def run(self, elements, power: bool) -> bool:
        dispatch = self.dispatch
        for el in elements:
            if isinstance(el, Branch):
                power = any([self.run(leg, power) for leg in el.legs])
            else:
                power = dispatch[el.mnemonic](el.operands, power)
        return power

    @property
    def dispatch(self) -> dict:
        d = self.__dict__.get("_dispatch")
        if d is None:
            d = self.__dict__["_dispatch"] = {
                name[2:]: getattr(self, name) for name in dir(self) if name.startswith("i_")
            }
        return d

    def i_XIC(self, ops, p):
        return p and bool(self.get(ops[0]))

    def i_XIO(self, ops, p):
        return p and not self.get(ops[0])

    def i_OTE(self, ops, p):
        self.set(ops[0], p)
        return p

    def i_OTL(self, ops, p):
        if p:
            self.set(ops[0], True)
        return p

    def i_OTU(self, ops, p):
        if p:
            self.set(ops[0], False)
        return p

    def i_ONS(self, ops, p):
        out = p and not self.get(ops[0])
        self.set(ops[0], p)
        return out

    def i_GRT(self, ops, p):
        return p and self.get(ops[0]) > self.get(ops[1])

    def i_MOV(self, ops, p):
        if p:
            self.set(ops[1], self.get(ops[0]))
        return p

    def i_ADD(self, ops, p):
        if p:
            r = self.get(ops[0]) + self.get(ops[1])
            self.set(ops[2], ((r + 32768) & 65535) - 32768)
        return p

    def i_TON(self, ops, p):
        t = self.timers[ops[0].text.upper()]
        t["PRE"] = self.get(ops[1])
        if p:
            if t["EN"] and t["ACC"] < t["PRE"]:
                t["ACC"] = min(t["ACC"] + self.dt, t["PRE"])
            t["EN"] = True
            t["DN"] = t["ACC"] >= t["PRE"]
            t["TT"] = not t["DN"]
        else:
            t["EN"] = t["TT"] = t["DN"] = False
            t["ACC"] = 0
        return p

    def i_TOF(self, ops, p):
        t = self.timers[ops[0].text.upper()]
        t["PRE"] = self.get(ops[1])
        if p:
            t["EN"] = t["DN"] = True
            t["TT"] = False
            t["ACC"] = 0
        else:
            if t["EN"]:
                t["EN"] = False
                t["ACC"] = 0
                t["TT"] = t["DN"]
            elif t["TT"]:
                t["ACC"] = min(t["ACC"] + self.dt, t["PRE"])
            if t["TT"] and t["ACC"] >= t["PRE"]:
                t["TT"] = t["DN"] = False
        return p

    def i_CTU(self, ops, p):
        c = self.counters[ops[0].text.upper()]
        c["PRE"] = self.get(ops[1])
        if p:
            if not c["CU"]:
                c["ACC"] = c["ACC"] + 1 if c["ACC"] < 32767 else -32768
            c["CU"] = True
        else:
            c["CU"] = False
        c["DN"] = c["ACC"] >= c["PRE"]
        return p


def _count(elements) -> int:
    return sum(
        sum(_count(leg) for leg in el.legs) if isinstance(el, Branch) else 1 for el in elements
    )


def _pattern(k: int, ix: list, iw: list) -> None:
    """Deterministic input changes between scans, the same for every engine."""
    base = (k * 7) % 32
    for j in range(4):
        ix[(base + j * 5) % 32] = (k >> j) & 1 == 1
    iw[k % 32] = (k * 37) % 200


def _time_loop(step, batch: int, batches: int) -> tuple[float, float]:
    """Per-scan time in us over `batches` short batches: (best batch, median batch).

    Short batches and the minimum follow timeit's advice for a shared machine: the best
    batch is the one least disturbed by other processes; the median shows the disturbance.
    """
    times = []
    k = 0
    for _ in range(batches):
        t0 = time.perf_counter_ns()
        for _ in range(batch):
            step(k)
            k += 1
        times.append((time.perf_counter_ns() - t0) / batch / 1000.0)
    times.sort()
    return times[0], times[len(times) // 2]


def measure(n: int, budget_scans: int) -> dict:
    text = generate(n)
    t0 = time.perf_counter()
    compiled = compile_text(text, f"mixed{n}.ld")
    compile_ms = (time.perf_counter() - t0) * 1000.0
    img_c = ProcessImage(compiled.size)
    v = list(compiled.v_init)
    fn = compiled.scan_fn
    ix, qx, mx, iw, qw, mw = img_c.ix, img_c.qx, img_c.mx, img_c.iw, img_c.qw, img_c.mw

    def step_compiled(k: int) -> None:
        _pattern(k, ix, iw)
        fn(ix, qx, mx, iw, qw, mw, v, 10)

    img_i = ProcessImage(compiled.size)
    interp = TreeInterpreter(text, img_i)
    instructions = sum(_count(r.elements) for r in interp.program.rungs)

    def step_interp(k: int) -> None:
        _pattern(k, img_i.ix, img_i.iw)
        interp.scan(10)

    # differential check: same inputs, same scans -> same image
    for k in range(200):
        step_compiled(k)
        step_interp(k)
    assert img_c.snapshot(0) == img_i.snapshot(0), f"engines disagree on {n} rungs"

    batch = max(2, 10_000 // n)
    compiled_us, compiled_med = _time_loop(step_compiled, batch, budget_scans // batch)
    interp_us, interp_med = _time_loop(step_interp, max(1, batch // 4), 40)
    return {
        "rungs": n,
        "instructions": instructions,
        "compiled_us_per_scan": round(compiled_us, 2),
        "compiled_us_median_batch": round(compiled_med, 2),
        "interpreter_us_per_scan": round(interp_us, 2),
        "interpreter_us_median_batch": round(interp_med, 2),
        "speedup_vs_interpreter": round(interp_us / compiled_us, 1),
        "compiled_ns_per_rung": round(compiled_us * 1000.0 / n, 1),
        "compile_ms": round(compile_ms, 1),
    }


def full_scan_us(n: int, scans: int) -> tuple[float, float]:
    rt = Runtime(compile_text(generate(n), f"mixed{n}.ld"))
    ix, iw = rt.image.ix, rt.image.iw

    def step(k: int) -> None:
        _pattern(k, ix, iw)
        rt.scan(k * 10)

    best, median = _time_loop(step, 10, scans // 10)
    return round(best, 2), round(median, 2)


def online_change(n: int) -> dict:
    """Compile a changed program and swap it in between two scans of a running one."""
    rt = Runtime(compile_text(generate(n, seed=1), "v1.ld"))
    for k in range(20):
        rt.scan(k * 10)
    t0 = time.perf_counter()
    new = compile_text(generate(n, seed=2), "v2.ld")
    compile_ms = (time.perf_counter() - t0) * 1000.0
    before = rt.snapshot.scan
    t1 = time.perf_counter()
    rt.load_program(new)
    rt.scan(200)
    swap_scan_ms = (time.perf_counter() - t1) * 1000.0
    assert rt.program is new and rt.snapshot.scan == before + 1
    return {
        "rungs": n,
        "compile_ms": round(compile_ms, 1),
        "swap_scan_ms": round(swap_scan_ms, 3),
        "missed_scans": 0,
    }


def main() -> None:
    sizes = [100, 1000, 5000]
    results = [measure(n, budget_scans=3000) for n in sizes]
    r1000 = next(r for r in results if r["rungs"] == 1000)
    full_best, full_median = full_scan_us(1000, 1000)
    t0 = time.perf_counter()
    compile_text(generate(10_000), "mixed10000.ld")
    compile_10k_ms = (time.perf_counter() - t0) * 1000.0
    out = {
        "benchmark": "ladder scan: generated function vs tree-walking interpreter",
        "python": platform.python_version(),
        "programs": results,
        "runtime_scan_us_1000_rungs": full_best,
        "runtime_scan_us_1000_rungs_median_batch": full_median,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
        "compile_ms_10000_rungs": round(compile_10k_ms, 1),
        "online_change_1000_rungs": online_change(1000),
        "target_us_1000_rungs": TARGET_US_1000,
        "meets_target": r1000["compiled_us_per_scan"] <= TARGET_US_1000,
        "peer": "tree-walking interpreter of the same rungs (in this file)",
        "peer_us_1000_rungs": r1000["interpreter_us_per_scan"],
        "ratio_peer_over_compiled_1000": r1000["speedup_vs_interpreter"],
        "pyrung_anchor_ms_1000_rungs": PYRUNG_MS_1000,
        "note": "runtime_scan includes queued writes, input latch, Snapshot publish of a "
        "1024-entry image per area; compiled/interpreter are the solve alone",
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
