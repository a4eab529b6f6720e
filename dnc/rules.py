"""Dispatch rules: which waiting job an idle machine takes next.

Pure functions over plain data. Each rule orders the candidate jobs and explains its choice,
so every dispatch decision is recorded with a reason a production planner can read.
Priority classes come first under every rule (a rush job beats any rule); the rule orders
within a class; the job id breaks ties, so decisions are deterministic.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime


@dataclass(frozen=True, slots=True)
class JobView:
    id: int
    priority: int  # higher first
    created_at: datetime
    due_at: datetime | None
    remaining: int  # parts still to make
    cycle_time_s: float  # estimated time per part

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


RULES: dict[str, Rule] = {"fifo": fifo, "spt": spt, "edd": edd, "cr": critical_ratio}


def rule_named(name: str) -> Rule:
    try:
        return RULES[name.lower()]
    except KeyError:
        raise ValueError(
            f"unknown dispatch rule {name!r}; known rules: {', '.join(RULES)}"
        ) from None


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
