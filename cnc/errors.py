"""The cnc package's errors: one root, CncError; NcError, the refusal of a part program,
configuration or plan, names file, line, column and reason."""

from __future__ import annotations


class CncError(Exception):
    """Base of every error the cnc package raises (the NC kernel, the machine, its faces and
    data). Subclasses that are bad input keep ValueError as a second base, so existing
    handlers still see them."""


class NcError(CncError):
    """A part program, configuration or plan that the NC kernel refuses.

    `line` and `col` are 1-based positions in the source text (0 when not applicable).
    `str(err)` is the `FILE:LINE:COL: message` form the command line prints.
    """

    def __init__(self, message: str, line: int = 0, col: int = 0, file: str = "<program>") -> None:
        super().__init__(message)
        self.message = message
        self.line = line
        self.col = col
        self.file = file

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: {self.message}"
