"""The DNC host's keys of the cell file's `host` section: the program library's database,
when a machine counts as lost, and the dispatch rule. docs/configuration.md lists every
key; server/config.py composes them with the REST API's keys into `host`.

dnc owns these keys: their schema (a pydantic section, strict) and their rules
(`problems()`: the dispatch rule must name a rule of dnc/rules.py).
"""

from __future__ import annotations

from pydantic import Field

from cnc.config import Problem, Section
from dnc.rules import rule_named

__all__ = ["DncConfig"]


class DncConfig(Section):
    """The DNC host (`host`: database_url, lost_contact_s, dispatch_rule)."""

    database_url: str | None = Field(
        None, description="SQLAlchemy URL; null = the embedded SQLite file."
    )
    lost_contact_s: float = Field(
        30.0,
        gt=0,
        description="A machine out of contact this long is taken as lost: its allocation is"
        " interrupted and the part rerouted (seconds).",
    )
    dispatch_rule: str = Field(
        "fifo",
        min_length=1,
        description="Which waiting job a free machine takes next: `fifo`, `spt`, `edd`, `cr`"
        " or `same_program_first` (the job whose program the machine already holds, then"
        " FIFO; `same_program_first then edd` falls back to EDD instead); docs/dnc.md.",
    )

    def problems(self) -> list[Problem]:
        try:
            rule_named(self.dispatch_rule)
        except ValueError as exc:
            return [(("dispatch_rule",), str(exc))]
        return []
