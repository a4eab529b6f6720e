"""The event hub: one reader of the outbox per app, fanned out to every stream client.

Without it each SSE/WebSocket client polled the outbox on its own, so a hundred dashboards
meant a hundred queries every poll interval. The hub's reader thread follows the outbox
instead (a poll every `events_poll_s`, and at once when this process commits an outbox
row), keeps the newest events in a bounded ring and wakes the subscribers on their event
loops. A subscriber reads from the ring; one whose cursor is older than the ring (a resume
from an old Last-Event-ID, or a client too slow to keep up) reads the missing stretch from
the database, never past what the reader has accepted, and then joins the ring again. So
order is the outbox id order, nothing is sent twice, a slow client costs database reads
rather than memory, and nobody waits for anybody else.

Ids and commit order: on SQLite one writer at a time commits, so ids appear in order and
without holes. On PostgreSQL a transaction can commit after one that took a later id, and
a rolled-back one leaves a hole for good. The reader therefore stops at a hole and waits up
to `gap_grace_s` for it to fill before it steps over it; a transaction holding an outbox id
uncommitted for longer than that is the one case that can still be missed.

The ring is bounded twice: at most `capacity` events (up to twice that between trims), and
none older than `max_age_s` (accepted that long ago). A quiet cell writes an event every
few seconds: by count alone the ring took hours to fill, the process's memory growing all
that while; by age it is full within `max_age_s` and stays flat. A client that reconnects
later than that, or lags that far, reads the gap from the database as any client behind.

The reader runs while someone listens: the first subscriber starts it (anchored at the
newest event), and it stops after `idle_stop_s` without subscribers or when the app shuts
down (`close`). The core (`poll`, `take`) is plain calls that tests drive one by one.
"""

from __future__ import annotations

import asyncio
import bisect
import logging
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import anyio
from sqlalchemy import event as sa_event
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.db import transaction
from dnc.events import OUTBOX_WRITTEN
from dnc.outbox import Event, events_after
from web_api.errors import ShuttingDown

log = logging.getLogger(__name__)

ReadAfter = Callable[[int, int], Sequence[Event]]
"""(after_id, limit) -> up to `limit` events with id > after_id, in id order."""


@dataclass(frozen=True, slots=True)
class Published:
    """An event as the streams send it, encoded once however many clients receive it."""

    id: int
    json: str  # the WebSocket message
    sse: bytes  # the server-sent event, blank line included

    @classmethod
    def of(cls, event: Event) -> Published:
        text = event.to_json()
        return cls(event.id, text, f"id: {event.id}\ndata: {text}\n\n".encode())


class HubClosed(ShuttingDown):
    """The app is shutting down: streams end (a new one is refused as `shutting-down`)."""


class _Wakeup:
    """The subscribers waiting on one event loop share one future, replaced at each fire, so
    a batch of new events costs the reader one call per loop, not one per subscriber."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.future: asyncio.Future[None] = loop.create_future()

    def fire(self) -> None:  # runs on self.loop
        done, self.future = self.future, self.loop.create_future()
        if not done.done():
            done.set_result(None)


class Stream(Protocol):
    """What the SSE and WebSocket routes read: batches of events after a cursor."""

    cursor: int

    async def next_batch(self, timeout: float) -> list[Published]: ...

    def close(self) -> None: ...


class EventHub:
    def __init__(
        self,
        read_after: ReadAfter,
        latest_id: Callable[[], int],
        *,
        capacity: int = 4096,
        batch: int = 500,
        poll_s: float = 0.25,
        gap_grace_s: float = 2.0,
        idle_stop_s: float = 10.0,
        coalesce_s: float = 0.02,
        max_age_s: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if capacity < batch:
            raise ValueError(f"ring capacity {capacity} is smaller than one read ({batch})")
        if max_age_s is not None and max_age_s <= 0:
            raise ValueError(f"ring max_age_s must be > 0 s (or None), got {max_age_s}")
        self.max_age_s = max_age_s
        self._read_after = read_after
        self._latest_id = latest_id
        self.capacity, self.batch, self.poll_s = capacity, batch, poll_s
        self.gap_grace_s, self.idle_stop_s, self.coalesce_s = gap_grace_s, idle_stop_s, coalesce_s
        self._clock = clock
        self._lock = threading.Lock()
        self._start_lock = threading.Lock()  # one subscriber anchors and starts the reader
        # The ring holds every accepted event with floor < id <= horizon, ascending.
        self._ring: list[Published] = []
        self._ids: list[int] = []
        self._accepted_at: list[float] = []  # the clock when each was accepted (ascending)
        self._floor = 0
        self._horizon = 0
        self._anchored = False
        self._gap_since: float | None = None
        self._subscribers = 0
        self._idle_since: float | None = None
        self._closed = False
        self._failure: Exception | None = None
        self._wakeups: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _Wakeup] = (
            weakref.WeakKeyDictionary()
        )
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._nudge = threading.Event()
        self.polls = 0  # database reads by the reader (the benchmark reports them)
        self.on_open: Callable[[], None] | None = None
        self.on_close: Callable[[], None] | None = None

    # ------------------------------------------------------------------ the core

    @property
    def floor(self) -> int:
        return self._floor

    @property
    def horizon(self) -> int:
        return self._horizon

    def anchor(self) -> None:
        """Start following at the newest event: older ones are read from the database."""
        latest = self._latest_id()
        with self._lock:
            self._ring, self._ids, self._accepted_at = [], [], []
            self._floor = self._horizon = latest
            self._gap_since = None
            self._anchored = True

    def poll(self) -> int:
        """One read of the outbox after the horizon; returns how many events were accepted
        (a full batch means there may be more)."""
        rows = self._read_after(self._horizon, self.batch)
        self.polls += 1
        now = self._clock()
        accepted: list[Published] = []
        expect = self._horizon + 1
        for event in rows:
            if event.id > expect:  # a hole: an id not committed (yet)
                if self._gap_since is None:
                    self._gap_since = now
                if now - self._gap_since < self.gap_grace_s:
                    break
            self._gap_since = None
            accepted.append(Published.of(event))
            expect = event.id + 1
        if accepted:
            with self._lock:
                self._ring.extend(accepted)
                self._ids.extend(e.id for e in accepted)
                self._accepted_at.extend([now] * len(accepted))
                self._horizon = accepted[-1].id
                # Trim in chunks so appending stays amortised O(1).
                cut = len(self._ring) - self.capacity if len(self._ring) >= 2 * self.capacity else 0
                self._trim(max(cut, self._aged_out(now)))
            self._wake_all()
        elif self.max_age_s is not None and self._ring:
            with self._lock:
                self._trim(self._aged_out(now))
        return len(accepted)

    def _aged_out(self, now: float) -> int:
        """How many of the oldest events were accepted more than `max_age_s` ago."""
        if self.max_age_s is None:
            return 0
        return bisect.bisect_left(self._accepted_at, now - self.max_age_s)

    def _trim(self, cut: int) -> None:
        """Drop the `cut` oldest events (under the lock); the floor follows them."""
        if cut > 0:
            self._floor = self._ids[cut - 1]
            del self._ring[:cut], self._ids[:cut], self._accepted_at[:cut]

    def take(self, cursor: int, limit: int) -> tuple[list[Published] | None, int]:
        """Events after `cursor` from the ring, and the horizon they are bounded by.

        None when the cursor is older than the ring: the caller reads (cursor, horizon]
        from the database."""
        with self._lock:
            if cursor < self._floor:
                return None, self._horizon
            i = bisect.bisect_right(self._ids, cursor)
            return self._ring[i : i + limit], self._horizon

    def read_behind(self, cursor: int, bound: int, limit: int) -> tuple[list[Published], int]:
        """The database's events in (cursor, bound] for a subscriber behind the ring, and
        the cursor after them."""
        rows = [Published.of(e) for e in self._read_after(cursor, limit) if e.id <= bound]
        if rows:
            return rows, rows[-1].id
        # Nothing stored up to the bound (holes stepped over): the ring continues from there.
        return [], max(cursor, min(bound, self._floor))

    # ------------------------------------------------------------------ subscribers

    def _wakeup(self, loop: asyncio.AbstractEventLoop) -> _Wakeup:
        with self._lock:
            w = self._wakeups.get(loop)
            if w is None:
                w = self._wakeups[loop] = _Wakeup(loop)
            return w

    def _wake_all(self) -> None:
        with self._lock:
            wakeups = list(self._wakeups.values())
        for w in wakeups:
            try:
                w.loop.call_soon_threadsafe(w.fire)
            except RuntimeError:  # that loop is closed (a finished test client)
                with self._lock:
                    self._wakeups.pop(w.loop, None)

    def subscribe(self, cursor: int, *, start_reader: bool = True) -> Subscription:
        """A subscription after `cursor`; anchors the hub and starts its reader if needed.

        Raises HubClosed after `close`, and the reader's last failure (a database that is
        down) so the route answers 503 instead of opening a stream that stays silent."""
        with self._start_lock:
            if self._closed:
                raise HubClosed("the server is shutting down")
            with self._lock:
                # Decided under the lock the reader decides to stop under: a reader that
                # is seen running has also seen this subscriber before it could stop.
                running = self._thread is not None and self._thread.is_alive()
                if running and self._failure is None:
                    self._subscribers += 1
                    self._idle_since = None
                    return Subscription(self, cursor)
                failure = self._failure if running else None
            if failure is not None:
                raise failure
            if start_reader or not self._anchored:
                self.anchor()  # reads the database: a dead one raises here
            with self._lock:
                self._subscribers += 1
                self._idle_since = None
            if start_reader:
                self._start_reader()
        return Subscription(self, cursor)

    def _unsubscribe(self) -> None:
        with self._lock:
            self._subscribers -= 1
            if self._subscribers == 0:
                self._idle_since = self._clock()

    @property
    def subscribers(self) -> int:
        return self._subscribers

    # ------------------------------------------------------------------ the reader thread

    def nudge(self) -> None:
        """Read now: this process just committed outbox rows (any thread may call this)."""
        self._nudge.set()

    def _start_reader(self) -> None:
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                return
            self._stop.clear()
            self._failure = None
            self._idle_since = None
            self._thread = threading.Thread(target=self._run, name="fmscell-event-hub", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        backoff = self.poll_s
        last_read = time.monotonic()
        while not self._stop.is_set():
            try:
                accepted = self.poll()
                if self._failure is not None:
                    log.warning("event hub: the outbox is readable again")
                self._failure, backoff = None, self.poll_s
            except Exception as exc:  # the database is down: say so once, then back off
                if self._failure is None:
                    log.warning("event hub: cannot read the outbox: %s", exc)
                self._failure = exc
                accepted, backoff = 0, min(2 * backoff, 5.0)
            with self._lock:
                if (
                    self._subscribers == 0
                    and self._idle_since is not None
                    and self._clock() - self._idle_since >= self.idle_stop_s
                ):
                    # Nobody listens: stop, and re-anchor when someone does.
                    self._thread = None
                    self._anchored = False
                    return
            if accepted < self.batch:
                self._nudge.wait(backoff if self._failure else self.poll_s)
                self._nudge.clear()
                # Commits come in bursts (a cell writes every few ms under load): reading at
                # most every `coalesce_s` gives each burst one read and one wake-up per
                # client instead of one per commit. A lone commit is read at once.
                since = time.monotonic() - last_read
                if since < self.coalesce_s:
                    self._stop.wait(self.coalesce_s - since)
            last_read = time.monotonic()

    def close(self, *, wait: bool = True) -> None:
        """Stop the reader and end every subscriber's stream (the app shuts down).

        uvicorn waits for open responses before it runs the lifespan's shutdown, so a
        server that means to stop while clients watch calls this first (`wait=False` from
        a signal handler); the lifespan's call then only finishes the job."""
        with self._lock:
            self._closed = True
            thread = self._thread
        self._stop.set()
        self._nudge.set()
        if wait and thread is not None and thread is not threading.current_thread():
            thread.join(timeout=5)
        self._wake_all()
        if self.on_close is not None:
            self.on_close()

    def reopen(self) -> None:
        """After `close`, for an app started again (a test client entered twice)."""
        with self._lock:
            self._closed = False
            self._thread = None
        if self.on_open is not None:
            self.on_open()

    @property
    def closed(self) -> bool:
        return self._closed


class Subscription:
    """One client's place in the stream: the id of the last event it was given."""

    def __init__(self, hub: EventHub, cursor: int, limit: int = 200) -> None:
        self._hub, self.cursor, self.limit = hub, cursor, limit
        self._open = True

    async def next_batch(self, timeout: float) -> list[Published]:
        """The next events in id order, or [] when none came within `timeout` seconds.

        Raises HubClosed when the app shuts down."""
        hub = self._hub
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while True:
            if hub.closed:
                raise HubClosed("the server is shutting down")
            # Taken before looking, so a fire between the look and the wait is not lost.
            wake = hub._wakeup(loop).future
            got, bound = hub.take(self.cursor, self.limit)
            if got is None:
                got, self.cursor = await anyio.to_thread.run_sync(
                    hub.read_behind, self.cursor, bound, self.limit
                )
                if got:
                    return got
                continue
            if got:
                self.cursor = got[-1].id
                return got
            remaining = deadline - loop.time()
            if remaining <= 0:
                return []
            # asyncio.wait never cancels the shared future, even when this task is cancelled.
            await asyncio.wait({wake}, timeout=remaining)

    def close(self) -> None:
        if self._open:
            self._open = False
            self._hub._unsubscribe()


class PollingStream:
    """The stream as it was before the hub: this client polls the outbox itself every
    `poll_s`. Kept as the benchmark's peer (`events_fanout: poll`)."""

    def __init__(
        self,
        read_after: ReadAfter,
        cursor: int,
        poll_s: float,
        limit: int = 200,
        closed: Callable[[], bool] = lambda: False,
    ):
        self._read_after, self.cursor, self.poll_s, self.limit = read_after, cursor, poll_s, limit
        self._closed = closed

    async def next_batch(self, timeout: float) -> list[Published]:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while True:
            if self._closed():
                raise HubClosed("the server is shutting down")
            got = list(await anyio.to_thread.run_sync(self._read_after, self.cursor, self.limit))
            if got:
                self.cursor = got[-1].id
                return [Published.of(e) for e in got]
            remaining = deadline - loop.time()
            if remaining <= 0:
                return []
            await asyncio.sleep(min(self.poll_s, remaining))

    def close(self) -> None:
        pass


# ---------------------------------------------------------------------- over the outbox


def latest_event_id(sessions: sessionmaker[Session]) -> int:
    with transaction(sessions) as s:
        return s.scalar(select(func.max(m.OutboxEvent.id))) or 0


def outbox_hub(
    sessions: sessionmaker[Session],
    *,
    poll_s: float,
    capacity: int,
    max_age_s: float | None = None,
) -> EventHub:
    """The hub over the outbox of `sessions`, nudged whenever a session of that factory
    commits outbox rows (in-process writers are seen at once, others at the next poll)."""
    hub = EventHub(
        lambda after, limit: events_after(sessions, after, limit),
        lambda: latest_event_id(sessions),
        capacity=capacity,
        poll_s=poll_s,
        max_age_s=max_age_s,
    )
    hub_ref = weakref.ref(hub)

    def after_flush(session: Session, _context: object) -> None:
        if any(isinstance(obj, m.OutboxEvent) for obj in session.new):
            session.info[OUTBOX_WRITTEN] = True

    def after_commit(session: Session) -> None:
        if session.info.pop(OUTBOX_WRITTEN, False):
            target = hub_ref()
            if target is not None:
                target.nudge()

    def after_rollback(session: Session) -> None:
        session.info.pop(OUTBOX_WRITTEN, None)

    listeners = [
        ("after_flush", after_flush),
        ("after_commit", after_commit),
        ("after_rollback", after_rollback),
    ]

    def install() -> None:
        for name, fn in listeners:
            if not sa_event.contains(sessions, name, fn):
                sa_event.listen(sessions, name, fn)

    def forget() -> None:
        for name, fn in listeners:
            if sa_event.contains(sessions, name, fn):
                sa_event.remove(sessions, name, fn)

    install()
    hub.on_open, hub.on_close = install, forget
    return hub
