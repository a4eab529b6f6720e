# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The event hub driven call by call: an in-memory outbox, a hand-set clock, `poll()` run
by the test instead of the reader thread, and subscribers on one event loop."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

import pytest
from sqlalchemy import text

from dnc.db import transaction
from dnc.events import record
from dnc.outbox import Event
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    engine,
    pg_url,
    sessions,
    sqlite_template,
)
from web_api.event_hub import EventHub, HubClosed, PollingStream, outbox_hub

T = datetime(2026, 11, 21, tzinfo=UTC)


class Outbox:
    """Committed events by id; `reads` counts the queries made."""

    def __init__(self, ids=()) -> None:
        self.rows: dict[int, Event] = {}
        self.reads = 0
        self.commit(*ids)

    def commit(self, *ids: int) -> None:
        for i in ids:
            self.rows[i] = Event(i, T, "fmscell/machine/status", {"n": i})

    def append(self, count: int) -> list[int]:
        start = max(self.rows, default=0) + 1
        ids = list(range(start, start + count))
        self.commit(*ids)
        return ids

    def read_after(self, after: int, limit: int) -> list[Event]:
        self.reads += 1
        return [self.rows[i] for i in sorted(self.rows) if i > after][:limit]

    def latest(self) -> int:
        return max(self.rows, default=0)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def make_hub(outbox: Outbox, clock: Clock | None = None, **kw) -> EventHub:
    kw = {"capacity": 8, "batch": 4, "gap_grace_s": 2.0, **kw}
    return EventHub(outbox.read_after, outbox.latest, clock=clock or Clock(), **kw)


def poll_all(hub: EventHub) -> None:
    while hub.poll() == hub.batch:
        pass


async def drain(sub) -> list[int]:
    """Everything the subscription has now, without waiting."""
    got = []
    while batch := await sub.next_batch(0):
        got += [e.id for e in batch]
    return got


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 10))


# ------------------------------------------------------------------------------ resume

# (events stored before the hub anchors, written after, the client's resume point)
RESUME_CASES = [
    pytest.param(10, 3, 0, id="from-the-start-reads-the-database-then-the-ring"),
    pytest.param(10, 3, 7, id="inside-the-database-stretch"),
    pytest.param(10, 3, 10, id="at-the-anchor"),
    pytest.param(10, 3, 12, id="inside-the-ring"),
    pytest.param(10, 3, 13, id="at-the-horizon-nothing-yet"),
    pytest.param(0, 5, 0, id="empty-outbox-at-anchor"),
    pytest.param(10, 30, 2, id="ring-overflowed-since-anchor"),
    pytest.param(10, 3, 99, id="past-the-newest-waits-for-later-ids"),
]


@pytest.mark.parametrize(("before", "after", "cursor"), RESUME_CASES)
def test_resume_gets_every_event_after_the_cursor_once_in_order(before, after, cursor):
    outbox = Outbox(range(1, before + 1))

    async def scenario():
        hub = make_hub(outbox)
        sub = hub.subscribe(cursor, start_reader=False)
        outbox.append(after)
        poll_all(hub)
        return await drain(sub)

    got = run(scenario())
    assert got == [i for i in sorted(outbox.rows) if i > cursor]


def test_memory_stays_bounded_while_the_outbox_grows():
    outbox = Outbox()
    hub = make_hub(outbox)
    hub.subscribe(0, start_reader=False)
    for _ in range(50):
        outbox.append(4)
        hub.poll()
        assert len(hub._ring) < 2 * hub.capacity
    assert hub.floor > 0 and hub.horizon == 200


# A quiet cell: one event every `every` s into a ring of 4096 aged out after 300 s. By count
# alone the ring held all of them (8192 before a trim: hours of a soak's memory growth).
@pytest.mark.parametrize(
    ("every", "events", "max_age_s", "held_at_most"),
    [
        (2.0, 2000, 300.0, 151),  # steady after 5 minutes, then flat
        (2.0, 2000, None, 2000),  # count only: still growing at the end
        (0.01, 3000, 300.0, 1000),  # a burst: the count bound rules (2 x capacity)
    ],
)
def test_the_ring_ages_out_so_a_quiet_cell_is_flat_within_max_age(
    every, events, max_age_s, held_at_most
):
    outbox, clock = Outbox(), Clock()
    hub = make_hub(outbox, clock, capacity=500, batch=500, max_age_s=max_age_s)
    hub.subscribe(0, start_reader=False)
    held = []
    for _ in range(events):
        clock.t += every
        outbox.append(1)
        hub.poll()
        held.append(len(hub._ring))
    assert max(held) <= held_at_most
    if max_age_s is not None:
        # every event younger than max_age_s is still served from memory
        assert held[-1] == min(int(max_age_s / every) + 1, len(hub._ring))
        assert hub.floor == hub.horizon - held[-1]


def test_an_aged_out_ring_sends_a_reconnecting_client_to_the_database():
    outbox, clock = Outbox(), Clock()
    hub = make_hub(outbox, clock, max_age_s=10.0)
    hub.subscribe(0, start_reader=False)
    outbox.append(3)
    hub.poll()
    clock.t = 11.0
    hub.poll()  # nothing new: the old ones still age out
    assert hub._ring == [] and hub.floor == hub.horizon == 3
    got, bound = hub.take(1, 10)
    assert got is None and bound == 3  # behind the ring: read (1, 3] from the database
    assert [e.id for e in hub.read_behind(1, bound, 10)[0]] == [2, 3]
    outbox.append(1)
    hub.poll()
    assert [e.id for e in hub.take(3, 10)[0]] == [4]


def test_a_max_age_of_zero_is_refused():
    with pytest.raises(ValueError, match="max_age_s must be > 0 s"):
        make_hub(Outbox(), max_age_s=0.0)


# ------------------------------------------------------------------------------ live


def test_one_poll_wakes_every_waiting_subscriber():
    outbox = Outbox([1, 2])

    async def scenario():
        hub = make_hub(outbox)
        subs = [hub.subscribe(2, start_reader=False) for _ in range(20)]
        waiting = [asyncio.ensure_future(s.next_batch(60)) for s in subs]
        await asyncio.sleep(0)  # let each one reach its wait
        assert not any(w.done() for w in waiting)
        outbox.append(3)
        reads = outbox.reads
        hub.poll()
        batches = await asyncio.gather(*waiting)
        return batches, outbox.reads - reads

    batches, reads = run(scenario())
    assert all([e.id for e in b] == [3, 4, 5] for b in batches)
    assert reads == 1, "twenty subscribers, one database read"


def test_a_slow_client_catches_up_from_the_database_without_holding_the_others():
    outbox = Outbox()

    async def scenario():
        hub = make_hub(outbox)
        slow, quick = hub.subscribe(0, start_reader=False), hub.subscribe(0, start_reader=False)
        quick_got = []
        for _ in range(10):  # 40 events: five rings' worth pass while the slow one sleeps
            outbox.append(4)
            hub.poll()
            quick_got += await drain(quick)
        assert slow.cursor < hub.floor
        return quick_got, await drain(slow)

    quick_got, slow_got = run(scenario())
    assert quick_got == slow_got == list(range(1, 41))


def test_waiting_times_out_empty():
    async def scenario():
        hub = make_hub(Outbox([1]))
        return await hub.subscribe(1, start_reader=False).next_batch(0.01)

    assert run(scenario()) == []


def test_close_ends_waiting_and_new_streams():
    async def scenario():
        hub = make_hub(Outbox([1]))
        sub = hub.subscribe(1, start_reader=False)
        waiting = asyncio.ensure_future(sub.next_batch(60))
        await asyncio.sleep(0)
        hub.close()
        with pytest.raises(HubClosed):
            await waiting
        with pytest.raises(HubClosed):
            hub.subscribe(0, start_reader=False)
        hub.reopen()
        return await hub.subscribe(0, start_reader=False).next_batch(0)

    assert [e.id for e in run(scenario())] == [1]


# ------------------------------------------------------------------------------ holes

# Each step: (clock, ids committed just before the poll, horizon expected after it).
# A hole is an id taken by a transaction not committed yet (PostgreSQL) or rolled back.
GAP_CASES = [
    pytest.param(
        [(0.0, [3], 1), (0.5, [], 1), (1.0, [2], 3)],
        [1, 2, 3],
        id="late-commit-fills-the-hole-order-kept",
    ),
    pytest.param(
        [(0.0, [3, 4], 1), (1.9, [], 1), (2.0, [], 4)],
        [1, 3, 4],
        id="rolled-back-id-stepped-over-after-the-grace",
    ),
    pytest.param(
        [(0.0, [2, 4], 2), (1.0, [], 2), (2.5, [5], 5), (2.6, [7], 5)],
        [1, 2, 4, 5],
        id="each-hole-gets-its-own-grace",
    ),
]


@pytest.mark.parametrize(("steps", "delivered"), GAP_CASES)
def test_a_hole_in_the_ids_is_waited_for_then_stepped_over(steps, delivered):
    outbox, clock = Outbox([1]), Clock()
    hub = make_hub(outbox, clock)

    async def scenario():
        sub = hub.subscribe(0, start_reader=False)
        got = []
        for t, ids, horizon in steps:
            clock.t = t
            outbox.commit(*ids)
            hub.poll()
            assert hub.horizon == horizon, (t, ids)
            got += await drain(sub)
        return got

    assert run(scenario()) == delivered


def test_catching_up_from_the_database_stops_at_the_hubs_horizon():
    """An event beyond a hole the hub still waits on is not given out early, from the
    database either: the client would step over the late one."""
    outbox, clock = Outbox(range(1, 21)), Clock()
    hub = make_hub(outbox, clock)

    async def scenario():
        sub = hub.subscribe(0, start_reader=False)
        outbox.commit(22)
        hub.poll()
        first = await drain(sub)
        outbox.commit(21)
        hub.poll()
        return first, await drain(sub)

    first, rest = run(scenario())
    assert first == list(range(1, 21)) and rest == [21, 22]


def test_capacity_below_one_read_is_refused():
    with pytest.raises(ValueError, match="smaller than one read"):
        make_hub(Outbox(), capacity=2, batch=4)


# ------------------------------------------------------------------------------ peer, glue


def test_polling_stream_reads_the_outbox_itself():
    outbox = Outbox([1, 2, 3])

    async def scenario():
        return await drain(PollingStream(outbox.read_after, 1, 0.01, 2))

    assert run(scenario()) == [2, 3]


def test_a_commit_with_outbox_rows_nudges_the_reader(sessions):
    hub = outbox_hub(sessions, poll_s=1.0, capacity=4096)
    with transaction(sessions) as s:
        s.execute(text("SELECT 1"))
    assert not hub._nudge.is_set(), "a commit without events is not news"
    with transaction(sessions) as s:
        record(s, now=T, actor="t", action="machine.status", entity="machine", entity_id=None)
    assert hub._nudge.is_set()
    hub.close()
    hub._nudge.clear()
    with transaction(sessions) as s:
        record(s, now=T, actor="t", action="machine.status", entity="machine", entity_id=None)
    assert not hub._nudge.is_set(), "a closed hub no longer listens"


def test_a_database_that_cannot_be_read_refuses_the_subscription():
    from dnc.errors import DatabaseUnavailable

    def down() -> int:
        raise DatabaseUnavailable("database unavailable: no such file")

    hub = EventHub(Outbox().read_after, down, capacity=8, batch=4)
    with pytest.raises(DatabaseUnavailable):
        hub.subscribe(0, start_reader=False)
    assert hub.subscribers == 0


def test_the_reader_stops_when_nobody_listened_for_a_while_and_reanchors_later():
    outbox, clock = Outbox([1, 2]), Clock()
    hub = make_hub(outbox, clock, idle_stop_s=5.0)
    hub.subscribe(0, start_reader=False).close()
    clock.t = 5.0
    hub._run()  # in this thread: one read, then it sees nobody for 5 s and returns
    assert outbox.reads == 1 and not hub._anchored
    outbox.append(3)
    hub.subscribe(0, start_reader=False)
    assert hub.floor == hub.horizon == 5, "anchored again at the newest event"
