"""A CiA 301 slave: NMT, heartbeat, SDO, PDO, SYNC and EMCY around a `DriveApplication`.

`CanopenSlave.handle(msg)` processes one received frame and `advance(dt)` runs the timers;
both send through the python-can bus given at construction and do nothing else, so the same
object runs under the lockstep hub (which calls both), under a realtime hub, or on any
python-can bus through `start()`, a small receive-and-tick thread.
"""

from __future__ import annotations

import copy
import logging
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Final

import can
import canopen

from drives import EDS_PATH
from drives.application import DriveApplication, ObjectAccessError
from drives.bus.hub import SimBus
from drives.bus.message import owned_frame
from drives.cia301.emcy import EmcyProducer
from drives.cia301.heartbeat import HeartbeatConsumer, HeartbeatProducer
from drives.cia301.nmt import (
    RESET_COMMUNICATION,
    RESET_NODE,
    NmtState,
    emcy_allowed,
    nmt_transition,
    pdo_allowed,
    sdo_allowed,
)
from drives.cia301.od import ObjectDictionary
from drives.cia301.pdo import PdoChannel, PdoService
from drives.cia301.sdo_server import SdoServer
from drives.cia301.store import ParameterStore
from drives.cia301.sync import SyncConsumer
from drives.realtime import RealtimeProcess

logger = logging.getLogger(__name__)

EMCY_HEARTBEAT_LOST: Final = 0x8130
EMCY_BUS_OFF_RECOVERED: Final = 0x8140
EMCY_RPDO_TIMEOUT: Final = 0x8250
EMCY_SYNC_TIMEOUT: Final = 0x8100
EMCY_PDO_LENGTH: Final = 0x8210
EMCY_PDO_LENGTH_EXCEEDED: Final = 0x8220
EMCY_SYNC_LENGTH: Final = 0x8240


class CanopenSlave:
    """One CANopen node. See the module docstring; `docs/canopen.md` lists the behaviour."""

    def __init__(
        self,
        node_id: int,
        bus: can.BusABC,
        application: DriveApplication,
        *,
        eds_path: str = EDS_PATH,
        boot: bool = True,
        sdo_timeout_s: float = 1.0,
    ) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"node_id must be 1..127, got {node_id}")
        self.node_id = node_id
        self.bus = bus
        self.application = application
        self.state = NmtState.INITIALISING
        self.time_s = 0.0
        self.send_failures = 0
        self.handler_errors = 0
        self._bus_off = False
        self._guard_toggle = 0
        self._lock = threading.RLock()
        self._dispatch: dict[int, Callable[[can.Message], None]] = {}
        self._sync_rpdos: list[PdoChannel] = []
        self._sync_tpdos: list[PdoChannel] = []
        self._event_tpdos: list[PdoChannel] = []
        self._deadline_rpdos: list[PdoChannel] = []
        self._worker: threading.Thread | None = None
        self._running = False
        self.od = ObjectDictionary(eds_path, node_id, application)
        self.emcy = EmcyProducer(self.od)
        self.heartbeat = HeartbeatProducer(self.od)
        self.consumer = HeartbeatConsumer(self.od)
        self.sync = SyncConsumer(self.od, self._rebuild_dispatch)
        self.sdo = SdoServer(self.od, timeout_s=sdo_timeout_s)
        self.pdo = PdoService(self.od, self._rebuild_dispatch)
        self.store = ParameterStore(self.od)
        self._life_guarding = False
        self._life_guard_lost = False
        self._since_guard_s = 0.0
        consumer_hook = self.od.write_hooks.get(0x1016)
        if consumer_hook is not None:

            def write_consumer(entry, value):
                consumer_hook(entry, value)
                self._rebuild_dispatch()

            self.od.write_hooks[0x1016] = write_consumer
        if isinstance(bus, SimBus):
            bus.add_listener(self.handle)
            bus.hub.add_clocked(self)
        self._rebuild_dispatch()  # also installs the acceptance filter on a SimBus
        if boot:
            self.boot()

    # ------------------------------------------------------------------ dispatch
    def _rebuild_dispatch(self) -> None:
        if not hasattr(self, "pdo"):
            return  # services still being constructed
        n = self.node_id
        table: dict[int, Callable[[can.Message], None]] = {
            0x000: self._on_nmt,
            self.sync.cob_id: self._on_sync,
            0x600 + n: self._on_sdo,
            0x700 + n: self._on_guarding,
        }
        for node_id in self.consumer.monitored:
            table.setdefault(0x700 + node_id, self._on_heartbeat)
        for channel in self.pdo.rpdos:
            if channel.valid:
                table.setdefault(channel.cob_id, partial(self._on_rpdo, channel))
        for channel in self.pdo.tpdos:
            if channel.valid and channel.rtr_allowed:
                table.setdefault(channel.cob_id, partial(self._on_tpdo_rtr, channel))
        self._dispatch = table
        if isinstance(self.bus, SimBus):
            self.bus.set_accept(self.handle, set(table))  # the hub skips frames we ignore
        # The per-SYNC and per-tick loops only visit channels that can act.
        self._sync_rpdos = [c for c in self.pdo.rpdos if c.valid and c.synchronous]
        self._sync_tpdos = [c for c in self.pdo.tpdos if c.valid and c.synchronous]
        self._event_tpdos = [c for c in self.pdo.tpdos if c.valid and c.event_driven]
        self._deadline_rpdos = [c for c in self.pdo.rpdos if c.valid and c.event_timer_ms]

    def handle(self, msg: can.Message) -> None:
        """Process one received frame (replies go out through the bus)."""
        if msg.is_error_frame or msg.is_extended_id:
            return
        handler = self._dispatch.get(msg.arbitration_id)
        if handler is not None:
            with self._lock:
                try:
                    handler(msg)
                except Exception:
                    # A failing application must not break the bus delivery of other nodes.
                    self.handler_errors += 1
                    logger.exception("node %d: frame %03X failed", self.node_id, msg.arbitration_id)

    # ------------------------------------------------------------------ sending
    def _send(self, cob_id: int, data: bytes, *, remote: bool = False) -> bool:
        msg = owned_frame(cob_id, data, remote)
        try:
            self.bus.send(msg)
        except can.CanError:
            self.send_failures += 1
            self._bus_off = True
            return False
        if self._bus_off:
            self._bus_off = False
            # Reported once after recovery, with the communication bit set while it is sent.
            self.emcy.communication_errors.add(EMCY_BUS_OFF_RECOVERED)
            self._emit_emcy(EMCY_BUS_OFF_RECOVERED)
            self.emcy.communication_errors.discard(EMCY_BUS_OFF_RECOVERED)
            self.application.on_communication_fault(EMCY_BUS_OFF_RECOVERED)
            self._pump_application_emcy()
        return True

    def _emit_emcy(self, error_code: int, manufacturer: bytes = b"\x00" * 5) -> None:
        data = self.emcy.frame(error_code, manufacturer)
        if self.emcy.cob_id is None:
            return
        self.emcy.queue.append(data)
        self._flush_emcy()

    def _flush_emcy(self) -> None:
        """Send queued EMCYs as far as the NMT state and the inhibit time 0x1015 allow."""
        cob_id = self.emcy.cob_id
        if cob_id is None or not emcy_allowed(self.state):
            return
        emcy = self.emcy
        while emcy.queue and emcy.may_send():
            if emcy.inhibit_s:
                emcy.since_sent_s = 0.0
            self._send(cob_id, emcy.queue.popleft())

    def _pump_application_emcy(self) -> None:
        for request in self.application.take_emcy():
            self.emcy.application_register = request.error_register & 0xFF
            self._emit_emcy(request.error_code, request.manufacturer)

    def _raise_communication_error(self, code: int) -> None:
        """A communication fault: EMCY once per condition, then tell the application."""
        if code in self.emcy.communication_errors:
            return
        self.emcy.communication_errors.add(code)
        self._emit_emcy(code)
        self.application.on_communication_fault(code)
        self._pump_application_emcy()

    def _clear_communication_error(self, code: int) -> None:
        if code in self.emcy.communication_errors:
            self.emcy.communication_errors.discard(code)
            self._emit_emcy(0x0000)

    # ------------------------------------------------------------------ NMT
    def boot(self) -> None:
        """Initialising -> boot-up frame -> Pre-operational (power-on or after a reset)."""
        with self._lock:
            self._set_state(NmtState.INITIALISING)
            self._send(0x700 + self.node_id, b"\x00")
            self.heartbeat.elapsed_s = 0.0
            self._set_state(NmtState.PRE_OPERATIONAL)

    def _set_state(self, state: NmtState) -> None:
        if state is self.state:
            return
        self.state = state
        self.application.on_nmt_state(state.label)
        if self.emcy.queue:
            self._flush_emcy()
        if state is not NmtState.OPERATIONAL:
            for channel in self.pdo.rpdos:
                channel.pending = None
        else:
            for channel in self.pdo.tpdos:
                channel.last_sent, channel.since_sent, channel.sync_count = None, 1e9, 0
                channel.started = False
        self._pump_application_emcy()

    def reset_communication(self) -> None:
        """NMT reset communication: 0x1000-0x1FFF back to defaults, then boot-up."""
        with self._lock:
            self.od.reset(0x1000, 0x1FFF)
            self.store.apply(0x1000, 0x1FFF)
            self._reset_services()
            self._notify_reset("communication")
            self.boot()

    def reset_node(self) -> None:
        """NMT reset node: every stored object back to its default, then boot-up."""
        with self._lock:
            self._notify_reset("node")  # before the kept parameters are written back
            self.od.reset(0x0000, 0xFFFF)
            self.store.apply(0x0000, 0xFFFF)
            self._reset_services()
            self.boot()

    def _notify_reset(self, scope: str) -> None:
        # Optional hook beyond the DriveApplication protocol: on_nmt_state('INITIALISING')
        # alone cannot tell "reload your parameters" (node) from "keep them" (communication).
        hook = getattr(self.application, "on_nmt_reset", None)
        if hook is not None:
            hook(scope)

    def _reset_services(self) -> None:
        self.emcy.communication_errors.clear()
        self.emcy.history.clear()
        self.emcy.queue.clear()
        self.sdo.reset()
        self.sync.reset()
        self.consumer.reload()
        self.pdo.reload()
        self._guard_toggle = 0
        self._life_guarding = self._life_guard_lost = False
        self._since_guard_s = 0.0

    def _on_nmt(self, msg: can.Message) -> None:
        data = msg.data
        if len(data) != 2 or data[1] not in (0, self.node_id):
            return
        if self.state is NmtState.INITIALISING:
            return
        result = nmt_transition(self.state, data[0])
        if result is None:
            return
        if result == RESET_NODE:
            self.reset_node()
        elif result == RESET_COMMUNICATION:
            self.reset_communication()
        elif isinstance(result, NmtState):
            self._set_state(result)

    def _on_guarding(self, msg: can.Message) -> None:
        # Node guarding answers an RTR only when the heartbeat producer is off (CiA 301).
        if not msg.is_remote_frame or self.heartbeat.period_s > 0:
            return
        if self.state is NmtState.INITIALISING:
            return
        self._send(0x700 + self.node_id, bytes([(self._guard_toggle << 7) | self.state.value]))
        self._guard_toggle ^= 1
        # Life guarding starts with the first guard RTR (CiA 301 7.2.8.3.1).
        self._life_guarding = True
        self._since_guard_s = 0.0
        if self._life_guard_lost:
            self._life_guard_lost = False
            if not self.consumer.any_timeout:
                self._clear_communication_error(EMCY_HEARTBEAT_LOST)

    def _on_heartbeat(self, msg: can.Message) -> None:
        if msg.is_remote_frame or not msg.data:
            return
        recovered = self.consumer.on_heartbeat(msg.arbitration_id - 0x700, msg.data[0])
        if recovered and not self.consumer.any_timeout and not self._life_guard_lost:
            self._clear_communication_error(EMCY_HEARTBEAT_LOST)

    # ------------------------------------------------------------------ SDO
    def _on_sdo(self, msg: can.Message) -> None:
        if not sdo_allowed(self.state) or msg.is_remote_frame:
            return
        tx = 0x580 + self.node_id
        for response in self.sdo.on_request(bytes(msg.data)):
            self._send(tx, response)
        self._pump_application_emcy()
        if self._event_tpdos and self.state is NmtState.OPERATIONAL:
            self._send_event_tpdos(0.0)  # a write may have changed mapped data: report now

    # ------------------------------------------------------------------ SYNC and PDO
    def _on_sync(self, msg: can.Message) -> None:
        state = self.state
        operational = state is NmtState.OPERATIONAL
        # `sync_allowed(state)`, inlined: every SYNC reaches every node
        if not (operational or state is NmtState.PRE_OPERATIONAL) or msg.is_remote_frame:
            return
        sync = self.sync
        overflow = sync.overflow
        if len(msg.data) != (1 if overflow else 0):
            self._raise_communication_error(EMCY_SYNC_LENGTH)
            return
        counter = msg.data[0] if overflow else 0
        if sync.on_sync():
            self._clear_communication_error(EMCY_SYNC_TIMEOUT)
        pdo = self.pdo
        if operational:
            for channel in self._sync_rpdos:
                if channel.pending is not None:
                    data, channel.pending = channel.pending, None
                    pdo.unpack(channel, data)
        self.application.on_sync()
        if operational:
            for channel in self._sync_tpdos:
                if channel.trans_type == 0:
                    data = pdo.pack(channel)
                    if data != channel.last_sent:
                        self._send_tpdo(channel, data)
                else:
                    if not channel.started:
                        # With a SYNC counter and a start value the first transmission is at
                        # the SYNC whose counter equals it; otherwise at the n-th SYNC
                        # (CANopenNode, CTT "PDO 13").
                        if overflow and channel.sync_start:
                            if counter != channel.sync_start:
                                continue
                            channel.sync_count = channel.trans_type - 1
                        channel.started = True
                    channel.sync_count += 1
                    if channel.sync_count >= channel.trans_type:
                        channel.sync_count = 0
                        self._send_tpdo(channel, pdo.pack(channel))
        self._pump_application_emcy()

    def _send_tpdo(self, channel: PdoChannel, data: bytes) -> None:
        if self._send(channel.cob_id, data):
            channel.last_sent = data
            channel.since_sent = 0.0

    def _on_rpdo(self, channel: PdoChannel, msg: can.Message) -> None:
        # `pdo_allowed(self.state)`, inlined: every RPDO of every cycle
        if self.state is not NmtState.OPERATIONAL or msg.is_remote_frame:
            return
        channel.since_rx, channel.rx_seen = 0.0, True
        if channel.timed_out:
            channel.timed_out = False
            if not any(c.timed_out for c in self.pdo.rpdos):
                self._clear_communication_error(EMCY_RPDO_TIMEOUT)
        size = len(msg.data)
        if size < channel.length:
            channel.length_error = True
            self._raise_communication_error(EMCY_PDO_LENGTH)
            return
        if size > channel.length:
            self._raise_communication_error(EMCY_PDO_LENGTH_EXCEEDED)
        elif channel.length_error or self.emcy.communication_errors:
            channel.length_error = False
            if not any(c.length_error for c in self.pdo.rpdos):
                self._clear_communication_error(EMCY_PDO_LENGTH)
            self._clear_communication_error(EMCY_PDO_LENGTH_EXCEEDED)
        if channel.trans_type <= 240:  # `channel.synchronous`
            channel.pending = bytes(msg.data)
        else:
            self.pdo.unpack(channel, msg.data)
            self._pump_application_emcy()
            if self._event_tpdos:
                self._send_event_tpdos(0.0)  # e.g. the statusword answering a controlword

    def _on_tpdo_rtr(self, channel: PdoChannel, msg: can.Message) -> None:
        if msg.is_remote_frame and pdo_allowed(self.state):
            self._send_tpdo(channel, self.pdo.pack(channel))

    # ------------------------------------------------------------------ time
    def advance(self, dt_s: float) -> None:
        """Run the timers over dt_s, integrate the application, send what became due."""
        with self._lock:
            self.time_s += dt_s
            state = self.state
            if state is NmtState.INITIALISING:
                return
            emcy = self.emcy
            emcy.since_sent_s += dt_s
            if emcy.queue:
                self._flush_emcy()
            if self.heartbeat.due(dt_s):
                self._send(0x700 + self.node_id, bytes([state.value]))
            if self.sdo.transfer is not None:
                for response in self.sdo.advance(dt_s):
                    self._send(0x580 + self.node_id, response)
            consumer = self.consumer
            if consumer.monitored and consumer.advance(dt_s):
                self._raise_communication_error(EMCY_HEARTBEAT_LOST)
            if self.sync.advance(dt_s) and state is NmtState.OPERATIONAL:
                self._raise_communication_error(EMCY_SYNC_TIMEOUT)
            if self._life_guarding:
                self._check_life_guarding(dt_s)
            if self._deadline_rpdos and state is NmtState.OPERATIONAL:
                self._check_rpdo_deadlines(dt_s)
            self.application.advance(dt_s)
            self._pump_application_emcy()
            if self._event_tpdos and self.state is NmtState.OPERATIONAL:
                self._send_event_tpdos(dt_s)

    def _check_life_guarding(self, dt_s: float) -> None:
        self._since_guard_s += dt_s
        lifetime_ms = int(self.od.get(0x100C, 0)) * int(self.od.get(0x100D, 0))
        if lifetime_ms and not self._life_guard_lost and self._since_guard_s * 1e3 > lifetime_ms:
            self._life_guard_lost = True
            self._raise_communication_error(EMCY_HEARTBEAT_LOST)

    def _check_rpdo_deadlines(self, dt_s: float) -> None:
        # 0x14xx:05 is the RPDO deadline (CANopenNode): monitoring starts at the first frame.
        for channel in self._deadline_rpdos:
            if not channel.rx_seen or channel.timed_out:
                continue
            channel.since_rx += dt_s
            if channel.since_rx * 1e3 > channel.event_timer_ms:
                channel.timed_out = True
                self._raise_communication_error(EMCY_RPDO_TIMEOUT)

    def _send_event_tpdos(self, dt_s: float) -> None:
        for channel in self._event_tpdos:
            channel.since_sent += dt_s
            if channel.since_sent + 1e-12 < channel.inhibit_100us * 1e-4:
                continue
            data = self.pdo.pack(channel)
            timer = channel.event_timer_ms * 1e-3
            if data != channel.last_sent or (timer > 0 and channel.since_sent + 1e-12 >= timer):
                self._send_tpdo(channel, data)

    # ------------------------------------------------------------------ artefacts
    def export_dcf(self, dest) -> None:
        """Write this node's DCF: the EDS plus current values and its node-ID/bitrate.

        Values go out as `ParameterValue` text written here (decimal integers) because
        canopen's own formatter writes negative integers as `0x-3`, which it cannot read back.
        """
        od = copy.deepcopy(self.od.definitions)
        od.node_id = self.node_id
        if isinstance(self.bus, SimBus):
            od.bitrate = self.bus.hub.bitrate
        with self._lock:
            for (index, subindex), entry in self.od.entries.items():
                if not entry.readable:
                    continue
                try:
                    value = self.od.get(index, subindex)
                except ObjectAccessError:
                    continue
                obj = od[index]
                var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[subindex]
                if isinstance(value, bytes | bytearray):
                    var.value_raw = bytes(value).hex()  # type: ignore[attr-defined]
                elif isinstance(value, float):
                    var.value_raw = repr(value)  # type: ignore[attr-defined]
                elif isinstance(value, str):
                    var.value_raw = value  # type: ignore[attr-defined]
                else:
                    var.value_raw = str(int(value))  # type: ignore[attr-defined]
                if getattr(var, "relative", False) and var.default is not None:
                    var.default_raw = f"$NODEID+0x{var.default:X}"  # type: ignore[attr-defined]
        canopen.export_od(od, dest, doc_type="dcf")

    # ------------------------------------------------------------------ realtime shell
    def start(self, tick_s: float = 0.001) -> None:
        """Serve in realtime on a plain python-can bus: one thread receives and ticks.

        On a `SimBus` the hub delivers and ticks instead: a realtime hub is started here, a
        lockstep hub is stepped by its owner.
        """
        if isinstance(self.bus, SimBus):
            if self.bus.hub.mode == "realtime":
                self.bus.hub.start()
                return
            raise RuntimeError("lockstep hub: step it with hub.advance(dt) instead of start()")
        if self._worker is not None:
            return
        RealtimeProcess.acquire()  # the GC in the slack, short GIL switch interval
        self._running = True
        self._worker = threading.Thread(
            target=self._serve, args=(tick_s,), name=f"canopen-slave-{self.node_id}", daemon=True
        )
        self._worker.start()

    def stop(self) -> None:
        self._running = False
        if self._worker is not None:
            self._worker.join(timeout=5.0)
            self._worker = None
            RealtimeProcess.release()

    def _serve(self, tick_s: float) -> None:
        last = next_tick = time.perf_counter()
        next_tick += tick_s
        while self._running:
            # garbage collection in the slack before the tick, not while a frame waits
            slack = next_tick - time.perf_counter()
            RealtimeProcess.collect_in_slack(slack)
            msg = self.bus.recv(timeout=max(0.0, slack))
            if msg is not None:
                self.handle(msg)
            now = time.perf_counter()
            if now >= next_tick:
                self.advance(now - last)
                last = now
                next_tick = max(next_tick + tick_s, now)
