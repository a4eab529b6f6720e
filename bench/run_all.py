"""Run every benchmark in bench/ one after another and print each one's JSON object.

Benchmarks run one at a time (never in parallel) so that they do not disturb each other's
figures on a 2-core machine. Output: one JSON object per line, `{"bench": name, ...figures}`;
a benchmark that fails prints `{"bench": name, "error": ...}` and the run exits non-zero.
The soaks (bench_soak*.py, an hour or more each) run only when named, or by `make soak`.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    here = Path(__file__).resolve().parent
    wanted = set(argv)
    failed = 0
    for script in sorted(here.glob("bench_*.py")):
        name = script.stem.removeprefix("bench_")
        if wanted and name not in wanted:
            continue
        if not wanted and name.startswith("soak"):
            continue  # an hour or more each: `make soak` runs them (or name one here)
        proc = subprocess.run(
            [sys.executable, str(script)], capture_output=True, text=True, cwd=here.parent
        )
        lines = [ln for ln in proc.stdout.splitlines() if ln.strip().startswith("{")]
        if proc.returncode != 0 or not lines:
            failed += 1
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
            print(json.dumps({"bench": name, "error": " | ".join(tail)}), flush=True)
            continue
        figures = json.loads(lines[-1])
        print(json.dumps({"bench": name, **figures}), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
