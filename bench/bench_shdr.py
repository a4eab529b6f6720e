"""Status pipeline throughput: SHDR formatting on the machine, ingest and requests in the agent.

- `format_publishes_per_s`: ShdrFormatter state + diff for a 3-axis mill whose axes, feed,
  line and spindle load change every cycle (the IPO-cycle worst case), SHDR lines out.
- `ingest_observations_per_s`: Agent.ingest_line on those lines (tokenize, map, buffer,
  checkpoints) for a cell of 8 machines.
- `sample_requests_per_s`: /sample?count=100 documents from a full buffer, and
  `current_requests_per_s` for the whole cell.

No peer: there is no other Python MTConnect agent worth measuring against here (the PyPI
`mtconnect` 0.3.3 package is a one-device toy). Targets come from docs/mtconnect.md and the
cell goals: a machine publishing every 2 ms IPO cycle needs >= 500 publishes/s (8 machines on
one core: 4000/s); 50 machines x 30 items at 10 Hz needs >= 15000 observations/s ingested.

Prints one JSON object. Usage: bench_shdr.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cnc.faces.shdr import ShdrFormatter  # noqa: E402
from cnc.status import AxisStatus, MachineStatus  # noqa: E402
from mtconnect import Agent, build_device  # noqa: E402

AXES = ("X", "Y", "Z")
TARGET_FORMAT = 4000
TARGET_INGEST = 15000


def statuses(n: int) -> list[MachineStatus]:
    out = []
    for i in range(n):
        t = i * 0.002
        out.append(
            MachineStatus(
                execution="ACTIVE",
                program="O1000",
                line=10 + i // 50,
                path_feed_rate=1200.0 + (i % 7),
                axes={
                    "X": AxisStatus(-100 + t * 10, -100 + t * 10 + 0.001),
                    "Y": AxisStatus(-50 + t * 5, -50 + t * 5),
                    "Z": AxisStatus(-5.0, -5.0),
                },
                spindle_speed=3000.0,
                spindle_load=30.0 + (i % 13) * 0.5,
                part_count=i // 1000,
            )
        )
    return out


def timed(fn, seconds: float) -> float:
    """Calls of fn per second, run for about `seconds`."""
    n, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        fn()
        n += 1
    return n / elapsed


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=2.0)
    args = ap.parse_args()

    fmt = ShdrFormatter(AXES)
    snaps = statuses(5000)
    ts = "2026-11-21T06:00:00.000000Z"

    i = calls = 0
    prev_state = fmt.state(snaps[0])
    lines_out = 0

    def publish() -> None:
        nonlocal i, prev_state, lines_out, calls
        calls += 1
        i = (i + 1) % len(snaps)
        state = fmt.state(snaps[i])
        lines_out += len(fmt.diff_states(prev_state, state, ts))
        prev_state = state

    pubs = timed(publish, args.seconds)

    # ingest: the lines of consecutive publishes, fed to 8 machines in turn
    lines = []
    for a, b in zip(snaps, snaps[1:], strict=False):
        lines += fmt.diff(a, b, ts)
    lines = lines[:20000]
    names = [f"m{k}" for k in range(8)]
    agent = Agent([build_device(n, AXES) for n in names])
    obs_per_line = sum(len(ln.split("|")) // 2 for ln in lines[:1000]) / 1000
    j = 0

    def ingest() -> None:
        nonlocal j
        j += 1
        agent.ingest_line(names[j % 8], lines[j % len(lines)])

    start_seq = agent.buffer.next_sequence
    t0 = time.perf_counter()
    line_rate = timed(ingest, args.seconds)
    obs_rate = (agent.buffer.next_sequence - start_seq) / (time.perf_counter() - t0)

    sample_rate = timed(lambda: agent.request("sample", None, {"count": "100"}), args.seconds / 2)
    current_rate = timed(lambda: agent.request("current", None, {}), args.seconds / 2)

    print(
        json.dumps(
            {
                "bench": "shdr",
                "format_publishes_per_s": round(pubs),
                "format_lines_per_publish": round(lines_out / max(1, calls), 2),
                "ingest_lines_per_s": round(line_rate),
                "ingest_observations_per_s": round(obs_rate),
                "observations_per_line": round(obs_per_line, 2),
                "sample_count100_requests_per_s": round(sample_rate, 1),
                "current_8_machines_requests_per_s": round(current_rate, 1),
                "buffer_size": agent.buffer.size,
                "target_format_publishes_per_s": TARGET_FORMAT,
                "target_ingest_observations_per_s": TARGET_INGEST,
                "meets_targets": pubs >= TARGET_FORMAT and obs_rate >= TARGET_INGEST,
                "peer": None,
            }
        )
    )


if __name__ == "__main__":
    main()
