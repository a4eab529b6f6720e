"""The simulated CAN bus: a hub that arbitrates, times and delivers frames between endpoints.

Every attached `SimBus` is a python-can `BusABC`, so `canopen.Network(bus=endpoint)` or any
python-can user can sit on the hub. Each endpoint has a FIFO transmit queue like a CAN
controller; among the queue heads the lowest identifier wins arbitration. Each frame occupies
its bit-exact stuffed length of wire time at the configured bitrate.

Lockstep mode (default) has no threads: a frame sent while the hub is idle is delivered at
once in the sender's call (responses sent from listeners join the same arbitration round), and
`advance(dt)` moves virtual time, releases delayed frames and ticks the clocked participants
(the slaves' timers). Timestamps are virtual, so the candump trace is byte-identical run to run.
Realtime mode delivers from a background thread and stamps frames with the wall clock.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, TextIO

import can

from drives.bus.candump import CandumpWriter
from drives.bus.frame import ERROR_FRAME_BITS, data_frame_bits, frame_bits
from drives.bus.loadplan import plan_load
from drives.bus.message import OwnedMessage, new_message
from drives.realtime import RealtimeProcess

logger = logging.getLogger(__name__)


class Clocked(Protocol):
    def advance(self, dt_s: float) -> None: ...


Listener = Callable[[can.Message], None]


@dataclass
class WindowLoad:
    """Bits carried between two SYNC frames (one SYNC window)."""

    start: float
    duration: float
    bits: int
    frames: int

    @property
    def load(self) -> float:
        return 0.0 if self.duration <= 0 else self.bits / self.duration


class BusLoadAccount:
    """Bus load per SYNC window: mean and peak, as a fraction of the bitrate."""

    # The last `keep_windows` SYNC windows are kept for inspection; mean and peak cover the
    # whole run. 100 000 windows (200 s at 2 ms) held some 20 MB per bus in a cell running
    # for hours (RSS grew for minutes after its start): a few seconds' worth is what a
    # look at the recent load needs.
    def __init__(self, bitrate: int, sync_id: int, keep_windows: int = 2000) -> None:
        self.bitrate = bitrate
        self.sync_id = sync_id
        self.total_bits = 0
        self.total_frames = 0
        self.windows: deque[WindowLoad] = deque(maxlen=keep_windows)
        self._window_start: float | None = None
        self._window_bits = 0
        self._window_frames = 0
        self._closed_bits = 0
        self._closed_time = 0.0
        self.peak = 0.0

    def account(self, start: float, bits: int, is_sync: bool) -> None:
        if is_sync:
            if self._window_start is not None:
                duration = start - self._window_start
                window = WindowLoad(
                    self._window_start, duration, self._window_bits, self._window_frames
                )
                window_load = self._window_bits / (duration * self.bitrate) if duration > 0 else 0.0
                if duration > 0:
                    self._closed_bits += self._window_bits
                    self._closed_time += duration
                    self.peak = max(self.peak, window_load)
                self.windows.append(window)
            self._window_start = start
            self._window_bits = 0
            self._window_frames = 0
        self._window_bits += bits
        self._window_frames += 1
        self.total_bits += bits
        self.total_frames += 1

    @property
    def mean(self) -> float:
        """Mean load over all closed SYNC windows (0.0 before the second SYNC)."""
        if self._closed_time <= 0:
            return 0.0
        return self._closed_bits / (self._closed_time * self.bitrate)

    def summary(self) -> dict[str, float | int]:
        return {
            "windows": len(self.windows),
            "mean_load": self.mean,
            "peak_load": self.peak,
            "total_bits": self.total_bits,
            "total_frames": self.total_frames,
        }


@dataclass
class FrameFault:
    """An injected fault matched against frames when they win arbitration."""

    kind: str  # "drop" | "corrupt" | "delay"
    can_id: int | None = None
    sender: SimBus | None = None
    count: int | None = 1  # None = until cleared
    delay_s: float = 0.0

    def matches(self, sender: SimBus | None, msg: can.Message) -> bool:
        if self.can_id is not None and msg.arbitration_id != self.can_id:
            return False
        return self.sender is None or self.sender is sender


@dataclass
class _Babbler:
    can_id: int
    data: bytes
    extended: bool
    bits: int
    since: float
    sent: int = 0


@dataclass(order=True)
class _Delayed:
    release: float
    seq: int
    sender: Any = field(compare=False)
    msg: can.Message = field(compare=False)


def _priority(msg: can.Message) -> int:
    """Arbitration order as one int (lower wins): base ID, then 11-bit before 29-bit, then
    the extension, then data before remote. Bits: base << 20 | IDE << 19 | ext << 1 | RTR."""
    ident = msg.arbitration_id
    if msg.is_extended_id:
        return (ident >> 18) << 20 | 1 << 19 | (ident & 0x3FFFF) << 1 | msg.is_remote_frame
    return ident << 20 | msg.is_remote_frame


_HUBS: dict[str, CanHub] = {}
_HUBS_LOCK = threading.Lock()


def get_hub(channel: str, **kwargs: Any) -> CanHub:
    """The process-wide hub named `channel`, created with `kwargs` on first use."""
    with _HUBS_LOCK:
        hub = _HUBS.get(channel)
        if hub is None:
            hub = _HUBS[channel] = CanHub(channel=channel, **kwargs)
        return hub


def drop_hub(channel: str) -> None:
    """Forget a named hub (tests create fresh ones)."""
    with _HUBS_LOCK:
        hub = _HUBS.pop(channel, None)
    if hub is not None:
        hub.close()


class CanHub:
    """One simulated CAN bus segment. See the module docstring for the two modes."""

    def __init__(
        self,
        bitrate: int = 1_000_000,
        *,
        mode: str = "lockstep",
        channel: str = "can0",
        sync_id: int = 0x080,
        log: TextIO | None = None,
        start_time: float = 0.0,
        auto_deliver: bool = True,
        rx_queue_limit: int = 10_000,
        realtime_tick_s: float = 0.001,
    ) -> None:
        if mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode must be 'lockstep' or 'realtime', got {mode!r}")
        if bitrate <= 0:
            raise ValueError(f"bitrate must be > 0, got {bitrate}")
        self.bitrate = bitrate
        self.mode = mode
        self.channel = channel
        self.sync_id = sync_id
        self.auto_deliver = auto_deliver
        self.rx_queue_limit = rx_queue_limit
        self.realtime_tick_s = realtime_tick_s
        self.load = BusLoadAccount(bitrate, sync_id)
        self.endpoints: list[SimBus] = []
        self.clocked: list[Clocked] = []
        self.observers: list[Listener] = []
        self.faults: list[FrameFault] = []
        self.error_frames = 0
        self.dropped_frames = 0
        #: worst queue-to-end-of-frame latency per traffic class, seconds
        self.worst_latency_s = {"pdo": 0.0, "sdo": 0.0, "other": 0.0}
        self._now = start_time
        self._bus_free_at = start_time
        self._lock = threading.RLock()
        self._pending = 0
        self._delivering = False
        self._delayed: list[_Delayed] = []
        self._seq = itertools.count()
        self._babbler: _Babbler | None = None
        self._wake = threading.Condition(self._lock)
        self._worker: threading.Thread | None = None
        self._running = False
        self.late_ticks = 0
        self.tick_errors = 0
        self.ticks = 0
        if log is not None:
            self.add_observer(CandumpWriter(log, channel).write)

    # ----------------------------------------------------------------- attachment
    def endpoint(self, name: str = "", *, receive_own_messages: bool = False) -> SimBus:
        """A new python-can bus object attached to this hub."""
        return SimBus(self.channel, hub=self, name=name, receive_own_messages=receive_own_messages)

    def _attach(self, bus: SimBus) -> None:
        with self._lock:
            self.endpoints.append(bus)

    def _detach(self, bus: SimBus) -> None:
        with self._lock:
            if bus in self.endpoints:
                self._pending -= len(bus._tx)
                bus._tx.clear()
                self.endpoints.remove(bus)

    def add_clocked(self, participant: Clocked) -> None:
        """Tick `participant.advance(dt)` on every `advance` (lockstep) or tick (realtime)."""
        with self._lock:
            if participant not in self.clocked:
                self.clocked.append(participant)

    def remove_clocked(self, participant: Clocked) -> None:
        """Stop ticking `participant`."""
        with self._lock:
            if participant in self.clocked:
                self.clocked.remove(participant)

    def add_observer(self, observer: Listener) -> None:
        """Called with every frame put on the wire (the candump writer is one)."""
        self.observers.append(observer)

    def check_load(self, frames: list, sync_period_s: float):
        """`plan_load` at this hub's bitrate: refuses > 100 %, warns > 70 % (see loadplan)."""
        return plan_load(frames, sync_period_s=sync_period_s, bitrate=self.bitrate)

    # ----------------------------------------------------------------- time
    @property
    def now(self) -> float:
        """Hub time: virtual in lockstep, `time.time()` in realtime."""
        return self._now if self.mode == "lockstep" else time.time()

    @property
    def backlog_s(self) -> float:
        """How far the wire is booked beyond `now` (> 0 means frames queue up)."""
        return max(0.0, self._bus_free_at - self.now)

    def advance(self, dt_s: float) -> None:
        """Lockstep: move virtual time by `dt_s`, tick clocked participants, deliver."""
        if self.mode != "lockstep":
            raise RuntimeError("advance() is for lockstep hubs; a realtime hub runs by itself")
        if dt_s < 0:
            raise ValueError(f"dt_s must be >= 0, got {dt_s}")
        with self._lock:
            self._now += dt_s
            self._release_delayed()
            self.deliver()
            for participant in list(self.clocked):
                participant.advance(dt_s)
            self.deliver()

    def run_for(self, duration_s: float, step_s: float) -> None:
        """Lockstep: `advance(step_s)` repeatedly for `duration_s` (rounded to whole steps)."""
        for _ in range(round(duration_s / step_s)):
            self.advance(step_s)

    # ----------------------------------------------------------------- faults
    def drop(
        self, can_id: int | None = None, *, count: int | None = 1, sender: SimBus | None = None
    ) -> FrameFault:
        """Lose the next `count` matching frames (None = all until cleared)."""
        fault = FrameFault("drop", can_id, sender, count)
        self.faults.append(fault)
        return fault

    def corrupt(
        self, can_id: int | None = None, *, count: int | None = 1, sender: SimBus | None = None
    ) -> FrameFault:
        """Destroy the next matching frames: receivers get an error frame instead."""
        fault = FrameFault("corrupt", can_id, sender, count)
        self.faults.append(fault)
        return fault

    def delay(
        self,
        can_id: int | None = None,
        delay_s: float = 0.001,
        *,
        count: int | None = 1,
        sender: SimBus | None = None,
    ) -> FrameFault:
        """Hold matching frames back by `delay_s` of hub time before they compete again."""
        fault = FrameFault("delay", can_id, sender, count, delay_s)
        self.faults.append(fault)
        return fault

    def bus_off(self, endpoint: SimBus) -> None:
        """The node goes bus-off: its sends fail with CanOperationError, others see nothing."""
        with self._lock:
            endpoint._bus_off = True
            self._pending -= len(endpoint._tx)
            endpoint._tx.clear()

    def recover(self, endpoint: SimBus) -> None:
        """Bus-off recovery: the node may send again."""
        endpoint._bus_off = False

    def babble(self, can_id: int, data: bytes = b"\xff" * 8, *, extended: bool = False) -> None:
        """A babbling node floods `can_id`: whenever it wins arbitration it fills the wire."""
        bits = frame_bits(can_id, bytes(data), extended)
        self._babbler = _Babbler(can_id, bytes(data), extended, bits, self.now)

    def stop_babble(self) -> int:
        """Silence the babbling node; returns how many frames it sent."""
        babbler, self._babbler = self._babbler, None
        return babbler.sent if babbler else 0

    def clear_faults(self) -> None:
        """Remove every injected frame fault and silence the babbler (bus-off stays)."""
        self.faults.clear()
        self._babbler = None

    # ----------------------------------------------------------------- transmission
    def submit(self, sender: SimBus, msg: can.Message) -> None:
        """Queue a frame in the sender's transmit FIFO (endpoints call this from `send`)."""
        with self._lock:
            if self.mode == "realtime":
                sender._tx.append((time.time(), msg))
                self._pending += 1
                self._wake.notify()
                return
            if (
                self.auto_deliver
                and not self._delivering
                and not self._pending
                and self._babbler is None
                and not self.faults
            ):
                # Idle bus, nothing to arbitrate against: straight onto the wire, then
                # deliver whatever the receivers queued in answer.
                self._delivering = True
                try:
                    self._transmit(sender, msg, self._now)
                finally:
                    self._delivering = False
                if self._pending:
                    self.deliver()
                return
            sender._tx.append((self._now, msg))
            self._pending += 1
            if self.auto_deliver and not self._delivering:
                self.deliver()

    def _release_delayed(self) -> None:
        now = self._now if self.mode == "lockstep" else time.time()
        while self._delayed and self._delayed[0].release <= now:
            item = heapq.heappop(self._delayed)
            self._transmit(item.sender, item.msg, item.release)

    def deliver(self) -> int:
        """Put every queued frame on the wire in arbitration order; returns frames delivered.

        Frames queued by listeners while delivering join the same arbitration round.
        """
        with self._lock:
            if self._delivering:
                return 0
            self._delivering = True
            delivered = 0
            endpoints, faults = self.endpoints, self.faults  # both mutated in place only
            try:
                while self._pending or self._babbler:
                    winner = None
                    best = None
                    for bus in endpoints:
                        tx = bus._tx
                        if tx:
                            key = _priority(tx[0][1])
                            if best is None or key < best:
                                best, winner = key, bus
                    babbler = self._babbler
                    if babbler is not None and (
                        # (can_id, IDE) before the queue head's (base ID, IDE)
                        best is None or babbler.can_id << 1 | babbler.extended < best >> 19
                    ):
                        # The babbler only fills wire time up to now; starved frames wait.
                        if self._bus_free_at >= self.now:
                            break
                        self._transmit_babble(babbler)
                        continue
                    if winner is None:
                        break
                    queued_at, msg = winner._tx.popleft()
                    self._pending -= 1
                    if faults and self._apply_faults(winner, msg):
                        continue
                    self._transmit(winner, msg, queued_at)
                    delivered += 1
            finally:
                self._delivering = False
            return delivered

    def _apply_faults(self, sender: SimBus, msg: can.Message) -> bool:
        """True if a fault consumed the frame."""
        if not self.faults:
            return False
        for fault in self.faults:
            if fault.matches(sender, msg):
                if fault.count is not None:
                    fault.count -= 1
                    if fault.count <= 0:
                        self.faults.remove(fault)
                if fault.kind == "drop":
                    self.dropped_frames += 1
                    return True
                if fault.kind == "corrupt":
                    self._transmit_error(sender, msg)
                    return True
                if fault.kind == "delay":
                    heapq.heappush(
                        self._delayed,
                        _Delayed(self.now + fault.delay_s, next(self._seq), sender, msg),
                    )
                    return True
        return False

    def _occupy(self, queued_at: float, bits: int, is_sync: bool) -> float:
        start = max(self._bus_free_at, queued_at)
        if self.mode == "realtime":
            start = max(start, time.time())
        end = start + bits / self.bitrate
        self._bus_free_at = end
        self.load.account(start, bits, is_sync)
        return end

    def _transmit(self, sender: SimBus | None, msg: can.Message, queued_at: float) -> None:
        ident = msg.arbitration_id
        extended = msg.is_extended_id
        if msg.is_remote_frame:
            bits = frame_bits(ident, b"", extended, True, msg.dlc)
            is_sync = False
        else:
            bits = data_frame_bits(ident, msg.data, extended)
            is_sync = ident == self.sync_id and not extended
        # `_occupy`, inlined: this runs for every frame
        start = self._bus_free_at
        if queued_at > start:
            start = queued_at
        if self.mode == "realtime":
            start = max(start, time.time())
        end = start + bits / self.bitrate
        self._bus_free_at = end
        load = self.load
        if is_sync:
            load.account(start, bits, True)
        else:  # `BusLoadAccount.account` for a frame inside the SYNC window
            load._window_bits += bits
            load._window_frames += 1
            load.total_bits += bits
            load.total_frames += 1
        kind = "pdo" if 0x180 <= ident < 0x580 else "sdo" if 0x580 <= ident < 0x680 else "other"
        latency = end - queued_at
        worst = self.worst_latency_s
        if latency > worst[kind]:
            worst[kind] = latency
        if type(msg) is OwnedMessage:  # handed over: it becomes the received frame
            msg.__class__ = can.Message  # type: ignore[assignment]
            msg.timestamp = end
            msg.channel = self.channel
            msg.is_rx = True
            self._fan_out(sender, msg)
            return
        # A fresh received copy of `msg`, filled slot by slot: Message() costs ~3 us.
        wire = new_message(can.Message)
        wire.timestamp = end
        wire.arbitration_id = ident
        wire.is_extended_id = extended
        wire.is_remote_frame = msg.is_remote_frame
        wire.is_error_frame = False
        wire.channel = self.channel
        wire.dlc = msg.dlc
        wire.data = bytearray(msg.data)
        wire.is_fd = wire.bitrate_switch = wire.error_state_indicator = False
        wire.is_rx = True
        self._fan_out(sender, wire)

    def _transmit_error(self, sender: SimBus, msg: can.Message) -> None:
        # The corrupted frame occupies the wire until the error flag, then the error frame.
        bits = (
            frame_bits(msg.arbitration_id, bytes(msg.data), msg.is_extended_id) + ERROR_FRAME_BITS
        )
        end = self._occupy(self.now, bits, False)
        self.error_frames += 1
        error = can.Message(timestamp=end, is_error_frame=True, channel=self.channel, check=False)
        self._fan_out(sender, error)

    def _transmit_babble(self, babbler: _Babbler) -> None:
        end = self._occupy(babbler.since, babbler.bits, False)
        babbler.sent += 1
        wire = can.Message(
            timestamp=end,
            arbitration_id=babbler.can_id,
            is_extended_id=babbler.extended,
            data=babbler.data,
            channel=self.channel,
            check=False,
        )
        self._fan_out(None, wire)

    def _fan_out(self, sender: SimBus | None, wire: can.Message) -> None:
        for observer in self.observers:
            observer(wire)
        ident = -1 if wire.is_extended_id or wire.is_error_frame else wire.arbitration_id
        for bus in self.endpoints:
            if bus is sender and not bus.receive_own_messages:
                continue
            if bus._bus_off:
                continue
            accept = bus.accept_ids
            if accept is not None and ident not in accept:
                continue
            listeners = bus._listeners
            if listeners:  # `bus._receive` inlined for the synchronous listeners
                for listener in listeners:
                    listener(wire)
            else:
                bus._receive(wire)

    # ----------------------------------------------------------------- realtime
    def start(self) -> None:
        """Realtime: start the delivery and tick thread."""
        if self.mode != "realtime":
            raise RuntimeError("start() is for realtime hubs; step a lockstep hub with advance()")
        if self._worker is not None:
            return
        RealtimeProcess.acquire()  # the GC in the slack, short GIL switch interval
        self._running = True
        self._worker = threading.Thread(
            target=self._run, name=f"canhub-{self.channel}", daemon=True
        )
        self._worker.start()

    def stop(self) -> None:
        """Realtime: stop the delivery thread (frames still queued stay queued)."""
        if self._worker is None:
            return
        with self._lock:
            self._running = False
            self._wake.notify()
        self._worker.join(timeout=5.0)
        self._worker = None
        RealtimeProcess.release()

    def _run(self) -> None:
        # Frames wake the condition and are delivered at once (a SYNC's TPDOs are answered
        # from here). Ticks need no spin: the drives integrate the measured dt. Garbage is
        # collected in the slack before a tick, when no frame is waiting.
        perf = time.perf_counter
        tick = self.realtime_tick_s
        next_tick = perf() + tick
        last = perf()
        while True:
            with self._lock:
                if not self._running:
                    return
                timeout = next_tick - perf()
                if timeout > 0 and not self._pending:
                    RealtimeProcess.collect_in_slack(timeout)
                    timeout = next_tick - perf()
                    if timeout > 0:
                        self._wake.wait(timeout)
                if not self._running:
                    return
                self._release_delayed()
                self.deliver()
                now = perf()
                if now >= next_tick:
                    self.ticks += 1
                    if now - next_tick > tick:
                        self.late_ticks += 1
                        next_tick = now  # skip missed ticks rather than bursting to catch up
                    next_tick += tick
                    dt, last = now - last, now
                    for participant in list(self.clocked):
                        try:
                            participant.advance(dt)
                        except Exception:  # keep the bus running for everyone else
                            self.tick_errors += 1
                            logger.exception("clocked participant %r failed", participant)
                    self.deliver()

    def close(self) -> None:
        """Stop the thread (realtime) and detach every endpoint."""
        self.stop()
        for bus in list(self.endpoints):
            bus.shutdown()


class SimBus(can.BusABC):
    """A python-can endpoint on a `CanHub`.

    Received frames go to synchronous listeners if any are attached (`add_listener`, used by
    the slaves: no thread, no queue), otherwise to a bounded receive queue read by `recv()`
    (used by `can.Notifier`, e.g. a `canopen.Network` after `connect()`).
    """

    def __init__(
        self,
        channel: str | None = None,
        can_filters: Any = None,
        *,
        hub: CanHub | None = None,
        name: str = "",
        receive_own_messages: bool = False,
        **kwargs: Any,
    ) -> None:
        if hub is None:
            hub = get_hub(str(channel or "can0"), bitrate=int(kwargs.pop("bitrate", 1_000_000)))
        self.hub = hub
        self.channel = hub.channel
        self.channel_info = f"fmscell simulated CAN {hub.channel} ({name or 'endpoint'})"
        self.name = name
        self.receive_own_messages = receive_own_messages
        self._tx: deque[tuple[float, can.Message]] = deque()
        self._rx: deque[can.Message] = deque()
        self._rx_cond = threading.Condition()
        self._listeners: list[Listener] = []
        self._accepts: dict[Listener, set[int] | None] = {}
        self._bus_off = False
        self.rx_overruns = 0
        #: acceptance filter like a controller's: 11-bit IDs delivered to this endpoint, or
        #: None for everything (29-bit and error frames are then filtered out as well)
        self.accept_ids: set[int] | None = None
        super().__init__(channel=hub.channel, can_filters=can_filters, **kwargs)
        hub._attach(self)

    def add_listener(self, listener: Listener, accept: set[int] | None = None) -> None:
        """Deliver received frames by calling `listener(msg)` in the delivering thread.

        `accept` (11-bit IDs) lets the hub skip frames no listener wants, like a
        controller's acceptance filter; one listener without `accept` disables filtering.
        """
        self._listeners.append(listener)
        self._accepts[listener] = accept
        self._update_filter()

    def set_accept(self, listener: Listener, accept: set[int] | None) -> None:
        """Change the identifiers `listener` wants (None = everything)."""
        self._accepts[listener] = accept
        self._update_filter()

    def remove_listener(self, listener: Listener) -> None:
        self._listeners.remove(listener)
        self._accepts.pop(listener, None)
        self._update_filter()

    def _update_filter(self) -> None:
        wanted = list(self._accepts.values())
        if not wanted or any(a is None for a in wanted):
            self.accept_ids = None
        else:
            self.accept_ids = {i for ids in wanted if ids is not None for i in ids}

    @property
    def bus_off(self) -> bool:
        return self._bus_off

    @property
    def state(self) -> can.BusState:
        return can.BusState.ERROR if self._bus_off else can.BusState.ACTIVE

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        raise NotImplementedError("the simulated bus state changes only through hub faults")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._is_shutdown:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        if self._bus_off:
            raise can.CanOperationError(f"{self.channel_info} is bus-off")
        if not msg.is_remote_frame and len(msg.data) > 8:
            raise can.CanOperationError(f"classic CAN frame with {len(msg.data)} data bytes")
        self.hub.submit(self, msg)

    def _receive(self, msg: can.Message) -> None:
        if self._listeners:
            for listener in self._listeners:
                listener(msg)
            return
        with self._rx_cond:
            if len(self._rx) >= self.hub.rx_queue_limit:
                self.rx_overruns += 1  # a real controller overruns too (EMCY 0x8110)
                return
            self._rx.append(msg)
            self._rx_cond.notify()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        with self._rx_cond:
            if not self._rx:
                if timeout == 0:
                    return None, False
                self._rx_cond.wait(timeout)
                if not self._rx:
                    return None, False
            return self._rx.popleft(), False

    def fileno(self) -> int:
        return -1

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        self.hub._detach(self)
        super().shutdown()


def connect_network(network: Any, endpoint: SimBus) -> Any:
    """Put a `canopen.Network` on an endpoint without a Notifier thread.

    Frames reach the network's listeners synchronously in the delivering call, so a stock
    master runs deterministically under a lockstep hub (an SDO request is answered before
    `send` returns). `network.connect()` with the endpoint as `bus` also works, threaded.
    """
    network.bus = endpoint
    for listener in network.listeners:
        endpoint.add_listener(listener.on_message_received)
    return network
