"""Lockstep: 1 s of machine time, 6 CSP axes at a 1 ms SYNC, full drive model, axis group.

6 axes x (RPDO + TPDO) at 1 ms exceed one 1 Mbit/s line (plan_load refuses it), so the
honest configuration is two CAN lines of 3 axes (RPDO1 6 B cw+target, TPDO1 6 B
sw+position, following error TPDO2 every 4th SYNC, heartbeats 100 ms). Reported for the
default 125 us plant sub-step and the coarse 1 ms sub-step. Target: <= 0.25 s wall (>= 4x).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
import warnings

import drives.plant.plant as plant_module
from drives import VirtualDrive
from drives.bus import BusLoadWarning, CanHub
from drives.master import AxisConfig, AxisGroup

TARGET_WALL_S = 0.25


def run(substep: float | None, seconds: float) -> dict:
    hubs = [CanHub(channel="can0"), CanHub(channel="can1")]
    for hub in hubs:
        for n in (1, 2, 3):
            VirtualDrive(n, hub.endpoint(f"n{n}"), substep=substep)
    names = ["X", "Y", "Z", "A", "B", "C"]
    axes = [AxisConfig(name, i % 3 + 1, line=i // 3) for i, name in enumerate(names)]
    group = AxisGroup(
        [h.endpoint("master") for h in hubs], axes, ipo_cycle_s=0.001, following_error_every=4
    )
    group.boot()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BusLoadWarning)
        group.configure()
    group.enable()
    start = {n: group.position_mm(n) for n in names}
    cycles = round(seconds / 0.001)
    t0 = time.perf_counter()
    c0 = time.process_time()
    fb = None
    for k in range(cycles):
        t = k * 0.001
        # a 20 mm circle-ish sweep on every axis (phase-shifted): the drives really move
        fb = group.cycle(
            {n: start[n] + 10.0 * math.sin(2 * math.pi * t + i) for i, n in enumerate(names)}
        )
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    group.close()
    for hub in hubs:
        hub.close()
    return {
        "substep_us": (substep or 125e-6) * 1e6,
        "wall_s": round(wall, 4),
        "realtime_factor": round(seconds / wall, 2),
        # the machine is shared: CPU time is the steadier figure
        "cpu_s": round(cpu, 4),
        "cpu_realtime_factor": round(seconds / cpu, 2),
        "frames": sum(h.load.total_frames for h in hubs),
        "measured_mean_load": [round(h.load.mean, 4) for h in hubs],
        "planned_worst_case_load": [round(p.worst_case_load, 4) for p in group.load_plans],
        "all_fresh": bool(fb and fb.all_fresh),
        "faults": len(group.fault_log),
        "meets_target": wall <= TARGET_WALL_S * seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=1.0, help="machine time to simulate")
    args = parser.parse_args()
    default = run(None, args.seconds)
    coarse = run(1e-3, args.seconds)
    print(
        json.dumps(
            {
                "benchmark": "drives_lockstep",
                "machine_time_s": args.seconds,
                "configuration": "6 CSP axes, 1 ms SYNC, 2 CAN lines x 3 axes at 1 Mbit/s, "
                "RPDO1 6 B + TPDO1 6 B per axis per SYNC, TPDO2 (following error) every 4th",
                "target": f"<= {TARGET_WALL_S} s wall per machine second (>= 4x real time)",
                "default_substep": default,
                "coarse_substep": coarse,
                "load_average_1min": round(os.getloadavg()[0], 2),
                # mypyc extensions (drives/*/mypyc.list) or the plain Python sources
                "compiled": not plant_module.__file__.endswith(".py"),
            }
        )
    )


if __name__ == "__main__":
    main()
