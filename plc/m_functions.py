"""A machine's M-code table: the M functions its PLC handles besides the standard program's.

The table (the machine configuration's `plc.m_codes`, docs/machine_plc.md) declares for
each M code how long the function takes and, optionally, a PLC bit it switches on or off
(`sets` / `clears`: a chip conveyor, a brake, an air blast...). It is compiled into the PLC
program as ladder rungs (`with_m_functions`): the rungs run where the program marks the slot
(a comment line `// @m-functions` before a rung), each code starts its own on-delay timer on
the M strobe, and the program reads two bits:

    MTabKnown   MCode is a code of the table (the unknown-code alarm 1021 spares it)
    MTabDone    the timer of the strobed code has run its time (the finish may be given)

so a table function finishes `ms` after the strobe (at the earliest with the program's own
50 ms check delay) and a code in no table is still alarm 1021. The NC reads the same table
(cnc.config -> MachineParams.plc_m_codes): an M code neither the NC's own nor the PLC's is
refused at its block, with line and column, before anything is handed over.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from plc.errors import PlcError
from plc.ladder.ast import Program
from plc.ladder.parser import parse_program

SLOT = "@m-functions"  # the comment marking where the table's rungs run
# M codes the NC kernel handles itself or the standard program decodes: not table codes
RESERVED = frozenset((0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 14, 19, 30, 98, 99))
# the standard program's own M codes that reach the PLC as plain M functions (M13/M14)
STANDARD_EXTRA = frozenset((13, 14))
MAX_CODE = 9999
MAX_MS = 29_000  # under the program's 30 s M-finish supervision (alarm 1020)
_TAG = re.compile(r"[A-Za-z_][A-Za-z0-9_]*$")


class MTableError(PlcError, ValueError):
    """A table entry that cannot be compiled; `where` names the entry (e.g. `m_codes.31.ms`)."""

    def __init__(self, where: str, message: str) -> None:
        super().__init__(f"{where}: {message}")
        self.where = where
        self.message = message


@dataclass(frozen=True, slots=True)
class MFunction:
    """One M function of the table: `code`, its time `ms`, a text, the bit it sets/clears."""

    code: int
    ms: int
    text: str = ""
    sets: str | None = None
    clears: str | None = None


def table_from(entries: Mapping[int, Mapping[str, object]]) -> tuple[MFunction, ...]:
    """The table from configuration entries {code: {ms, text, sets, clears}}, checked."""
    out = []
    for code, entry in sorted(entries.items()):
        where = f"m_codes.{code}"
        if not isinstance(code, int) or not 0 <= code <= MAX_CODE:
            raise MTableError(where, f"an M code is 0..{MAX_CODE}")
        if code in RESERVED:
            raise MTableError(where, f"M{code} is handled by the NC or the standard PLC program")
        ms = entry.get("ms", 0)
        if not isinstance(ms, int) or isinstance(ms, bool) or not 0 <= ms <= MAX_MS:
            raise MTableError(f"{where}.ms", f"the function's time is 0..{MAX_MS} ms (an integer)")
        for key in ("sets", "clears"):
            name = entry.get(key)
            if name is not None and (not isinstance(name, str) or not _TAG.match(name)):
                raise MTableError(f"{where}.{key}", f"{name!r} is not a PLC tag name")
        sets, clears = entry.get("sets"), entry.get("clears")
        out.append(MFunction(code, ms, str(entry.get("text", "")), sets, clears))  # type: ignore[arg-type]
    return tuple(out)


def section_text(table: tuple[MFunction, ...], declared: frozenset[str] = frozenset()) -> str:
    """The ladder text of the table: its tags (bits not in `declared`, one timer per code)
    and its rungs (timers, the bits set/cleared on the strobe, MTabKnown, MTabDone)."""
    lines = ["PROGRAM m_functions"]
    bits = sorted({n for f in table for n in (f.sets, f.clears) if n} - declared)
    lines += [f"TAG {n} : BOOL  // switched by the M-code table" for n in bits]
    lines += [f"TAG TmrM{f.code} : TIMER  // M{f.code} {f.text}" for f in table]
    for f in table:
        lines.append(f"// M{f.code}: {f.text} ({f.ms} ms)")
        lines.append(f"XIC MStrobe EQU MCode {f.code} TON TmrM{f.code} {f.ms}")
        if f.sets:
            lines.append(f"XIC MStrobe EQU MCode {f.code} OTL {f.sets}")
        if f.clears:
            lines.append(f"XIC MStrobe EQU MCode {f.code} OTU {f.clears}")
    known = " NXB ".join(f"EQU MCode {f.code}" for f in table)
    done = " NXB ".join(f"XIC TmrM{f.code}.DN" for f in table)
    lines.append(f"BST {known} BND OTE MTabKnown")
    lines.append(f"XIC MStrobe BST {done} BND OTE MTabDone")
    return "\n".join(lines) + "\n"


def with_m_functions(program: Program, table: tuple[MFunction, ...]) -> Program:
    """`program` with the table's tags and rungs put in at its `// @m-functions` slot."""
    if not table:
        return program
    at = next((i for i, r in enumerate(program.rungs) if r.comment and SLOT in r.comment), None)
    if at is None:
        raise MTableError(
            "m_codes",
            f"the PLC program {program.file} has no '// {SLOT}' comment line marking where"
            " the M-code table's rungs run",
        )
    declared = frozenset(t.name for t in program.tags)
    section, sink = parse_program(section_text(table, declared), f"{program.file} (m_codes)")
    if sink.has_errors:  # pragma: no cover - the text above is generated from checked entries
        raise MTableError("m_codes", "; ".join(str(d) for d in sink.sorted()))
    rungs = program.rungs[:at] + section.rungs + program.rungs[at:]
    for i, rung in enumerate(rungs):
        rung.number = i
    return Program(program.name, program.file, program.tags + section.tags, rungs, program.alarms)
