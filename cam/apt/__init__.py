"""The APT processor (seed 004 §3-§6): lexer, parser and evaluator producing CL records."""

from cam.apt.evaluator import Processor, process

__all__ = ["Processor", "process"]
