"""IEC 61131-3 standard functions in a PLCopen LD body, lowered to ladder instructions.

A function (a `block` without an instance name) is called when its EN input carries power
(always, when EN is not wired). OpenPLC's generated code assigns a function's OUT to the
variables wired to it only when ENO is true; ENO equals EN here (no function raises an error
that clears ENO: a division by zero sets S_DIV_ZERO as the DIV instruction does).

Value results (MOVE, arithmetic, selection) go to a hidden INT tag `_F<localId>` that the
block's rungs write and its readers read. Comparisons give a BOOL: they become input
instructions (`GRT`, `EQU`, ...) inline in the power flow of whatever they feed, so they need
no rung of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Kind = Literal["compare", "arith", "move", "select"]


@dataclass(frozen=True, slots=True)
class FunctionSpec:
    name: str
    kind: Kind
    inputs: tuple[str, ...]  # formal inputs in call order; "IN*" = extensible IN1, IN2, ...
    mnemonic: str = ""  # the ladder instruction it lowers to, where there is one


def _extensible(name: str, kind: Kind, mnemonic: str) -> FunctionSpec:
    return FunctionSpec(name, kind, ("IN*",), mnemonic)


STANDARD_FUNCTIONS: dict[str, FunctionSpec] = {
    s.name: s
    for s in (
        FunctionSpec("MOVE", "move", ("IN",), "MOV"),
        # comparison: extensible except NE; GT(a, b, c) = a > b AND b > c (IEC 61131-3 2.5.1.5.5)
        _extensible("GT", "compare", "GRT"),
        _extensible("GE", "compare", "GEQ"),
        _extensible("EQ", "compare", "EQU"),
        _extensible("LE", "compare", "LEQ"),
        _extensible("LT", "compare", "LES"),
        FunctionSpec("NE", "compare", ("IN1", "IN2"), "NEQ"),
        # arithmetic: ADD and MUL are extensible
        _extensible("ADD", "arith", "ADD"),
        _extensible("MUL", "arith", "MUL"),
        FunctionSpec("SUB", "arith", ("IN1", "IN2"), "SUB"),
        FunctionSpec("DIV", "arith", ("IN1", "IN2"), "DIV"),
        FunctionSpec("MOD", "arith", ("IN1", "IN2"), "MOD"),
        # selection
        FunctionSpec("SEL", "select", ("G", "IN0", "IN1")),
        _extensible("MAX", "select", "GRT"),
        _extensible("MIN", "select", "LES"),
        FunctionSpec("LIMIT", "select", ("MN", "IN", "MX")),
        FunctionSpec("MUX", "select", ("K", "IN*")),
    )
}

FUNCTION_BLOCKS = ("TON", "TOF", "CTU")


def supported_blocks_text() -> str:
    """The list an 'unsupported block' error names."""
    return (
        "function blocks "
        + ", ".join(FUNCTION_BLOCKS)
        + " and the standard functions "
        + ", ".join(STANDARD_FUNCTIONS)
    )


def formal_inputs(spec: FunctionSpec, wired: list[str]) -> list[str]:
    """The formal inputs a call uses, in order: extensible `IN*` expands to the wired
    IN1, IN2, ... (MUX: IN0, IN1, ...) in numeric order."""
    out: list[str] = []
    for formal in spec.inputs:
        if formal != "IN*":
            out.append(formal)
            continue
        numbered = sorted(
            (f for f in wired if f.startswith("IN") and f[2:].isdigit()), key=lambda f: int(f[2:])
        )
        out.extend(numbered)
    return out
