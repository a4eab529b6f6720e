"""The NC interpreter: part program lines in, canonical machine commands out.

Public API: `Interpreter(params, ...)`, `Interpreter.run(lines)`, `Interpreter.state`,
`check(lines, params, file=...)`, `ToolOffset`, `ModalState`.
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
