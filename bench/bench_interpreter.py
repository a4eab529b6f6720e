"""Interpreter throughput against pygcode and gcodeparser, and time to first move.

Generates a 200k-block program of G1/G2/G3 moves in a temporary directory and measures, in
the same run: our lexer + interpreter producing every canonical command (blocks/s);
pygcode's `Line` parsing plus `Machine.process_block` (its equivalent of modal processing);
gcodeparser's `parse_gcode_lines` (tokens only, no semantics). Then writes a ~100 MB
program and measures the time until the interpreter hands out its first motion command.
Prints one JSON object.
"""

from __future__ import annotations

import gc
import itertools
import json
import os
import sys
import tempfile
import time
import tracemalloc

TARGET_BLOCKS_PER_S = 100_000
PYGCODE_REFERENCE = 16_600  # pygcode Machine blocks/s on the reference machine (anchor study)
BLOCKS = 200_000
PEER_BLOCKS = 20_000  # pygcode is slow: measure it on the first 20k blocks of the same file


def write_program(path: str, blocks: int) -> None:
    with open(path, "w") as fh:
        fh.write("%\nO0001 (bench)\nG21 G90 G17 G54\nG0 X-25 Y0 Z1\nG1 Z-1 F1200\n")
        n = 0
        i = 0
        while n < blocks:
            x0 = (i % 100) * 0.5 - 25.0
            fh.write(
                f"G1 X{x0:.3f} Y0\n"
                f"G2 X{x0 + 1.0:.3f} Y0 I0.5 J0\n"
                f"G3 X{x0 + 2.0:.3f} Y0 R0.5\n"
                f"G1 X{x0 + 2.0:.3f} Y1.25\n"
            )
            n += 4
            i += 1
        fh.write("M30\n%\n")


def bench_ours(path: str) -> dict:
    from cnc.interp import Interpreter
    from cnc.params import AxisParams, MachineParams

    axes = tuple(AxisParams(a, -1000.0, 1000.0, 30000.0, 3000.0, 5e4) for a in "XYZ")
    params = MachineParams(axes=axes)
    best = cpu_best = None
    for _ in range(2):
        gc.collect()
        with open(path) as fh:
            interp = Interpreter(params)
            t0, c0 = time.perf_counter(), time.process_time()
            ncmd = 0
            for _c in interp.run(fh):
                ncmd += 1
            dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        best = dt if best is None else min(best, dt)
        cpu_best = cpu if cpu_best is None else min(cpu_best, cpu)
    return {
        "blocks_per_s": round(BLOCKS / best),
        "cpu_blocks_per_s": round(BLOCKS / cpu_best),
        "seconds": round(best, 4),
        "commands": ncmd,
    }


def bench_pygcode(path: str) -> dict:
    try:
        from pygcode import Line, Machine
    except Exception as err:  # noqa: BLE001 - report any failure of the peer
        return {"error": f"{type(err).__name__}: {err}"}
    try:
        with open(path) as fh:
            lines = [ln for ln in fh if ln[0] == "G"][:PEER_BLOCKS]
        m = Machine()
        t0, c0 = time.perf_counter(), time.process_time()
        for ln in lines:
            m.process_block(Line(ln).block)
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        return {
            "blocks_per_s": round(len(lines) / dt),
            "cpu_blocks_per_s": round(len(lines) / cpu),
            "blocks_measured": len(lines),
        }
    except Exception as err:  # noqa: BLE001
        return {"error": f"{type(err).__name__}: {err}"}


def bench_gcodeparser(path: str) -> dict:
    try:
        from gcodeparser import parse_gcode_lines
    except Exception as err:  # noqa: BLE001
        return {"error": f"{type(err).__name__}: {err}"}
    try:
        with open(path) as fh:
            text = fh.read()
        t0, c0 = time.perf_counter(), time.process_time()
        n = sum(1 for _ in parse_gcode_lines(text))
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        return {
            "lines_per_s": round(n / dt),
            "cpu_lines_per_s": round(n / cpu),
            "lines": n,
            "note": "tokens only, no semantics",
        }
    except Exception as err:  # noqa: BLE001
        return {"error": f"{type(err).__name__}: {err}"}


def first_move_big_file(tmp: str) -> dict:
    from cnc.canon import MOTION_TYPES
    from cnc.interp import Interpreter
    from cnc.params import AxisParams, MachineParams

    path = os.path.join(tmp, "big.nc")
    chunk = "".join(f"G1 X{(i % 200) * 0.1:.3f} Y{(i % 50) * 0.2:.3f} F1500\n" for i in range(4000))
    with open(path, "w") as fh:
        fh.write("%\nO0002\nG21 G90\n")
        while fh.tell() < 100 * 1024 * 1024:
            fh.write(chunk)
        fh.write("M30\n%\n")
    size = os.path.getsize(path)
    axes = tuple(AxisParams(a, -1000.0, 1000.0, 30000.0, 3000.0, 5e4) for a in "XYZ")
    params = MachineParams(axes=axes)
    t0 = time.perf_counter()
    with open(path) as fh:
        for cmd in Interpreter(params).run(fh):
            if isinstance(cmd, MOTION_TYPES):
                break
    first = time.perf_counter() - t0
    # memory stays flat while streaming: peak Python allocation over the first 50k blocks
    tracemalloc.start()
    with open(path) as fh:
        for _ in itertools.islice(Interpreter(params).run(fh), 50_000):
            pass
    _cur, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    os.remove(path)
    return {
        "file_mb": round(size / 2**20, 1),
        "first_move_ms": round(first * 1000, 3),
        "target_first_move_ms": 5.0,
        "peak_alloc_kb_50k_blocks": round(peak / 1024, 1),
    }


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.nc")
        write_program(path, BLOCKS)
        ours = bench_ours(path)
        pyg = bench_pygcode(path)
        gcp = bench_gcodeparser(path)
        big = first_move_big_file(tmp)
    cpu_ours = ours["cpu_blocks_per_s"]
    result = {
        "blocks": BLOCKS,
        "fmscell_blocks_per_s": ours["blocks_per_s"],
        "fmscell_cpu_blocks_per_s": cpu_ours,
        "fmscell_canon_commands": ours["commands"],
        "target_blocks_per_s": TARGET_BLOCKS_PER_S,
        "meets_target_wall": ours["blocks_per_s"] >= TARGET_BLOCKS_PER_S,
        "meets_target_cpu": cpu_ours >= TARGET_BLOCKS_PER_S,
        "pygcode": pyg,
        "gcodeparser": gcp,
        "ratio_vs_pygcode": round(cpu_ours / pyg["cpu_blocks_per_s"], 2)
        if "cpu_blocks_per_s" in pyg
        else None,
        "ratio_vs_gcodeparser": round(cpu_ours / gcp["cpu_lines_per_s"], 2)
        if "cpu_lines_per_s" in gcp
        else None,
        "ratios_from": "CPU time (process_time) of each, so a loaded shared machine skews less",
        # pygcode managed 16.6k blocks/s on the reference machine class (issue 2): scale our
        # CPU-time rate by the same factor to estimate the figure the target refers to
        "est_blocks_per_s_on_reference_machine": round(
            cpu_ours * PYGCODE_REFERENCE / pyg["cpu_blocks_per_s"]
        )
        if "cpu_blocks_per_s" in pyg
        else None,
        **big,
        "python": sys.version.split()[0],
        "loadavg_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
