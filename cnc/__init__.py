"""NC kernel: G-code lexer -> interpreter -> look-ahead planner -> interpolator."""

from cnc.errors import NcError

__all__ = ["NcError"]
