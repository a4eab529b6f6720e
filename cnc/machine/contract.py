"""The seam between the machine and its controller (`cnc.controller`, docs/controller.md).

The machine talks to the controller only through this contract: per IPO cycle
`CycleInputs` in, `CycleOutputs` out; operator commands by name (`CommandRefused` says why
not); `drip_input()` and `policy()` for the DNC port.
"""

from __future__ import annotations

from cnc.controller import (
    AXIS_COMMANDS,
    AxisFeedback,
    CommandRefused,
    Controller,
    CycleInputs,
    CycleOutputs,
)

__all__ = [
    "AXIS_COMMANDS",
    "AxisFeedback",
    "CommandRefused",
    "CycleInputs",
    "CycleOutputs",
    "controller_class",
]


def controller_class():
    """The default controller: `cnc.controller.Controller`."""
    return Controller
