"""The NC check run on every upload: the NC kernel's own checker, per machine kind.

A kind's machines may differ in their axes (a cell's mills: mill3's X Y Z, mill4's X Y Z
and rotary table A), so an upload is checked with the axes of every shipped machine of
its kind (the widest: mill4 for `mill`); a dispatch then checks the program against the
machine it goes to (`machine_check`), and a program with an A word sent to a mill without
one is refused there with its line and why.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from functools import cache
from typing import IO, Any

from cnc.interp import check

MAX_STORED_ERRORS = 100
UNBOUNDED_MM = 1e9


@cache
def _params(machine_kind: str):
    # deferred: the configuration is not loaded for `fmscell --help` (start-up cost)
    from cnc.config import SHIPPED_MACHINES, builtin_machine

    shipped = [builtin_machine(n) for n in SHIPPED_MACHINES]
    of_kind = [c for c in shipped if c.kind == machine_kind] or [builtin_machine("mill3")]
    widest = max(of_kind, key=lambda c: len(c.axes))  # mill4 for mill: X Y Z and A
    return _unbounded(widest.params)


def _unbounded(params):
    # The host does not know the machines' work offsets (G54..G59 are set at the machine),
    # so soft limits in machine coordinates cannot be judged here; the machine checks them
    # when the program is loaded. Everything else (syntax, modal groups, arcs, F, cutter
    # compensation, subprograms) is checked exactly as the machine will.
    axes = tuple(
        dataclasses.replace(a, min_mm=-UNBOUNDED_MM, max_mm=UNBOUNDED_MM) for a in params.axes
    )
    return dataclasses.replace(params, axes=axes)


def kind_axes(machine_kind: str) -> tuple[str, ...]:
    """The axes an upload for the kind may program (those of its widest shipped machine)."""
    return tuple(a.name for a in _params(machine_kind).axes)


def machine_check(
    text: str, machine_kind: str, config: Any, *, programs: Mapping[int, str] | None = None
) -> list[dict[str, Any]]:
    """Errors of a G-code program of `machine_kind` (it passed the upload check) on one
    machine of the kind, `config` its `cnc.config.MachineConfig`: the NC check with the
    machine's own axes, run only when the machine lacks an axis the kind has and the text
    names that axis' address at all (a mill3 and an A word); [] otherwise."""
    missing = [a for a in kind_axes(machine_kind) if a not in config.axes]
    if not missing or not re.search(f"[{''.join(missing)}]\\s*[-+.\\d#\\[]", text, re.IGNORECASE):
        return []
    errors = check(text.splitlines(), _unbounded(config.params), file="program",
                   programs=programs)  # fmt: skip
    return _as_data(errors)


class Findings(list):
    """The upload check's errors (a list of {line, col, message}) and what the program
    needs of a machine: `axes`, the kind's linear axes and every rotary axis a block moves
    or sets (a macro call's argument A is none), its called programs' included
    (dnc/requirements.py); None when not known."""

    axes: tuple[str, ...] | None = None


def linear_axes(machine_kind: str) -> tuple[str, ...]:
    """The axes every machine of the kind has (its kinematics fix them: mill X Y Z,
    lathe X Z); the rotary axes (mill4's A) are the machine's own."""
    params = _params(machine_kind)
    rotary = {a.name for a in params.rotary_axes}
    return tuple(a.name for a in params.axes if a.name not in rotary)


def needed_axes(
    text: str, machine_kind: str, *, programs: Mapping[int, str] | None = None
) -> tuple[str, ...]:
    """The axes a machine needs to run a G-code program of the kind (see `Findings`):
    the NC check runs only when the text names one of the kind's rotary addresses."""
    rotary = "".join(a.name for a in _params(machine_kind).rotary_axes)
    if not rotary or not re.search(f"[{rotary}]\\s*[-+.\\d#\\[]", text, re.IGNORECASE):
        return linear_axes(machine_kind)
    return nc_checker(text, machine_kind, programs=programs).axes or linear_axes(machine_kind)


def nc_checker(
    text: str | IO[str], machine_kind: str, *, programs: Mapping[int, str] | None = None
) -> Findings:
    """Errors as plain data ({line, col, message}) for storing with the revision. `text`
    may be an open text file (its path as `name`): its lines are read as the check goes,
    never all at once (a 15 MB program as a list of lines is some 60 MB).

    `programs` answers the calls (M98 P, G65 P, G66 P) by O number (the library's
    programs, dnc.dependencies.LibraryPrograms); an error inside a called program names it
    (`(in O1002)`, its own line and column). A program whose last block is M99 is checked
    as a subprogram."""
    lines = text.splitlines() if isinstance(text, str) else text
    params = _params(machine_kind)
    named: set[str] = set()
    found = _as_data(check(lines, params, file="program", programs=programs, rotary_named=named))
    found.axes = (*linear_axes(machine_kind), *(a.name for a in params.rotary_axes
                                                if a.name in named))  # fmt: skip
    return found


def _as_data(errors) -> Findings:
    return Findings(
        {"line": e.line, "col": e.col,
         "message": e.message if e.file == "program" else f"{e.message} (in {e.file})"}
        for e in errors[:MAX_STORED_ERRORS]
    )  # fmt: skip


nc_checker.reads_files = True  # type: ignore[attr-defined]  # Library hands it uploads as files
nc_checker.resolves_calls = True  # type: ignore[attr-defined]  # and the library's programs
