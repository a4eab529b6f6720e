"""Program flow: G4 dwell, M0/M1/M2/M30 stops, M98/M99 subprograms, G65/G66/G67 macro calls."""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.canon import Dwell, ProgramStop, StopKind

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

_STOPS = {
    0: StopKind.PROGRAM_STOP,
    1: StopKind.OPTIONAL_STOP,
    2: StopKind.PROGRAM_END,
    30: StopKind.PROGRAM_END_REWIND,
}


def dwell(ip: Context, run: BlockRun) -> None:
    """G4: P in milliseconds (an integer), X (lathe also U) in seconds."""
    blk, words = run.blk, run.words
    if "P" in words:
        p = words["P"]
        if p != int(p):
            raise ip._err("G4 P is in milliseconds (an integer)", blk, "P")
        sec = p / 1000.0
    elif "X" in words:
        sec = ip._plain(blk, "X")
    elif "U" in words:
        sec = ip._plain(blk, "U")
    else:
        raise ip._err("G4 dwell needs P (ms) or X (s)", blk, "G")
    if sec < 0:
        raise ip._err("negative dwell time", blk, "P" if "P" in words else "X")
    ip._emit(Dwell(blk.line, sec))


def stop(ip: Context, run: BlockRun) -> None:
    code = run.m["stop"]
    ip._emit(ProgramStop(run.line, _STOPS[code]))
    if code in (2, 30):
        ip._flush_comp()
        ip._ended = ip._switch = True


def call(ip: Context, run: BlockRun) -> None:
    ip._call(run.blk)


def return_(ip: Context, run: BlockRun) -> None:
    ip._return(run.blk)


def macro_call(ip: Context, run: BlockRun) -> None:
    """G65/G66: the interpreter takes such a block whole (its words are arguments)."""
    ip._macro_call(
        run.blk, run.rows["macro_call"] if "macro_call" in run.rows else run.rows["macro_modal"]
    )


def macro_modal_cancel(ip: Context, run: BlockRun) -> None:
    """G67: no more modal macro calls."""
    ip._macro_modal_cancel()
