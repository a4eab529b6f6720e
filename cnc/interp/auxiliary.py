"""Tool, spindle and coolant functions: T, M6, M3/M4/M5/M19, M7/M8/M9, other M codes."""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.canon import AuxFunction, Coolant, SpindleDirection, ToolChange
from cnc.interp.gnum import M7, M8, M9

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

_DIRECTION = {
    3: SpindleDirection.CW,
    4: SpindleDirection.CCW,
    5: SpindleDirection.STOP,
    19: SpindleDirection.ORIENT,
}


def tool_word(ip: Context, run: BlockRun) -> None:
    ip._tool_word(run.blk, run.words["T"])


def tool_change(ip: Context, run: BlockRun) -> None:
    ip._emit(ToolChange(run.line, ip._tool))
    ip._tool_in = ip._tool


def spindle(ip: Context, run: BlockRun) -> None:
    ip._spindle = _DIRECTION[run.m["spindle"]]
    ip._emit_spindle(run.line)


def spindle_speed_change(ip: Context, run: BlockRun) -> None:
    """S or G96/G97 without M3/M4/M5: a turning spindle takes the new speed."""
    if (
        run.spindle_changed
        and "spindle" not in run.m
        and ip._spindle in (SpindleDirection.CW, SpindleDirection.CCW)
    ):
        ip._emit_spindle(run.line)


def coolant(ip: Context, run: BlockRun) -> None:
    code = run.m["coolant"]
    if code == M9:
        ip._mist = ip._flood = False
    elif code == M7:
        ip._mist = True
    elif code == M8:
        ip._flood = True
    else:  # M7 and M8 in one block
        ip._mist = ip._flood = True
    ip._emit(Coolant(run.line, ip._mist, ip._flood))


def aux_functions(ip: Context, run: BlockRun) -> None:
    for code in run.aux:
        ip._emit(AuxFunction(run.line, code))
