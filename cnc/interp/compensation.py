"""Cutter radius compensation G40/G41/G42 (D) and tool length compensation G43/G44/G49 (H).

The read-ahead compensation itself (segments held back, corners) is the interpreter's
geometry core (`_cutter_comp`, `_comp_line`, cnc.cutter_comp); these are the code handlers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.interp.gnum import G43, G49

# Lathe cycles whose D is their own word (cnc.interp.lathe_cycles), not a radius offset.
D_WORD_CYCLES = frozenset(("G70", "G71", "G72", "G73", "G74", "G75", "G76"))

if TYPE_CHECKING:
    from cnc.gcode.lexer import Block
    from cnc.interp.context import BlockRun, Context


def cutter_comp(ip: Context, run: BlockRun) -> None:
    ip._cutter_comp(run.blk, run.g["cutter_comp"])


def d_word(ip: Context, run: BlockRun) -> None:
    nonmodal = run.rows.get("nonmodal")
    if nonmodal is not None and nonmodal.name in D_WORD_CYCLES and ip._lathe:
        return  # a lathe cycle's D (depth of cut, passes, Haas clearance): the cycle's word
    # G41/G42 read their D first (this runs after them: the same number again); with G40
    # or alone, D selects the offset the next G41/G42 takes
    ip._d = ip._int_word(run.blk, "D")


def length_comp(ip: Context, run: BlockRun) -> None:
    apply_length(ip, run.blk, run.g["length_comp"])


def h_word(ip: Context, run: BlockRun) -> None:
    """H alone: selects the offset; under G43/G44 it applies at once."""
    if "length_comp" in run.g:
        return
    ip._h = ip._int_word(run.blk, "H")
    if ip._tlo_code != G49:
        apply_length(ip, run.blk, ip._tlo_code)


def apply_length(ip: Context, blk: Block, code: int) -> None:
    if "H" in blk.words:
        ip._h = ip._int_word(blk, "H")
    ip._tlo_code = code
    if code == G49:
        ip._tlo = (0.0, 0.0, 0.0)
    else:
        length = ip._offset_entry(blk, "H", ip._h).length
        ip._tlo = (0.0, 0.0, length if code == G43 else -length)
    ip._refresh_offsets(resync=False)
