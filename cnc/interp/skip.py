"""G31 skip function (Fanuc): a linear feed move that stops at the skip signal.

`G31 X Y Z [P1..P4] [F]` feeds towards its end point like G1 (at the modal or the block's
F); when the skip signal comes the machine stops, the rest of the move is dropped and the
program goes on from there. The position at the signal is stored in #5061.. (the first
axes in order, in the work coordinate system with the tool length offset, as #5041..);
without a signal the move ends at its end point, which is then the skip position, and no
alarm is raised (a measuring macro compares #5061.. against its tolerances itself).
G31 is one-shot (group 00); P1..P4 choose the multi-step skip's input (the simulated tool
setter drives every one of them); under cutter compensation it is alarm PS0035.

With G53 in the block (`G91 G53 G31 Z-50`, a Kitamura tool measuring macro) the end point is
in machine coordinates, and under G91 an increment as for any G53 here.

Where the signal comes from: in `nc check` / `nc plan` the machine's tool setter
(cnc.probe, `probe.tool_setter`) decides from the programmed path (`first_trip`); without a
sensor the move runs to its end and the interpreter notes the line (`skip_misses`, printed
as a warning). On the machine the controller latches the encoder position at the IPO
cycle the sensor switches and corrects the interpreter (`Interpreter.skipped`) before it
reads the next block.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.canon import SkipFeed
from cnc.interp.gnum import G53
from cnc.interp.offsets import machine_target

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

PS_SKIP_IN_COMP = "PS0035"  # Fanuc: G31 commanded in cutter compensation mode
SKIP_STEPS = range(1, 5)  # G31 P1..P4 (multi-step skip)


def skip_move(ip: Context, run: BlockRun) -> None:
    blk, words = run.blk, run.words
    col = run.gcol["skip"]
    if ip._comp_engaged():
        raise ip._err(
            f"{PS_SKIP_IN_COMP} G31 with cutter compensation active (cancel with G40)",
            blk,
            "G",
            col,
        )
    signal = 0
    if "P" in words:
        p = words["P"]
        if p != int(p) or int(p) not in SKIP_STEPS:
            raise ip._err(f"G31 P{p:g}: the multi-step skip is P1..P4", blk, "P")
        signal = int(p)
    rot = ip._rot
    if rot is not None and rot.words_in(blk):
        letter = rot.words_in(blk)[0]
        raise ip._err(f"G31 skips on X Y Z only, not on the rotary axis {letter}", blk, letter)
    start = ip._mach
    if run.g.get("nonmodal") == G53:
        end = machine_target(ip, blk)
    else:
        t = ip._target(blk, words)
        if ip._xf_on:
            t = ip._xf.apply(t)
        o = ip._off
        end = (t[0] + o[0], 0.0 if ip._lathe else t[1] + o[1], t[2] + o[2])
    ip._check(end, blk, blk.line)
    feed = ip._feed(blk)
    # the tool in the spindle as the control knows it (offset number = tool number)
    tool = ip._tools.get(ip._tool_in) if ip._tool_in and not ip._lathe else None
    length, radius = (0.0, 0.0) if tool is None else (tool.length, tool.radius)
    sensor = ip.params.tool_setter
    trip = sensor.first_trip(start, end, length, radius) if sensor is not None else None
    ip._out.append(SkipFeed(blk.line, end, feed, True, signal, length, radius, trip))
    if trip is None:
        ip.skip_misses.append((ip._frames[-1].file if ip._frames else ip.file, blk.line))
    ip._moved = True
    ip.skipped(trip, trip if trip is not None else end)
