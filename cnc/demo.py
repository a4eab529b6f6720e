"""The NC kernel demo `make run` shows until the cell server exists (issue 7).

It runs a sample part program through the interpreter, the look-ahead planner and the
interpolator on ideal axes (no drives, no PLC: sync points are acknowledged at once, dwells
are waited out) and prints a summary.
"""

from __future__ import annotations

from cnc.canon import ArcFeed, PathMode, Plane, SetPathMode, StraightFeed, StraightTraverse
from cnc.cli_plan import plan_run
from cnc.params import MachineParams

SAMPLE_PROGRAM = """%
O0001 (fmscell demo: pocket contour with arcs and a helical entry)
N10 G21 G90 G17 G54 G64 P0.01
N20 T1 M6
N30 S8000 M3
N40 M8
N50 G0 X-120 Y-100 Z-5
N60 G1 Z-20 F1200
N70 G3 X-120 Y-100 Z-22 I10 J0 F2400
N80 G1 X-60 F6000
N90 G2 X-40 Y-120 I0 J-20
N100 G1 Y-180
N110 G2 X-60 Y-200 I-20 J0
N120 G1 X-180
N130 G2 X-200 Y-180 I0 J20
N140 G1 Y-120
N150 G2 X-180 Y-100 I20 J0
N160 G1 X-120
N170 G4 X0.2
N180 G0 Z-5
N190 M9
N200 M5
N210 M30
%
"""


def _fallback_commands():
    """The same contour as canonical commands, for when the interpreter is unavailable."""
    z = -22.0
    return [
        SetPathMode(3, PathMode.CONTINUOUS, 0.01),
        StraightTraverse(6, (-120.0, -100.0, -5.0)),
        StraightFeed(7, (-120.0, -100.0, z), 1200.0),
        StraightFeed(9, (-60.0, -100.0, z), 6000.0),
        ArcFeed(10, (-40.0, -120.0, z), (-60.0, -120.0, z), Plane.XY, True, 6000.0),
        StraightFeed(11, (-40.0, -180.0, z), 6000.0),
        ArcFeed(12, (-60.0, -200.0, z), (-60.0, -180.0, z), Plane.XY, True, 6000.0),
        StraightFeed(13, (-180.0, -200.0, z), 6000.0),
        ArcFeed(14, (-200.0, -180.0, z), (-180.0, -180.0, z), Plane.XY, True, 6000.0),
        StraightFeed(15, (-200.0, -120.0, z), 6000.0),
        ArcFeed(16, (-180.0, -100.0, z), (-180.0, -120.0, z), Plane.XY, True, 6000.0),
        StraightFeed(17, (-120.0, -100.0, z), 6000.0),
        StraightTraverse(19, (-120.0, -100.0, -5.0)),
    ]


def run_demo() -> int:
    params = MachineParams()
    print("fmscell: the cell server is not built yet; this is the NC kernel demo (issue 2).")
    try:  # deferred: optional, the demo runs fixed commands in a build without the interpreter
        from cnc.interp import Interpreter
    except ImportError:
        Interpreter = None
    if Interpreter is not None:
        interp = Interpreter(params, file="demo.nc")
        start = tuple(interp.state.machine_position)
        print("Running the sample program through interpreter -> planner -> interpolator:")
        report = plan_run(params, interp.run(SAMPLE_PROGRAM), start)
    else:
        print(
            "The interpreter (cnc.interp) is not available in this build: running a"
            " hard-coded list of canonical commands for the same contour through planner"
            " and interpolator."
        )
        report = plan_run(params, _fallback_commands(), (0.0, 0.0, 0.0))
    axes = list(report["final_position"])
    print(f"  blocks {report['blocks']}, moves {report['moves']}")
    print(f"  cycle time {report['cycle_time_s']:.3f} s at IPO {report['ipo_cycle_s'] * 1000:g} ms")
    print(
        f"  feed path {report['path_length_mm']:.3f} mm, rapid path"
        f" {report['rapid_length_mm']:.3f} mm"
    )
    pos = ", ".join(f"{a}{report['final_position'][a]:.4f}" for a in axes)
    print(f"  final machine position {pos}")
    print(f"  max path deviation {report['max_path_deviation_mm'] * 1000:.2f} um (G64 P0.01)")
    for ax in params.axes:
        n = ax.name
        if n in report["max_abs_accel"]:
            print(
                f"  {n}: |v| {report['max_abs_velocity'][n]:8.2f} mm/s"
                f" (limit {ax.max_velocity / 60:.0f}),"
                f" |a| {report['max_abs_accel'][n]:8.1f} mm/s^2 (limit {ax.max_accel:.0f}),"
                f" |j| {report['max_abs_jerk'][n]:9.0f} mm/s^3 (limit {ax.max_jerk:.0f})"
            )
    return 0
