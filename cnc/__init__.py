"""NC kernel: G-code lexer -> interpreter -> look-ahead planner -> interpolator.

The public API; everything else in the package is internal.
"""

from cnc.errors import NcError
from cnc.interp import Interpreter, ModalState, ToolOffset, check
from cnc.params import AxisParams, DecimalStyle, MachineParams

__all__ = [
    "AxisParams",
    "DecimalStyle",
    "Interpreter",
    "MachineParams",
    "ModalState",
    "NcError",
    "ToolOffset",
    "check",
]
