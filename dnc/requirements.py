"""What a program needs of a machine, and which machines have it (pure; no database).

A job's parts may go only to machines that can run its program. The upload check knows
what the program needs (dnc/checker.py): the machine kinds it is for (a G-code program:
its program's kind; an APT or CL source: the kinds it was trial-posted for) and the axes
a machine must have (the kind's linear axes and every rotary axis a block moves: a mill
program with A words needs a mill4's rotary table, not a mill3). A machine offers its
kind and its configured axes. `refusal` says why a machine cannot run a program, in the
words an integrator checks a cell file against; the scheduler allocates only to machines
it finds nothing against, and a job whose program no machine of the cell can run is
refused when it is created (dnc/jobs.py).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class Needs:
    """What a machine must be and have to run a program."""

    kinds: tuple[str, ...]  # the machine kinds it is for (one of them)
    axes: tuple[str, ...] = ()  # every one of them; () = not known (judged by kind alone)

    def met_by(self, kind: str, axes: tuple[str, ...]) -> bool:
        """`refusal` without its reason (the scheduler asks it per job and machine)."""
        return kind in self.kinds and (not axes or all(a in axes for a in self.axes))

    def as_data(self) -> dict[str, list[str]]:
        return {"kinds": list(self.kinds), "axes": list(self.axes)}

    @classmethod
    def from_data(cls, data: Mapping[str, Any] | None, kind: str) -> Needs:
        """From the stored form; None (a job queued before the host knew needs) is the
        job's machine kind alone, as the scheduler judged it then."""
        if not data:
            return cls((kind,))
        return cls(tuple(data.get("kinds") or (kind,)), tuple(data.get("axes") or ()))


@dataclass(frozen=True, slots=True)
class Offer:
    """What a machine is and has: its name, kind and configured axes (() = not known)."""

    name: str
    kind: str
    axes: tuple[str, ...] = ()


def revision_needs(
    revision_kind: str,
    program_kind: str,
    post_kinds: Iterable[str] | None,
    axes: Iterable[str] | None,
    called_axes: Iterable[Iterable[str] | None] = (),
) -> Needs:
    """A released revision's needs from what its upload check stored.

    G-code: its program's kind, its axes and those of the programs it calls (a subprogram
    turning the A axis needs it as much as the caller). APT/CL: the kinds it was
    trial-posted for (each post writes the axes of its kind's machines, checked then);
    no axis beyond the kind's. A revision whose axes are not known (None) needs its kind."""
    if revision_kind != "gcode":
        return Needs(tuple(post_kinds or ()) or (program_kind,))
    if axes is None:
        return Needs((program_kind,))
    union = list(axes)
    for more in called_axes:
        for a in more or ():
            if a not in union:
                union.append(a)
    return Needs((program_kind,), tuple(_ordered(union)))


def refusal(needs: Needs, machine: Offer) -> str | None:
    """Why `machine` cannot run a program with `needs`; None when it can (or when its
    axes are not known: then only its kind is judged, and its own check at loading is
    the last word)."""
    if needs.met_by(machine.kind, machine.axes):
        return None
    if machine.kind not in needs.kinds:
        return f"{machine.name} is a {machine.kind}; the program is for {_kinds(needs.kinds)}"
    missing = [a for a in needs.axes if a not in machine.axes]
    return (
        f"{machine.name} has axes {' '.join(machine.axes)}; the program needs {' '.join(missing)}"
    )


def runnable_on(needs: Needs, machines: Iterable[Offer]) -> list[str]:
    """The names of the machines that can run it, in the order given."""
    return [m.name for m in machines if refusal(needs, m) is None]


def why_none(needs: Needs, machines: Iterable[Offer]) -> str:
    """One sentence for a program no machine can run: each machine's reason."""
    reasons = [r for m in machines if (r := refusal(needs, m)) is not None]
    if not reasons:
        return "the cell has no machines"
    return "no machine of the cell can run it: " + "; ".join(reasons)


_ORDER = "XYZUVWABC"


def _ordered(axes: Iterable[str]) -> list[str]:
    # linear before rotary, as machines list them (X Y Z A, X Y Z B C)
    return sorted(set(axes), key=lambda a: (_ORDER.find(a) if a in _ORDER else 99, a))


def _kinds(kinds: tuple[str, ...]) -> str:
    return " or ".join(f"{k} machines" for k in kinds) if kinds else "no machine kind"
