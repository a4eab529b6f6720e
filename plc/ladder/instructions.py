"""The instruction set: mnemonic -> position in the rung and operand kinds.

Operand kinds:
    bit     a bit to read: BOOL tag, %IX/%QX/%MX, timer/counter status member (.DN ...)
    bit_w   a bit to write: BOOL tag, %QX/%MX (inputs are never written by logic)
    word    a word to read: INT tag, %IW/%QW/%MW, .ACC/.PRE member, or an INT literal
    word_w  a word to write: INT tag, %QW/%MW, .ACC member
    preset  a timer preset in ms: literal (`5000`, `T#5s`) or a word to read
    timer   a TIMER tag;  counter  a COUNTER tag;  tc  a TIMER or COUNTER tag
    label   a jump label name
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Position = Literal["input", "output"]


@dataclass(frozen=True, slots=True)
class InstrSpec:
    mnemonic: str
    position: Position
    operands: tuple[str, ...]
    summary: str
    cost_ns: int  # conservative execution cost for the scan-time estimate


def _spec(m: str, pos: Position, ops: tuple[str, ...], summary: str, cost: int) -> InstrSpec:
    return InstrSpec(m, pos, ops, summary, cost)


INSTRUCTIONS: dict[str, InstrSpec] = {
    s.mnemonic: s
    for s in (
        _spec("XIC", "input", ("bit",), "examine if closed: passes power when the bit is 1", 60),
        _spec("XIO", "input", ("bit",), "examine if open: passes power when the bit is 0", 60),
        _spec(
            "ONS", "input", ("bit_w",), "one-shot: passes power for one scan on a rising rung", 150
        ),
        _spec("EQU", "input", ("word", "word"), "A == B", 80),
        _spec("NEQ", "input", ("word", "word"), "A != B", 80),
        _spec("LES", "input", ("word", "word"), "A < B", 80),
        _spec("LEQ", "input", ("word", "word"), "A <= B", 80),
        _spec("GRT", "input", ("word", "word"), "A > B", 80),
        _spec("GEQ", "input", ("word", "word"), "A >= B", 80),
        _spec(
            "LIM",
            "input",
            ("word", "word", "word"),
            "low <= test <= high (wraps if low > high)",
            300,
        ),
        _spec("LBL", "input", ("label",), "jump target; must start its rung", 0),
        _spec("OTE", "output", ("bit_w",), "output energize: bit = rung", 80),
        _spec("OTL", "output", ("bit_w",), "output latch: set the bit while the rung is true", 80),
        _spec(
            "OTU", "output", ("bit_w",), "output unlatch: clear the bit while the rung is true", 80
        ),
        _spec("OTN", "output", ("bit_w",), "output not (negated coil): bit = NOT rung", 80),
        _spec(
            "OSR", "output", ("bit_w", "bit_w"), "one-shot rising: output bit 1 for one scan", 200
        ),
        _spec(
            "OSF", "output", ("bit_w", "bit_w"), "one-shot falling: output bit 1 for one scan", 200
        ),
        _spec("TON", "output", ("timer", "preset"), "timer on delay (ms)", 600),
        _spec("TOF", "output", ("timer", "preset"), "timer off delay (ms)", 600),
        _spec("RTO", "output", ("timer", "preset"), "retentive timer on (ms)", 600),
        _spec("CTU", "output", ("counter", "word"), "count up on each rising rung", 500),
        _spec("CTD", "output", ("counter", "word"), "count down on each rising rung", 500),
        _spec("RES", "output", ("tc",), "reset a timer or counter", 300),
        _spec("ADD", "output", ("word", "word", "word_w"), "dest = A + B", 400),
        _spec("SUB", "output", ("word", "word", "word_w"), "dest = A - B", 400),
        _spec("MUL", "output", ("word", "word", "word_w"), "dest = A * B", 400),
        _spec("DIV", "output", ("word", "word", "word_w"), "dest = A / B (truncated)", 800),
        _spec("MOD", "output", ("word", "word", "word_w"), "dest = A MOD B (sign of A)", 800),
        _spec("MOV", "output", ("word", "word_w"), "dest = source", 150),
        _spec("JMP", "output", ("label",), "skip forward to the rung starting with LBL", 100),
    )
}

# Words with a meaning of their own in the text; they cannot name a tag. (ALARM only starts
# a statement, where a rung never has a tag, so "Alarm" stays a valid tag name.)
KEYWORDS = frozenset(
    {
        "TAG",
        "PROGRAM",
        "AT",
        "RETAIN",
        "BST",
        "NXB",
        "BND",
        "SOR",
        "EOR",
        "BOOL",
        "INT",
        "TIMER",
        "COUNTER",
        "TRUE",
        "FALSE",
    }
) | frozenset(INSTRUCTIONS)

TIMER_MEMBERS = {
    "EN": "bit",
    "TT": "bit",
    "DN": "bit",
    "Q": "bit",
    "ACC": "word",
    "ET": "word",
    "PRE": "word",
    "PT": "word",
}
COUNTER_MEMBERS = {
    "CU": "bit",
    "CD": "bit",
    "DN": "bit",
    "Q": "bit",
    "OV": "bit",
    "UN": "bit",
    "ACC": "word",
    "CV": "word",
    "PRE": "word",
    "PV": "word",
}
# IEC names are aliases of the Rockwell-style members.
MEMBER_ALIASES = {"Q": "DN", "ET": "ACC", "CV": "ACC", "PT": "PRE", "PV": "PRE"}
TIMER_SLOTS = ("EN", "TT", "DN", "ACC", "PRE")
COUNTER_SLOTS = ("CU", "CD", "DN", "OV", "UN", "ACC", "PRE")
