"""The NC check run on every upload: the NC kernel's own checker, per machine kind."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from functools import cache
from typing import IO, Any

MAX_STORED_ERRORS = 100
KIND_TO_MACHINE = {"mill": "mill3", "lathe": "lathe2", "mill5": "mill5"}
UNBOUNDED_MM = 1e9


@cache
def _params(machine_kind: str):
    from cnc.config import builtin_machine

    params = builtin_machine(KIND_TO_MACHINE.get(machine_kind, "mill3")).params
    # The host does not know the machines' work offsets (G54..G59 are set at the machine),
    # so soft limits in machine coordinates cannot be judged here; the machine checks them
    # when the program is loaded. Everything else (syntax, modal groups, arcs, F, cutter
    # compensation, subprograms) is checked exactly as the machine will.
    axes = tuple(
        dataclasses.replace(a, min_mm=-UNBOUNDED_MM, max_mm=UNBOUNDED_MM) for a in params.axes
    )
    return dataclasses.replace(params, axes=axes)


def nc_checker(
    text: str | IO[str], machine_kind: str, *, programs: Mapping[int, str] | None = None
) -> list[dict[str, Any]]:
    """Errors as plain data ({line, col, message}) for storing with the revision. `text`
    may be an open text file (its path as `name`): its lines are read as the check goes,
    never all at once (a 15 MB program as a list of lines is some 60 MB).

    `programs` answers the calls (M98 P, G65 P, G66 P) by O number (the library's
    programs, dnc.dependencies.LibraryPrograms); an error inside a called program names it
    (`(in O1002)`, its own line and column). A program whose last block is M99 is checked
    as a subprogram."""
    from cnc.interp import check

    lines = text.splitlines() if isinstance(text, str) else text
    errors = check(lines, _params(machine_kind), file="program", programs=programs)
    return [
        {"line": e.line, "col": e.col,
         "message": e.message if e.file == "program" else f"{e.message} (in {e.file})"}
        for e in errors[:MAX_STORED_ERRORS]
    ]  # fmt: skip


nc_checker.reads_files = True  # type: ignore[attr-defined]  # Library hands it uploads as files
nc_checker.resolves_calls = True  # type: ignore[attr-defined]  # and the library's programs
