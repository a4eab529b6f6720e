"""The ladder program as parsed: tag declarations and rungs of instructions and branches.

The same tree comes out of the text parser and the PLCopen TC6 importer, so both feed one
checker and one compiler. `format_program` writes it back as neutral text.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

OperandKind = Literal["address", "tag", "int", "time"]
TagType = Literal["BOOL", "INT", "TIMER", "COUNTER"]


@dataclass(frozen=True, slots=True)
class Operand:
    """One operand as written: `%IX0.0`, `Start`, `Tmr.DN`, `-5`, `T#5s` (value in ms)."""

    kind: OperandKind
    text: str
    line: int
    col: int
    value: int | None = None  # for int and time literals


@dataclass(slots=True)
class Instr:
    mnemonic: str
    operands: list[Operand]
    line: int
    col: int


@dataclass(slots=True)
class Branch:
    """`BST leg NXB leg ... BND`: the legs are in parallel (OR of their power flows)."""

    legs: list[list[Element]]
    line: int
    col: int


Element = Instr | Branch


@dataclass(slots=True)
class Rung:
    number: int  # 0-based position in the program
    elements: list[Element]
    line: int
    col: int
    comment: str = ""


@dataclass(slots=True)
class TagDecl:
    name: str
    type: TagType
    line: int
    col: int
    address: Operand | None = None
    retain: bool = False
    init: int | None = None
    comment: str = ""


@dataclass(slots=True)
class AlarmDecl:
    """`ALARM number tag "text"`: the runtime shows alarm `number` while `tag` is 1."""

    number: int
    tag: Operand
    text: str
    line: int
    col: int


@dataclass(slots=True)
class Program:
    name: str
    file: str
    tags: list[TagDecl] = field(default_factory=list)
    rungs: list[Rung] = field(default_factory=list)
    alarms: list[AlarmDecl] = field(default_factory=list)


def format_elements(elements: list[Element]) -> str:
    parts: list[str] = []
    for el in elements:
        if isinstance(el, Branch):
            legs = [format_elements(leg) for leg in el.legs]
            parts.append("BST " + " NXB ".join(legs) + " BND")
        else:
            parts.append(" ".join([el.mnemonic, *(op.text for op in el.operands)]))
    return " ".join(parts)


def format_program(program: Program) -> str:
    """The program as neutral text that `parse_program` reads back to the same tree."""
    out = [f"PROGRAM {program.name}", ""]
    for t in program.tags:
        line = f"TAG {t.name} : {t.type}"
        if t.address is not None:
            line += f" AT {t.address.text}"
        if t.retain:
            line += " RETAIN"
        if t.init is not None:
            line += f" := {t.init}"
        if t.comment:
            line += f"  // {t.comment}"
        out.append(line)
    for a in program.alarms:
        out.append(f'ALARM {a.number} {a.tag.text} "{a.text}"')
    out.append("")
    for r in program.rungs:
        if r.comment:
            out.extend(f"// {c}" for c in r.comment.splitlines())
        out.append(format_elements(r.elements))
    return "\n".join(out) + "\n"
