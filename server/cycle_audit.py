"""Audit of cycle starts and program selects, whoever made them.

A Modbus client (an HMI, a SCADA, anyone who reaches the Modbus face) can select a program
and start a cycle on the machine's remote panel (`%MX0.0` cycle start, `%MW4` + strobe
`%MX0.3` program select) without passing through the host. The host does not see the Modbus
traffic of other clients, but it sees what the machine does on its status stream (SHDR ->
the MTConnect agent -> the monitoring model): the program changing and the execution
becoming ACTIVE. `CycleAudit.check` (a host loop at the scheduler's tick) records each such
change in the audit log and the event stream:

    machine.program_selected  {machine, program, previous, requested_by}
    machine.cycle_start       {machine, program, previous_execution, resumed, requested_by}

`requested_by` says who asked: the host's own starts and selects (the transfer worker's
starter, the REST machine commands) announce themselves in `HostRequests` before they press,
and the change they cause is attributed to them; any other is `"not the host: a Modbus client
on the remote panel, or the machine's own panel"`, recorded with the actor `machine-panel`.

The status is read at each tick (0.5 s on the realtime clock, 0.05 s on the fast one): a
program shorter than one tick can run and end between two looks; its start is then recorded
from the part counter rising (`"seen": "part count"`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from dnc.db import transaction
from dnc.events import record

NOT_THE_HOST = "not the host: a Modbus client on the remote panel, or the machine's own panel"
# Executions from which ACTIVE is a cycle start (READY...) or a resume (FEED_HOLD...).
RESUMES = frozenset({"FEED_HOLD", "OPTIONAL_STOP", "PROGRAM_STOPPED", "INTERRUPTED"})
NOT_SEEN = frozenset({"", "UNAVAILABLE"})


@dataclass(frozen=True, slots=True)
class Seen:
    """What the monitoring model shows of one machine at one look."""

    execution: str
    program: str
    part_count: float | None


def changes(prev: Seen | None, cur: Seen) -> list[tuple[str, dict]]:
    """The program selects and cycle starts between two looks (pure: a table of cases in
    tests/server/test_cycle_audit.py)."""
    if prev is None or prev.execution in NOT_SEEN or cur.execution in NOT_SEEN:
        return []  # the first look, or a machine (re)connecting: nothing was done
    out: list[tuple[str, dict]] = []
    if cur.program != prev.program and cur.program:
        out.append(("program_select", {"program": cur.program, "previous": prev.program}))
    if cur.execution == "ACTIVE" and prev.execution != "ACTIVE":
        out.append(
            (
                "cycle_start",
                {
                    "program": cur.program,
                    "previous_execution": prev.execution,
                    "resumed": prev.execution in RESUMES,
                    "seen": "execution",
                },
            )
        )
    elif (
        cur.execution != "ACTIVE"
        and prev.execution != "ACTIVE"
        and cur.part_count is not None
        and prev.part_count is not None
        and cur.part_count > prev.part_count
    ):
        # started and ended between two looks
        out.append(
            (
                "cycle_start",
                {
                    "program": cur.program,
                    "previous_execution": prev.execution,
                    "resumed": False,
                    "seen": "part count",
                },
            )
        )
    return out


class HostRequests:
    """What the host itself has asked a machine to do and not yet seen done: the audit
    gives the change to the request, not to a panel. A request is forgotten after `ttl_s`
    (a refused request must not take the credit for a later panel action)."""

    def __init__(self, ttl_s: float = 30.0, clock: Callable[[], float] = time.monotonic):
        self.ttl_s, self.clock = ttl_s, clock
        self._pending: dict[tuple[str, str], list[tuple[float, str]]] = {}
        self._lock = threading.Lock()

    def expect(self, machine: str, what: str, by: str) -> None:
        with self._lock:
            now = self.clock()
            # Stale ones go here too, not only in `take`: a request whose change never
            # shows (selecting the program already selected, every part of a job) is never
            # taken, and kept it grew the host's memory with every dispatch.
            self._forget_stale(now)
            self._pending.setdefault((machine, what), []).append((now, by))

    def take(self, machine: str, what: str) -> str | None:
        """Who asked for `what` on `machine` (the oldest pending request), or None."""
        with self._lock:
            self._forget_stale(self.clock())
            queue = self._pending.get((machine, what))
            if not queue:
                return None
            by = queue.pop(0)[1]
            if not queue:
                del self._pending[(machine, what)]
            return by

    def _forget_stale(self, now: float) -> None:
        for key in list(self._pending):
            queue = [(t, by) for t, by in self._pending[key] if now - t <= self.ttl_s]
            if queue:
                self._pending[key] = queue
            else:
                del self._pending[key]

    @property
    def pending(self) -> int:
        """Requests held (not yet seen done, not yet stale)."""
        with self._lock:
            return sum(len(q) for q in self._pending.values())


class CycleAudit:
    """The host loop: looks at each machine's status and records what changed."""

    def __init__(self, sessions, monitor, requests: HostRequests) -> None:
        self.sessions, self.monitor, self.requests = sessions, monitor, requests
        self.seen: dict[str, Seen] = {}

    def look(self, status: Mapping) -> Seen:
        count = (status.get("counters") or {}).get("part_count")
        return Seen(
            str(status.get("execution") or ""),
            str(status.get("program") or ""),
            None if count is None else float(count),
        )

    def check(self) -> int:
        from datetime import UTC, datetime

        found = []
        for name in self.monitor.links:
            cur = self.look(self.monitor.status(name))
            for what, detail in changes(self.seen.get(name), cur):
                # a select is the host's only if it selected that very program
                key = f"{what} {detail['program']}" if what == "program_select" else what
                by = self.requests.take(name, key)
                found.append((name, what, detail, by))
            self.seen[name] = cur
        if found:
            at = datetime.now(UTC)
            with transaction(self.sessions) as s:
                for name, what, detail, by in found:
                    record(
                        s,
                        now=at,
                        actor="host" if by else "machine-panel",
                        action="machine.program_selected"
                        if what == "program_select"
                        else "machine.cycle_start",
                        entity="machine",
                        entity_id=None,
                        machine=name,
                        requested_by=by or NOT_THE_HOST,
                        **detail,
                    )
        return len(found)
