"""`fmscell nc plan` speed and the planner's worst limit ratio over the G-code corpus.

Prints one JSON object:

* `speed`: per file (the corpus's three largest CAM programs), the whole `nc plan`
  process (interpreter, planner, interpolator, summary; no trace) on the shipped mill
  with soft limits far away: machining seconds (`cycle_time_s`), wall and CPU seconds
  of the process, and machining seconds per wall / per CPU second. Issue 13 target:
  >= 1000x on led-1089-wall.nc (`target`); `baseline` is the figure before it (~220x,
  compiled, quiet box) and `vs_baseline` the ratio of this run's figure to it.
* `corpus`: every corpus program the kernel reads (shipped mill, else the shipped
  lathe; wide travel; look-ahead `lookahead`) planned in-process, its IPO samples
  measured by the discrete definition of docs/motion.md: `planned`, `worst_limit_ratio`
  (must be <= 1: the planner's claim, up to 1e-9 float rounding) and where it occurs,
  and the programs cut short at `cycle_cap` IPO cycles (a lathe program read on a mill
  may run for hours of machining time) in `capped`.
* `compiled`: whether the planner and interpolator ran as mypyc extensions (the target is
  for the compiled build; as plain Python the same run takes about 3x the CPU time).

`--quick` plans only led-1089-wall.nc and caps the corpus at 25k cycles per program.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SPEED_FILES = ["led-1089-wall.nc", "led-1121-btn8.nc", "cline-rebels5.nc"]
BASELINE = 220.0  # machining s per wall s on led-1089-wall.nc before issue 13 (compiled)
TARGET = 1000.0
WIDE = """base: {base}
axes:
  X: {{min_mm: -100000.0, max_mm: 100000.0}}
  Z: {{min_mm: -100000.0, max_mm: 100000.0}}
{y}second_reference_mm: {ref}
"""


def corpus_dir() -> Path:
    from tests.reference import GCODE_CORPUS

    return GCODE_CORPUS


def compiled() -> bool:
    import cnc.interpolator.motion as m

    return not str(m.__file__).endswith(".py")


def speed(path: Path, config: Path) -> dict:
    """One whole `nc plan` process: machining s per wall s and per CPU s."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "server.cli", "nc", "plan", str(path), "--config", str(config)]
        + ["--json"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        check=False,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"nc plan {path.name}: {proc.stderr.strip()[-300:]}")
    rep = json.loads(proc.stdout.strip().splitlines()[-1])
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    m = rep["cycle_time_s"]
    return {
        "machining_s": round(m, 3),
        "wall_s": round(wall, 3),
        "cpu_s": round(cpu, 3),
        "machining_s_per_wall_s": round(m / wall, 1),
        "machining_s_per_cpu_s": round(m / cpu, 1) if cpu > 0 else None,
        "worst_limit_ratio": rep["worst_limit_ratio"],
        "moves": rep["moves"],
    }


class _Enough(Exception):
    pass


def corpus_ratio(lookahead: int, cycle_cap: int) -> dict:
    """Worst |v|/V, |a|/A, |j|/J over every sample of every corpus program that plans."""
    from cnc.cli_plan import plan_run
    from cnc.config import load_machine_params
    from cnc.errors import NcError
    from cnc.interp import Interpreter

    machines = {}
    for name in ("mill3", "lathe2"):
        p = load_machine_params(ROOT / "cnc" / "machines" / f"{name}.yaml")
        axes = tuple(dataclasses.replace(a, min_mm=-1e5, max_mm=1e5) for a in p.axes)
        machines[name] = dataclasses.replace(
            p, axes=axes, lookahead=lookahead, second_reference_mm=None
        )
    worst = {"ratio": 0.0}
    planned = []
    capped = []
    t0 = time.process_time()
    for path in sorted(corpus_dir().glob("*.nc")):
        for params in machines.values():
            try:
                interp = Interpreter(params, file=str(path))
                start = tuple(interp.state.machine_position)
                # the summary's own maxima (Motion.run + Peaks); a program still running
                # at the cap is planned again up to it, its samples measured one by one
                with open(path, encoding="latin-1") as fh:
                    try:
                        rep = plan_run(params, interp.run(fh), start, max_cycles=cycle_cap)
                    except NcError as e:
                        if "did not finish" not in str(e):
                            raise
                        capped.append(path.name)
                        rep = _capped_summary(params, path, cycle_cap, params.ipo_cycle_s)
            except NcError:
                continue
            planned.append(path.name)
            for ax, r in rep["limit_ratio"].items():
                for kind, x in r.items():
                    if x > worst["ratio"]:
                        worst = {"ratio": x, "file": path.name, "axis": ax, "kind": kind}
            break
    return {
        "lookahead": lookahead,
        "planned": len(planned),
        "worst_limit_ratio": worst["ratio"],
        "worst": worst,
        "cycle_cap": cycle_cap,
        "capped": capped,
        "cpu_s": round(time.process_time() - t0, 2),
    }


def _capped_summary(params, path: Path, cycle_cap: int, ipo: float) -> dict:
    """The limit ratios of the first `cycle_cap` samples (a trace run stopped there)."""
    from cnc.cli_plan import AXIS_INDEX, limit_ratios, plan_run
    from cnc.interp import Interpreter
    from cnc.interpolator.motion import Peaks

    interp = Interpreter(params, file=str(path))
    start = tuple(interp.state.machine_position)
    peaks = Peaks((start[0], start[1], start[2]), ipo)
    seen = [0]

    def on_sample(s) -> None:
        peaks.add(s.pose)
        seen[0] += 1
        if seen[0] >= cycle_cap:
            raise _Enough

    with open(path, encoding="latin-1") as fh, contextlib.suppress(_Enough):
        plan_run(params, interp.run(fh), start, on_sample=on_sample)
    names = [a.name for a in params.axes if a.name in AXIS_INDEX]
    idx = [AXIS_INDEX[n] for n in names]
    ratios = limit_ratios(params, peaks.vmax, peaks.amax, peaks.jmax, names, idx)
    return {"limit_ratio": ratios}


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    corpus = corpus_dir()
    if not corpus.is_dir():
        print(json.dumps({"error": f"corpus not found at {corpus} (set FMSCELL_SHARED)"}))
        return 1
    out: dict = {"compiled": compiled()}
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "wide-mill.yaml"
        config.write_text(
            WIDE.format(
                base="mill3",
                y="  Y: {min_mm: -100000.0, max_mm: 100000.0}\n",
                ref="{X: 0.0, Y: 0.0, Z: 0.0}",
            )
        )
        files = SPEED_FILES[:1] if quick else SPEED_FILES
        out["speed"] = {f: speed(corpus / f, config) for f in files}
    lead = out["speed"]["led-1089-wall.nc"]["machining_s_per_wall_s"]
    out["led_1089_machining_s_per_wall_s"] = lead
    out["target"] = TARGET
    out["target_met"] = lead >= TARGET
    out["baseline"] = BASELINE
    out["vs_baseline"] = round(lead / BASELINE, 2)
    out["corpus"] = corpus_ratio(200, 25_000 if quick else 150_000)
    out["worst_limit_ratio"] = out["corpus"]["worst_limit_ratio"]
    out["limits_met"] = out["worst_limit_ratio"] <= 1.0 + 1e-9
    out["load_average"] = os.getloadavg()[0]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
