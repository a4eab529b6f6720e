"""Diagnostics: every complaint about a program names its file, line, column and reason."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from plc.errors import PlcError

Severity = Literal["error", "warning"]


@dataclass(frozen=True, slots=True)
class Diagnostic:
    """One error or warning at `file:line:col` (line and column count from 1)."""

    file: str
    line: int
    col: int
    severity: Severity
    message: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: {self.severity}: {self.message}"


class LadderError(PlcError):
    """Raised when a program has errors; `diagnostics` holds all of them (warnings too)."""

    def __init__(self, diagnostics: list[Diagnostic]) -> None:
        self.diagnostics = diagnostics
        errors = [d for d in diagnostics if d.severity == "error"]
        super().__init__("\n".join(str(d) for d in errors) or "ladder program rejected")

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity == "error"]


class DiagnosticSink:
    """Collects diagnostics for one file so a pass can report many problems in one go."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.items: list[Diagnostic] = []

    def error(self, line: int, col: int, message: str) -> None:
        self.items.append(Diagnostic(self.file, line, col, "error", message))

    def warning(self, line: int, col: int, message: str) -> None:
        self.items.append(Diagnostic(self.file, line, col, "warning", message))

    @property
    def has_errors(self) -> bool:
        return any(d.severity == "error" for d in self.items)

    def sorted(self) -> list[Diagnostic]:
        return sorted(self.items, key=lambda d: (d.line, d.col, d.severity))
