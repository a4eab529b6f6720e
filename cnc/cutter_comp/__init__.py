"""Cutter radius compensation G40/G41/G42 in the active plane (see docs/cutter_comp.md).

Public API: `CutterCompensation` (start / push / cancel / flush / active) and `Segment`;
the tolerance constants are exported so callers and tests can quote them.
"""

from cnc.cutter_comp.compensator import CutterCompensation, Segment
from cnc.cutter_comp.geometry import (
    CONTINUITY_TOL_REL,
    INTERFERENCE_TOL_REL,
    LEN_TOL_REL,
    SHALLOW_ANGLE,
)

__all__ = [
    "CONTINUITY_TOL_REL",
    "INTERFERENCE_TOL_REL",
    "LEN_TOL_REL",
    "SHALLOW_ANGLE",
    "CutterCompensation",
    "Segment",
]
