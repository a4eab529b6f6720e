"""G71 stock removal on a 200-point contour: the cycle's expansion time.

The contour is a turned profile of 200 points (a bulb: a sine swell on a taper, monotonic
in X and Z so it runs as type I) under `G71 P Q U W D F`, depth 0.5 mm on a 60 mm bar.
Measured: the interpreter reading the contour, computing the passes and emitting every
canonical move of the cycle block (median of several runs); and the pure pass generator
alone (cnc.interp.lathe_geometry.rough_turning) on the same contour. Prints one JSON object.
"""

from __future__ import annotations

import json
import math
import statistics
import time

POINTS = 200
RUNS = 7


def program() -> str:
    lines = ["G18 G21 G40 G80 G99", "G97 S800 M3", "G0 X62 Z2", "G71 P10 Q20 U0.4 W0.1 D0.5 F0.25"]
    lines.append("N10 G0 X10")
    for i in range(1, POINTS + 1):
        t = i / POINTS
        dia = 10.0 + 48.0 * t + 4.0 * math.sin(math.pi * t) ** 2 * (1 - t)
        z = -120.0 * t
        lines.append(f"G1 X{dia:.4f} Z{z:.4f}")
    lines.append("N20 X62")
    lines.append("G0 X100 Z50")
    lines.append("M30")
    return "\n".join(lines) + "\n"


def main() -> None:
    from cnc.interp import Interpreter
    from cnc.interp import lathe_geometry as lg
    from cnc.params import AxisParams, MachineParams

    params = MachineParams(
        kind="lathe",
        axes=(
            AxisParams("X", -1000, 1000, 20000, 4000, 60000),
            AxisParams("Z", -1000, 1000, 24000, 3000, 50000),
        ),
    )
    text = program()
    times = []
    moves = 0
    for _ in range(RUNS):
        ip = Interpreter(params)
        t0 = time.perf_counter()
        cmds = [c for c in ip.run(text) if getattr(c, "line", 0) == 4]
        times.append(time.perf_counter() - t0)
        moves = len(cmds)
    # the pure pass generator on the same contour (radius, mm)
    pts = [(5.0, 2.0)]
    for i in range(1, POINTS + 1):
        t = i / POINTS
        dia = 10.0 + 48.0 * t + 4.0 * math.sin(math.pi * t) ** 2 * (1 - t)
        pts.append((dia / 2, -120.0 * t))
    segs = tuple(lg.Seg(lg.FEED, a, b) for a, b in zip(pts, pts[1:], strict=False))
    gen = []
    for _ in range(RUNS):
        t0 = time.perf_counter()
        mv = lg.rough_turning((31.0, 2.0), segs, 0.5, 0.5, (0.2, 0.1), False)
        gen.append(time.perf_counter() - t0)
    print(
        json.dumps(
            {
                "contour_points": POINTS,
                "cycle_moves": moves,
                # roughing passes and the contour pass: each starts with a rapid then a feed
                "passes": sum(
                    1
                    for a, b in zip(mv, mv[1:], strict=False)
                    if a[0] == lg.RAPID and b[0] != lg.RAPID
                ),
                "expansion_ms": round(statistics.median(times) * 1000, 2),
                "pass_generator_ms": round(statistics.median(gen) * 1000, 2),
                "moves_per_s": round(moves / statistics.median(times)),
            }
        )
    )


if __name__ == "__main__":
    main()
