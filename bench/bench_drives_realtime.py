"""Realtime: 6 CSP axes at a 1 ms SYNC on the wall clock, late cycles and lateness.

6 axes at 1 ms do not fit one 1 Mbit/s line, so two CAN lines of 3 axes. Two ways to run
in real time (`--mode`):

* paced (default): the deterministic lockstep core (hubs, drives, axis group) stepped from
  one thread, each IPO cycle started at its absolute wall-clock deadline; a cycle is late
  when its work (frames, drive plants) ends after the next SYNC is due.
* threaded: realtime hubs deliver and tick their drives from their own threads
  (`VirtualDrive.start()`), the axis group waits for the TPDOs; a cycle is late when not
  every TPDO arrived before the next SYNC was due.

Target: < 0.1 % late cycles over 60 s (`--seconds` to shorten).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
import warnings

from drives import VirtualDrive
from drives.bus import BusLoadWarning, CanHub
from drives.master import AxisConfig, AxisGroup
from drives.realtime import RT_PRIORITY_ENV, RealtimeProcess

TARGET_LATE_PCT = 0.1
NAMES = ["X", "Y", "Z", "A", "B", "C"]


def run(mode: str, seconds: float, substep: float) -> dict:
    hub_mode = "realtime" if mode == "threaded" else "lockstep"
    hubs = [CanHub(channel=f"can{i}", mode=hub_mode) for i in (0, 1)]
    drives = [
        VirtualDrive(n, hub.endpoint(f"n{n}"), substep=substep) for hub in hubs for n in (1, 2, 3)
    ]
    if mode == "threaded":
        for d in drives:
            d.start()
    axes = [AxisConfig(name, i % 3 + 1, line=i // 3) for i, name in enumerate(NAMES)]
    group = AxisGroup(
        [h.endpoint("master") for h in hubs],
        axes,
        ipo_cycle_s=0.001,
        following_error_every=4,
        paced=mode == "paced",
    )
    try:
        group.boot()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BusLoadWarning)
            group.configure()
        group.enable()
        start = {n: group.position_mm(n) for n in NAMES}
        group.stats = type(group.stats)()  # measure the steady run only
        collections = list(RealtimeProcess.collections)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for k in range(round(seconds / 0.001)):
            t = k * 0.001
            group.cycle(
                {n: start[n] + 10.0 * math.sin(2 * math.pi * t + i) for i, n in enumerate(NAMES)}
            )
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        summary = group.stats.summary()
        faults = len(group.fault_log)
        gc_in_slack = [b - a for a, b in zip(collections, RealtimeProcess.collections, strict=True)]
        late_ticks = sum(h.late_ticks for h in hubs)
        scheduling = group.scheduling if mode == "paced" else "threads: SCHED_OTHER"
    finally:
        group.close()
        for hub in hubs:
            hub.close()
    if mode == "paced":  # SYNC sent -> the cycle's work done, not a TPDO wait
        summary["cycle_work_p50_us"] = summary.pop("tpdo_latency_p50_us")
        summary["cycle_work_p99_us"] = summary.pop("tpdo_latency_p99_us")
    else:
        summary["drive_ticks_late"] = late_ticks
    return {
        **summary,
        # CPU of this process over the run (threads included) and the box's load: a late
        # cycle on a busy shared box is mostly the scheduler's, not the work's
        "cpu_s": round(cpu, 3),
        "wall_s": round(wall, 3),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "gc_collections_in_slack": gc_in_slack,
        "faults": faults,
        "scheduling": scheduling,
        "meets_target": summary["late_pct"] < TARGET_LATE_PCT,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0, help="per mode")
    parser.add_argument("--mode", choices=("paced", "threaded", "both"), default="paced")
    parser.add_argument("--substep", type=float, default=1e-3, help="plant sub-step, s")
    parser.add_argument(
        "--rt-priority",
        type=int,
        default=50,
        help="SCHED_FIFO priority of the pacing thread for the second paced run (0 = skip it)",
    )
    args = parser.parse_args()
    modes = ("paced", "threaded") if args.mode == "both" else (args.mode,)
    out = {
        "benchmark": "drives_realtime",
        "seconds": args.seconds,
        "configuration": "6 CSP axes, 1 ms SYNC, 2 CAN lines x 3 axes at 1 Mbit/s, "
        f"plant sub-step {args.substep * 1e6:g} us",
        "target": f"< {TARGET_LATE_PCT} % late cycles",
    }
    for mode in modes:
        out[mode] = run(mode, args.seconds, args.substep)
    if "paced" in modes and args.rt_priority:
        # the same run with the pacing thread at SCHED_FIFO (opt-in in drives.realtime)
        os.environ[RT_PRIORITY_ENV] = str(args.rt_priority)
        try:
            out["paced_sched_fifo"] = run("paced", args.seconds, args.substep)
        finally:
            del os.environ[RT_PRIORITY_ENV]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
