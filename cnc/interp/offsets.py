"""Offsets and coordinate systems: G54..G59 and G54.1 P, G10, G92 (lathe G50), G28/G30, G53.

Work offset slots (`ip._wofs`): 0 common (EXT), 1..6 G54..G59, 7..54 G54.1 P1..P48 (6 + P).
G10 and G92 write machine data: their bodies are the interpreter's `_g10` and
`_coordinate_set`, which own the offset and tool memories.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.canon import StraightFeed, StraightTraverse
from cnc.interp.gnum import G0, G1, G28, G30, G54, G54_1

if TYPE_CHECKING:
    from cnc.gcode.lexer import Block
    from cnc.interp.context import BlockRun, Context

EXTENDED_OFFSETS = 48  # G54.1 P1..P48 (Fanuc option "additional workpiece coordinate systems")


def select_work_offset(ip: Context, run: BlockRun) -> None:
    code = run.g["work_offset"]
    if code == G54_1:
        blk = run.blk
        p = run.words["P"]
        if p != int(p) or not 1 <= p <= EXTENDED_OFFSETS:
            raise ip._err(
                f"G54.1 P{p:g}: extended work offsets are P1..P{EXTENDED_OFFSETS}", blk, "P"
            )
        wcs = 6 + int(p)
    else:
        wcs = (code - G54) // 10 + 1
    if wcs != ip._wcs:
        ip._wcs = wcs
        ip._refresh_offsets(resync=True)


def data_setting(ip: Context, run: BlockRun) -> None:
    ip._g10(run.blk)


def coordinate_set(ip: Context, run: BlockRun) -> None:
    ip._coordinate_set(run.blk)


def reference_return(ip: Context, run: BlockRun) -> None:
    """G28 / G30 [P2]: via the intermediate point (the axis words) to the reference point."""
    blk, words = run.blk, run.words
    code = run.g["nonmodal"]
    if ip._comp_engaged():
        raise ip._err("G28/G30 with cutter compensation active (cancel with G40)", blk, "G")
    if code == G30 and "P" in words and int(words["P"]) not in (1, 2):
        raise ip._err("G30 P3/P4 (third/fourth reference) is not configured", blk, "P")
    named = [i for i, letter in enumerate("XYZ") if letter in words]
    if ip._lathe:
        if "U" in words:
            named.append(0)
        if "W" in words:
            named.append(2)
    ref = ip._home if code == G28 else ip._second_ref
    rot = ip._rot
    rot_named = rot is not None and bool(rot.words_in(blk))
    if rot_named:
        # the named rotary axes go straight to their reference angle (no intermediate)
        assert rot is not None
        rot.home_named(blk, ip, None if code == G28 else ip._second_ref_rot)
    if named:
        mid = ip._target(blk, words)
        ip._line_to(mid, None, blk, run.exact)
    elif not rot_named:
        named = [0, 1, 2]  # no axis words: every axis goes home directly (LinuxCNC)
        if rot is not None:
            rot.mach = list(rot.home) if code == G28 else list(ip._second_ref_rot)
    m = list(ip._mach)
    for i in set(named):
        m[i] = ref[i]
    mt = (m[0], 0.0 if ip._lathe else m[1], m[2])
    ip._check(mt, blk, blk.line)
    ip._out.append(StraightTraverse(blk.line, mt, run.exact))
    ip._mach = mt
    ip._pos = ip._prog_from_machine()
    # The return itself goes to a machine point whatever the unit, so it does not fix the
    # program's unit: Haas programs start `G28` before their `G20` (an intermediate point
    # is a programmed position and counted as motion by _line_to).


def machine_move(ip: Context, run: BlockRun) -> None:
    """G53 G0|G1 X Y Z: a move in machine coordinates (no offsets). Under G91 the words are
    increments from where the tool stands, the same displacement in any coordinate system:
    Fanuc ignores G53 in incremental mode, Mitsubishi moves by the increment (M700 manual,
    14.4 (4)); a Kitamura HMC's tool measuring macro (O919100) moves `G91 G53 G00 X#21`."""
    if "skip" in run.g:
        return  # G53 G31: the skip move goes in machine coordinates (cnc.interp.skip)
    blk = run.blk
    motion = run.g.get("motion")
    if ip._comp_engaged():
        raise ip._err("G53 with cutter compensation active", blk, "G")
    mo = motion if motion is not None else ip._motion
    if mo not in (G0, G1):
        raise ip._err("G53 moves only with G0 or G1", blk, "G")
    if ip._rot is not None:
        ip._rot.move(ip, blk, ip._abs, machine=ip._abs)
    mt = machine_target(ip, blk)
    ip._check(mt, blk, blk.line)
    if mo == G0:
        ip._out.append(StraightTraverse(blk.line, mt, run.exact))
    else:
        ip._out.append(StraightFeed(blk.line, mt, ip._feed(blk), run.exact))
    if motion is not None:
        ip._motion = motion
    ip._mach = mt
    ip._pos = ip._prog_from_machine()
    ip._moved = True


def machine_target(ip: Context, blk: Block) -> tuple[float, float, float]:
    """A G53 block's end point in machine coordinates: its words under G90, increments
    from where the tool stands under G91 (G53 G0/G1 here, G53 G31 in cnc.interp.skip)."""
    m = list(ip._mach)
    for i, letter in enumerate("XYZ"):
        if letter in blk.words:
            val = ip._dim(blk, letter) * (0.5 if letter == "X" and ip._diam else 1.0)
            m[i] = val if ip._abs else m[i] + val
    return (m[0], 0.0 if ip._lathe else m[1], m[2])
