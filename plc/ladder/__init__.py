"""Ladder language: neutral-text parser, PLCopen TC6 import, checker and compiler.

Public API::

    compile_text(text, file, size=None, watchdog_ms=None) -> CompiledProgram
    load_file(path, size=None, watchdog_ms=None) -> CompiledProgram   (.xml = PLCopen TC6)
    check_text(text, file, size=None, watchdog_ms=None) -> list[Diagnostic]
    check_file(path, size=None, watchdog_ms=None) -> list[Diagnostic]
    parse_program(text, file) -> (Program, DiagnosticSink)
    import_plcopen(path_or_text, file=None, pou=None) -> (Program, DiagnosticSink)
    format_program(Program) -> str           (neutral text export)
"""

from __future__ import annotations

from plc.image import ImageSize
from plc.ladder.ast import Program, format_program
from plc.ladder.compiler import (
    CompiledProgram,
    RungInfo,
    TagInfo,
    check_program,
    check_text,
    compile_program,
    compile_text,
    load_file,
)
from plc.ladder.diagnostics import Diagnostic, LadderError
from plc.ladder.parser import parse_program


def check_file(
    path: str, size: ImageSize | None = None, watchdog_ms: float | None = None
) -> list[Diagnostic]:
    """Every diagnostic for a program file (`.xml` = PLCopen TC6, else neutral text)."""
    if str(path).lower().endswith(".xml"):
        # deferred: the PLCopen importer (and expat) only for .xml programs: start-up cost
        from plc.ladder.plcopen import import_plcopen

        program, sink = import_plcopen(path)
        return check_program(program, sink, size, watchdog_ms)
    with open(path, encoding="utf-8") as f:
        return check_text(f.read(), str(path), size, watchdog_ms)


def import_plcopen(source: str, file: str | None = None, pou: str | None = None):
    """Import a PLCopen TC6 XML project's LD body: the first program POU, or the POU named
    `pou` (lazy import keeps startup fast)."""
    from plc.ladder.plcopen import import_plcopen as _imp  # deferred: as in check_file

    return _imp(source, file, pou)


__all__ = [
    "CompiledProgram",
    "Diagnostic",
    "LadderError",
    "Program",
    "RungInfo",
    "TagInfo",
    "check_file",
    "check_program",
    "check_text",
    "compile_program",
    "compile_text",
    "format_program",
    "import_plcopen",
    "load_file",
    "parse_program",
]
