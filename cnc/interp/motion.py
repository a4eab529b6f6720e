"""Motion: G0 G1 G2 G3, the canned cycle group, G9 exact stop.

The motion step runs once per block: it sets the modal motion from the block's G0..G3 or
cycle code and moves with the modal motion (or the modal cycle) unless a code of the block
owns its axis words (G4, G10, G28, G30, G92, G53, transforms). With G10/G28/G30/G92 a
G0..G3 or G80 only sets the mode (`G0 G91 G28 Z0`); a canned cycle or a transform there
would need the same words and is refused.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.interp import cycles
from cnc.interp.context import Step
from cnc.interp.gnum import G80

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context


def exact_stop(ip: Context, run: BlockRun) -> None:
    run.exact = True


def motion(ip: Context, run: BlockRun) -> None:
    g = run.g
    cy = g.get("cycle")
    mo = g.get("motion")
    owner = run.owner
    nonmodal = run.rows.get("nonmodal")
    g53 = nonmodal is not None and nonmodal.name == "G53"  # G53 moves with the G0/G1
    skip_g1 = "skip" in g and cy is None  # `G1 G31 Z..`: G31 moves, G1 stays modal
    if owner is not None and not g53 and not skip_g1 and (mo is not None or cy is not None):
        if nonmodal is None or nonmodal.step is not Step.NON_MODAL or cy not in (None, G80):
            raise ip._err("a motion G code cannot share a block with this G code", run.blk, "G")
        if cy == G80:
            cycles.cancel(ip)
    if mo is not None:
        ip._motion = mo
        if ip._cycle != G80:
            cycles.cancel(ip)
    if owner is not None:
        return
    if cy is not None or (ip._cycle != G80 and mo is None):
        cycles.cycle_block(ip, run.blk, cy, run.exact)
    else:
        ip._motion_block(run.blk, run.words, run.exact, mo)
