"""The seam between the machine and its controller (`cnc.controller`).

The machine composes a controller it does not own. It talks to it only through the types
below (the controller's contract): per IPO cycle `CycleInputs` in, `CycleOutputs` out. When
`cnc.controller` is importable its own classes are used; until then equal local records keep
the machine (and its axis layers) usable, so both sides can be built in parallel.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

try:  # the real controller, once it is there
    from cnc.controller import AxisFeedback, CycleInputs, CycleOutputs  # type: ignore
    from cnc.controller import IdealAxes as _ControllerIdealAxes  # type: ignore

    HAVE_CONTROLLER = True
except ImportError:  # pragma: no cover - depends on the tree's state
    HAVE_CONTROLLER = False
    _ControllerIdealAxes = None

    @dataclass(frozen=True)
    class AxisFeedback:  # type: ignore[no-redef]
        actual: Mapping[str, float]
        following_error: Mapping[str, float]
        enabled: bool
        homed: Mapping[str, bool]
        homing: bool
        faults: tuple = ()

    @dataclass(frozen=True)
    class CycleInputs:  # type: ignore[no-redef]
        t: float
        plc: Mapping[str, int | bool]
        axes: AxisFeedback

    @dataclass(frozen=True)
    class CycleOutputs:  # type: ignore[no-redef]
        targets: Mapping[str, float]
        axis_command: str = "none"
        home_axes: tuple[str, ...] = ()
        plc: Mapping[str, int | bool] = field(default_factory=dict)
        status: object = None


AXIS_COMMANDS = ("none", "enable", "disable", "quick_stop", "home", "fault_reset")


def controller_class():
    """`cnc.controller.Controller`; ImportError with a clear reason while it is missing."""
    try:
        from cnc.controller import Controller  # type: ignore
    except ImportError as exc:
        raise ImportError(
            "the NC controller (cnc.controller) is not available in this build: " + str(exc)
        ) from exc
    return Controller


def command_refused_class():
    try:
        from cnc.controller import CommandRefused  # type: ignore
    except ImportError:
        return _LocalRefused
    return CommandRefused


class _LocalRefused(Exception):
    """Stand-in while cnc.controller is missing (the controller raises its own)."""
