"""Dispatch rules: which waiting job an idle machine takes next.

Pure functions over plain data. Each rule orders the candidate jobs and explains its choice,
so every dispatch decision is recorded with a reason a production planner can read.
Priority classes come first under every rule (a rush job beats any rule); the rule orders
within a class; the job id breaks ties, so decisions are deterministic.

A setup-aware rule (`setup_aware = True`) is also told which program the candidate machine
holds (`held`: its selected program, else the program of its last allocation; None =
unknown); the scheduler asks it once per class of machine and program held, where it asks
the others once per class of machine.
A new rule is a function (or, setup-aware, a small class) and one row in `RULES`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import ClassVar


@dataclass(frozen=True, slots=True)
class JobView:
    id: int
    priority: int  # higher first
    created_at: datetime
    due_at: datetime | None
    remaining: int  # parts still to make
    cycle_time_s: float  # estimated time per part
    program: str | None = None  # O1234: the job's program (what a setup-aware rule matches)

    @property
    def processing_time_s(self) -> float:
        return self.cycle_time_s * self.remaining


@dataclass(frozen=True, slots=True)
class Ranked:
    job: JobView
    key: float
    explain: Callable[[JobView, float], str] = field(repr=False, compare=False)

    @property
    def reason(self) -> str:
        """Written when asked: a tick ranks every waiting job but records only the chosen."""
        prefix = f"priority {self.job.priority}; " if self.job.priority else ""
        return prefix + self.explain(self.job, self.key)


Rule = Callable[[list[JobView], datetime], list[Ranked]]
_FAR_FUTURE = float("inf")


def fifo(jobs: list[JobView], now: datetime) -> list[Ranked]:
    return _rank(
        jobs,
        lambda j: j.created_at.timestamp(),
        lambda j, k: f"FIFO: queued {j.created_at.isoformat()}",
    )


def spt(jobs: list[JobView], now: datetime) -> list[Ranked]:
    return _rank(
        jobs,
        lambda j: j.processing_time_s,
        lambda j, k: (
            f"SPT: remaining processing time {k:.1f} s ({j.remaining} x {j.cycle_time_s:.1f} s)"
        ),
    )


def edd(jobs: list[JobView], now: datetime) -> list[Ranked]:
    return _rank(
        jobs,
        lambda j: j.due_at.timestamp() if j.due_at else _FAR_FUTURE,
        lambda j, k: f"EDD: due {j.due_at.isoformat() if j.due_at else 'never'}",
    )


def critical_ratio(jobs: list[JobView], now: datetime) -> list[Ranked]:
    """CR = time until due / remaining processing time; below 1 the job is already late."""

    def ratio(j: JobView) -> float:
        if j.due_at is None:
            return _FAR_FUTURE
        slack = (j.due_at - now).total_seconds()
        return slack / j.processing_time_s if j.processing_time_s > 0 else slack

    return _rank(
        jobs, ratio, lambda j, k: f"CR: critical ratio {k:.3g}" + (" (late)" if k < 1 else "")
    )


@dataclass(frozen=True, slots=True)
class SameProgramFirst:
    """For a free machine, the jobs whose program the machine already holds come first (its
    fixture and tools are set up for it), then the rest; `then` orders each group (default
    FIFO).

    A machine that holds no waiting job's program, or whose program is unknown, gets
    exactly `then`'s order. Priority classes still come first."""

    then: Rule = fifo
    setup_aware: ClassVar[bool] = True

    def __call__(self, jobs: list[JobView], now: datetime, held: str | None = None) -> list[Ranked]:
        # one reason-writer per (setup case, base reason), not one per job: a tick ranks a
        # thousand jobs and records the reason of the one chosen
        why: dict[tuple, Callable[[JobView, float], str]] = {}
        ranked = []
        for r in self.then(jobs, now):
            case = (_setup(held, r.job.program), r.explain)
            if case not in why:
                why[case] = _prefixed(*case)
            ranked.append(Ranked(r.job, r.key, why[case]))
        if held is not None:
            # stable: the base rule's order stays within each priority class and each group
            ranked.sort(key=lambda r: (-r.job.priority, r.job.program != held))
        return ranked


RULES: dict[str, Rule] = {
    "fifo": fifo,
    "spt": spt,
    "edd": edd,
    "cr": critical_ratio,
    "same_program_first": SameProgramFirst(),
}
THEN = " then "  # `same_program_first then edd`: a setup-aware rule and the rule it falls back to


def rule_named(name: str) -> Rule:
    """The rule called `name`, or `SETUP_RULE then BASE_RULE` (e.g. `same_program_first then
    edd`: the setup-aware rule falling back to BASE_RULE instead of its default)."""
    head, sep, base = name.lower().partition(THEN)
    rule = _named(head, name)
    if not sep:
        return rule
    if not getattr(rule, "setup_aware", False):
        aware = [n for n, r in RULES.items() if getattr(r, "setup_aware", False)]
        raise ValueError(
            f"dispatch rule {name!r}: only a setup-aware rule ({', '.join(aware)}) falls back"
            f" to another with 'then'"
        )
    fallback = _named(base.strip(), name)
    if getattr(fallback, "setup_aware", False):
        raise ValueError(f"dispatch rule {name!r}: the rule after 'then' must be one of {_plain()}")
    return replace(rule, then=fallback)  # type: ignore[type-var]


def _named(key: str, name: str) -> Rule:
    try:
        return RULES[key]
    except KeyError:
        raise ValueError(
            f"unknown dispatch rule {name!r}; known rules: {', '.join(RULES)}"
            f" (a setup-aware one may fall back to another: 'same_program_first then edd')"
        ) from None


def _plain() -> str:
    return ", ".join(n for n, r in RULES.items() if not getattr(r, "setup_aware", False))


def _rank(
    jobs: list[JobView],
    key: Callable[[JobView], float],
    why: Callable[[JobView, float], str],
) -> list[Ranked]:
    # Each job's key is worked out once; the reason only for the jobs that are chosen.
    ranked = [Ranked(j, key(j), why) for j in jobs]
    ranked.sort(key=_order)
    return ranked


def _order(r: Ranked) -> tuple:
    return (-r.job.priority, r.key, r.job.id)


def _setup(held: str | None, program: str | None) -> str:
    if held is None:
        return "no program known on the machine"
    if program == held:
        return f"same program {held} already on the machine: no setup change"
    return f"not the program on the machine ({held})"


def _prefixed(why: str, base: Callable[[JobView, float], str]) -> Callable[[JobView, float], str]:
    return lambda j, k: f"{why}; {base(j, k)}"
