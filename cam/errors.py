"""Errors and warnings of the CAM chain: always file, line, column and why.

CamError is the package's one root: every error the cam package raises is a CamError, so a
user of the CAM chain alone (APT processor, CL reader, posts) catches one class. Its
subclasses keep the builtin base they had (ValueError for a geometry without a solution),
so existing handlers still see them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


class CamError(Exception):
    """APT source, CL data or a post that cannot be processed; the root of the package's
    errors.

    `line` and `col` are 1-based (0 when not applicable); `str(err)` is the
    `FILE:LINE:COL: message` form the command line prints, as the NC kernel's errors.
    """

    def __init__(self, message: str, line: int = 0, col: int = 0, file: str = "<input>") -> None:
        super().__init__(message)
        self.message = message
        self.line = line
        self.col = col
        self.file = file

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: {self.message}"


@dataclass(frozen=True, slots=True)
class CamWarning:
    """Something accepted but changed or doubtful (a normalised tool vector, a singular
    orientation): reported, never silent."""

    message: str
    line: int = 0
    col: int = 0
    file: str = "<input>"

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: warning: {self.message}"


WarningSink = Callable[[CamWarning], None]


def ignore_warning(_w: CamWarning) -> None:
    """The default sink: warnings dropped (callers that care pass a list's append)."""
