"""Realtime: 6 CSP axes at a 1 ms SYNC on the wall clock, late cycles and lateness.

Two realtime hubs (CAN lines of 3 axes: 6 axes at 1 ms do not fit one 1 Mbit/s line), each
delivering and ticking its drives from its own thread; the axis group paces its cycles on
absolute deadlines. A cycle is late when not every TPDO arrived before the next SYNC was due.
Target: < 0.1 % late cycles over 60 s (`--seconds` to shorten).
"""

from __future__ import annotations

import argparse
import json
import math
import warnings

from drives import VirtualDrive
from drives.bus import BusLoadWarning, CanHub
from drives.master import AxisConfig, AxisGroup

TARGET_LATE_PCT = 0.1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--substep", type=float, default=1e-3, help="plant sub-step, s")
    args = parser.parse_args()
    hubs = [CanHub(channel=f"can{i}", mode="realtime") for i in (0, 1)]
    drives = [
        VirtualDrive(n, hub.endpoint(f"n{n}"), substep=args.substep)
        for hub in hubs
        for n in (1, 2, 3)
    ]
    for d in drives:
        d.start()
    names = ["X", "Y", "Z", "A", "B", "C"]
    axes = [AxisConfig(name, i % 3 + 1, line=i // 3) for i, name in enumerate(names)]
    group = AxisGroup(
        [h.endpoint("master") for h in hubs], axes, ipo_cycle_s=0.001, following_error_every=4
    )
    try:
        group.boot()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BusLoadWarning)
            group.configure()
        group.enable()
        start = {n: group.position_mm(n) for n in names}
        group.stats = type(group.stats)()  # measure the steady run only
        cycles = round(args.seconds / 0.001)
        for k in range(cycles):
            t = k * 0.001
            group.cycle(
                {n: start[n] + 10.0 * math.sin(2 * math.pi * t + i) for i, n in enumerate(names)}
            )
        summary = group.stats.summary()
        late_ticks = sum(h.late_ticks for h in hubs)
        faults = len(group.fault_log)
    finally:
        group.close()
        for hub in hubs:
            hub.close()
    print(
        json.dumps(
            {
                "benchmark": "drives_realtime",
                "seconds": args.seconds,
                "configuration": "6 CSP axes, 1 ms SYNC, 2 realtime CAN hubs x 3 axes, "
                f"plant sub-step {args.substep * 1e6:g} us",
                "target": f"< {TARGET_LATE_PCT} % late cycles",
                **summary,
                "drive_tick_late": late_ticks,
                "faults": faults,
                "meets_target": summary["late_pct"] < TARGET_LATE_PCT,
            }
        )
    )


if __name__ == "__main__":
    main()
