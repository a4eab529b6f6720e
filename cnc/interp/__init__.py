"""The NC interpreter: part program lines in, canonical machine commands out.

Public API: `Interpreter(params, ...)`, `Interpreter.run(lines)`, `Interpreter.state`,
`check(lines, params, file=...)`, `ToolOffset`, `ModalState`.

The G and M codes are declared in `cnc.interp.codes` (one row per code: modal group,
machine kinds, words, execution step, handler); the handlers live in family modules
(modes, motion, offsets, compensation, transform_codes, cycles, flow, auxiliary) and take
the interpreter context explicitly (`cnc.interp.context`). Fanuc Macro B: the syntax in
`cnc.gcode.macro`, the variables in `cnc.interp.macro`, the statements and calls in the
interpreter (docs/gcode.md, "Fanuc Macro B").
"""

from cnc.interp.interpreter import ARC_TOLERANCE_MM, MAX_SUB_NESTING, Interpreter, check
from cnc.interp.state import ModalState, ToolOffset

__all__ = [
    "ARC_TOLERANCE_MM",
    "MAX_SUB_NESTING",
    "Interpreter",
    "ModalState",
    "ToolOffset",
    "check",
]
