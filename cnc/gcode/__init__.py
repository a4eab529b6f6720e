"""Streaming lexer for the ISO 6983 / DIN 66025 / Fanuc word-address format."""

from cnc.gcode.lexer import Block, blank_comments, find_col, parse_line
from cnc.gcode.source import ProgramLibrary, main_lines

__all__ = ["Block", "ProgramLibrary", "blank_comments", "find_col", "main_lines", "parse_line"]
