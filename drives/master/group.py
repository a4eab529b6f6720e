"""The axis group: the CANopen master the NC uses to close its axes over CiA 402 drives.

Built on the `canopen` library for everything acyclic (a `RemoteNode` per drive for SDO
configuration and NMT), with its own cyclic path: per IPO cycle it sends one RPDO
(controlword + target position) per axis, then SYNC, and reads one TPDO (statusword +
position actual, and optionally a second with the following error) per axis. The stock
library's periodic-TPDO waits measure wall time, so they are not used here.

Two time bases, picked from the buses:

* lockstep (every bus is a `SimBus` on a lockstep `CanHub`): `cycle()` sends, the hub
  delivers inside the send calls, then the group advances each hub by one IPO cycle (the
  drives integrate their plants). Nothing sleeps; the same scenario gives the same trace.
* realtime (any other python-can bus, e.g. socketcan or a realtime hub): `cycle()` waits
  for its slot on the wall clock (absolute deadlines), sends, and waits for the TPDOs with
  a deadline of one IPO cycle; late cycles and lateness are counted in `stats`.
"""

from __future__ import annotations

import contextlib
import logging
import math
import struct
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Final

import can
import canopen
from canopen.sdo.exceptions import SdoError

from drives import EDS_PATH
from drives.bus.hub import CanHub, SimBus
from drives.bus.loadplan import BusOverloadError, CyclicFrame, LoadPlan, plan_load
from drives.bus.message import owned_frame
from drives.master import power
from drives.master.config import AxisConfig, AxisError, AxisFault, AxisFeedback
from drives.realtime import Pacer, RealtimeProcess

logger = logging.getLogger(__name__)

_RPDO: Final = struct.Struct("<Hi")  # controlword, target position
_TPDO1: Final = struct.Struct("<Hi")  # statusword, position actual
_I32: Final = struct.Struct("<i")
_EMCY: Final = struct.Struct("<HB")
_OE_MASK: Final = 0x6F
_OE: Final = 0x27
_STATE_NAMES: Final[dict[int, str]] = {}  # statusword -> power state name (at most 65536 entries)


@dataclass
class CycleStats:
    """Realtime figures: late = not every TPDO arrived before the next SYNC was due."""

    cycles: int = 0
    late_cycles: int = 0
    skipped_slots: int = 0
    lateness_s: list[float] = field(default_factory=list)  # SYNC send time - its slot
    tpdo_latency_s: list[float] = field(default_factory=list)  # SYNC sent -> last TPDO

    def summary(self) -> dict[str, float | int]:
        def p(values: list[float], q: float) -> float:
            if not values:
                return 0.0
            ordered = sorted(values)
            return ordered[min(len(ordered) - 1, int(q * len(ordered)))]

        return {
            "cycles": self.cycles,
            "late_cycles": self.late_cycles,
            "late_pct": 100.0 * self.late_cycles / self.cycles if self.cycles else 0.0,
            "skipped_slots": self.skipped_slots,
            "lateness_p50_us": p(self.lateness_s, 0.50) * 1e6,
            "lateness_p99_us": p(self.lateness_s, 0.99) * 1e6,
            "lateness_max_us": max(self.lateness_s, default=0.0) * 1e6,
            "tpdo_latency_p50_us": p(self.tpdo_latency_s, 0.50) * 1e6,
            "tpdo_latency_p99_us": p(self.tpdo_latency_s, 0.99) * 1e6,
        }


class _Axis:
    """Master-side image of one drive (touched from the bus thread in realtime)."""

    def __init__(self, cfg: AxisConfig, line: _Line, node: canopen.RemoteNode) -> None:
        self.cfg = cfg
        self.name = cfg.name
        self.node_id = cfg.node_id
        self.line = line
        self.node = node
        self.rpdo_cob = 0x200 + cfg.node_id
        self.cw = power.CW_DISABLE_VOLTAGE
        self.target = 0
        self.sw = 0
        self.pos = 0
        self.fe: int | None = None
        self.known = False  # a TPDO1 has been received since NMT start
        self.rx_cycle = -1  # group cycle number of the last TPDO1
        self.rx_time = 0.0
        self.booted = False
        self.hb_last: float | None = None
        self.hb_lost = False
        self.active: list[AxisFault] = []
        self.restarting = False  # the master itself asked for the boot-up (not a fault)
        self.missed = 0  # consecutive SYNC cycles without this axis's TPDO1
        self.feedback_lost = False


class _Line:
    """One CAN line: a bus, its canopen Network, and the axes on it."""

    def __init__(self, index: int, bus: can.BusABC, lockstep: bool) -> None:
        self.index = index
        self.bus = bus
        self.lockstep = lockstep
        self.hub: CanHub | None = bus.hub if isinstance(bus, SimBus) else None
        self.network = canopen.Network()
        #: 11-bit COB-ID -> handler(data) for the cyclic TPDOs on a simulated line: they
        #: skip the canopen Network's listener and subscriber lists (twice per axis per SYNC)
        self.cyclic: dict[int, Callable[[bytearray], None]] = {}
        if isinstance(bus, SimBus):
            # synchronous delivery, no Notifier thread (`connect_network` with a shortcut)
            self.network.bus = bus
            bus.add_listener(self._receive)
            self.threaded = False
        else:
            self.network.bus = bus
            self.network.connect()  # Notifier thread on the user's bus
            self.threaded = True
        self.axes: list[_Axis] = []
        self.channel = str(getattr(bus, "channel_info", "") or getattr(bus, "channel", index))

    def _receive(self, msg: can.Message) -> None:
        handler = self.cyclic.get(msg.arbitration_id)
        if handler is not None and not (
            msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame
        ):
            handler(msg.data)
            return
        for listener in self.network.listeners:
            listener.on_message_received(msg)

    def close(self) -> None:
        net = self.network
        if self.threaded and net.notifier is not None:
            net.notifier.stop(1.0)
            net.notifier = None
        elif isinstance(self.bus, SimBus):
            with contextlib.suppress(ValueError):  # already removed
                self.bus.remove_listener(self._receive)


#: What the operator does when a fault reset is refused because the cause is still there.
REMEDIES = {
    0x2310: "the power stage is shorted: the drive needs service",
    0x2350: "I2t above 80 %: let the motor rest (a few seconds unloaded), then reset",
    0x3130: "no mains at the drive: restore the supply, then reset",
    0x3210: "DC link above the chopper level: check the mains and the brake chopper",
    0x3220: "DC link below 250 V: restore the mains, then reset",
    0x4310: "winding above 130 degC: let the motor cool, then reset",
    0x7305: "encoder signal lost: check the encoder cable, then reset and home",
}


class AxisGroup:
    """A CiA 402 axis group on one or more CAN lines. See the module docstring.

    Sequence: `boot()` (NMT reset node, boot-up) -> `configure()` (bus-load plan, SDO:
    PDO mapping for CSP, 0x60C2, limits, following error, heartbeats, mode 8; NMT start) ->
    `enable()` -> `home()` -> `cycle(targets)` every IPO cycle. `quick_stop()`,
    `fault_reset()`, `disable()` for stops and recovery; faults come back in each
    `AxisFeedback.faults` and in `faults` / `take_faults()`.

    Parameters
    ----------
    buses:
        One python-can bus or a sequence (CAN lines); `AxisConfig.line` indexes it.
    axes:
        The axes (names and node-IDs unique per group / per line).
    ipo_cycle_s:
        IPO cycle = SYNC period = 0x60C2 interpolation period.
    heartbeat_ms:
        0x1017 producer time written to every drive; the group reports a drive whose
        heartbeat is missing for `heartbeat_timeout_factor` x that (0 = off).
    master_node_id:
        If set, the group produces its own heartbeat (every `heartbeat_ms`) and each drive
        consumes it (0x1016:1, timeout `heartbeat_timeout_factor` x) so a dead master stops
        the axes (0x8130 -> 0x6007 reaction).
    following_error_every:
        Map 0x60F4 following error into TPDO2 sent every n-th SYNC (0 = not mapped,
        feedback then carries None). TPDO1 (6 bytes) cannot also hold it.
    rpdo_deadline_ms:
        Write 0x1400:5 (RPDO deadline, CiA 301) so a drive whose RPDO1 stops arriving faults
        (EMCY 0x8250 -> 0x6007 reaction) after this long (0 = off).
    feedback_timeout_cycles:
        The master's own check of the cyclic feedback: an axis whose TPDO1 has not arrived
        for this many consecutive SYNC cycles (lost, destroyed or late) is reported as a
        fault 0x8100 "cyclic feedback lost" (0 = off; the heartbeat still catches a node
        that falls silent, after 3 heartbeat periods).
    sync_watchdog:
        Write 0x1006 = IPO cycle so a drive faults (0x8100) when SYNC stops for 1.5 cycles.
    bitrate:
        For the load plan of buses that are not simulated (a hub knows its own).
    paced:
        Lockstep only: pace each `cycle()` to the wall clock (absolute deadlines) and count
        a cycle late when it finishes after the next slot: a deterministic core run in
        real time from one thread.
    """

    def __init__(
        self,
        buses: can.BusABC | Sequence[can.BusABC],
        axes: Iterable[AxisConfig],
        *,
        ipo_cycle_s: float = 0.002,
        heartbeat_ms: int = 100,
        heartbeat_timeout_factor: float = 3.0,
        master_node_id: int | None = None,
        following_error_every: int = 1,
        rpdo_deadline_ms: int = 0,
        feedback_timeout_cycles: int = 0,
        sync_watchdog: bool = False,
        bitrate: int = 1_000_000,
        eds_path: str = EDS_PATH,
        boot_timeout_s: float = 2.0,
        paced: bool = False,
    ) -> None:
        bus_list: list[can.BusABC] = (
            list(buses) if isinstance(buses, list | tuple) else [buses]  # type: ignore[list-item]
        )
        if not bus_list:
            raise ValueError("axis group: no CAN bus given")
        self.axes_config = tuple(axes)
        if not self.axes_config:
            raise ValueError("axis group: no axes configured")
        if not 0.0005 <= ipo_cycle_s <= 0.008 + 1e-12:
            raise ValueError(f"axis group: ipo_cycle_s {ipo_cycle_s} outside 0.5..8 ms")
        if not 0 <= following_error_every <= 240:
            raise ValueError("axis group: following_error_every must be 0..240")
        if master_node_id is not None and not 1 <= master_node_id <= 127:
            raise ValueError(f"axis group: master_node_id must be 1..127, got {master_node_id}")
        if heartbeat_ms < 0 or heartbeat_ms > 0xFFFF:
            raise ValueError(f"axis group: heartbeat_ms must be 0..65535, got {heartbeat_ms}")
        kinds = {isinstance(b, SimBus) and b.hub.mode == "lockstep" for b in bus_list}
        if len(kinds) > 1:
            raise ValueError("axis group: cannot mix lockstep hubs with realtime buses")
        self.lockstep = kinds.pop()
        if paced and not self.lockstep:
            raise ValueError("axis group: paced=True is for lockstep hubs (realtime is paced)")
        self.paced = paced
        self.ipo_cycle_s = ipo_cycle_s
        self.heartbeat_ms = heartbeat_ms
        self.heartbeat_timeout_factor = heartbeat_timeout_factor
        self.master_node_id = master_node_id
        self.following_error_every = following_error_every
        self.sync_watchdog = sync_watchdog
        if not 0 <= rpdo_deadline_ms <= 0xFFFF:
            raise ValueError(
                f"axis group: rpdo_deadline_ms must be 0..65535, got {rpdo_deadline_ms}"
            )
        if feedback_timeout_cycles < 0:
            raise ValueError("axis group: feedback_timeout_cycles must be >= 0")
        self.rpdo_deadline_ms = rpdo_deadline_ms
        self.feedback_timeout_cycles = feedback_timeout_cycles
        self.bitrate = bitrate
        self.boot_timeout_s = boot_timeout_s
        self.stats = CycleStats()
        self.load_plans: list[LoadPlan] = []
        self.fault_log: list[AxisFault] = []
        self.time = 0.0
        self.cycle_count = 0
        self._new_faults: list[AxisFault] = []
        self._lock = threading.RLock()
        self._cond = threading.Condition(self._lock)
        self._running = False  # after configure(): boot-ups are faults, heartbeats watched
        self._t0 = time.perf_counter()
        self._slot: float | None = None
        self._pacer = Pacer(ipo_cycle_s)
        self._realtime_held = False
        self._sync_sent_at = 0.0
        self._hb_elapsed = 0.0
        self._waiting = 0
        self._lines = [_Line(i, b, self.lockstep) for i, b in enumerate(bus_list)]
        self._hubs: list[CanHub] = list(
            dict.fromkeys(
                line.hub for line in self._lines if line.hub is not None and line.lockstep
            )
        )
        self._axes: dict[str, _Axis] = {}
        seen_nodes: set[tuple[int, int]] = set()
        for cfg in self.axes_config:
            if cfg.name in self._axes:
                raise ValueError(f"axis group: axis name {cfg.name!r} used twice")
            if cfg.line >= len(self._lines):
                raise ValueError(
                    f"axis {cfg.name}: line {cfg.line} but only {len(self._lines)} bus(es) given"
                )
            if (cfg.line, cfg.node_id) in seen_nodes:
                raise ValueError(f"axis {cfg.name}: node {cfg.node_id} used twice on its line")
            if cfg.node_id == master_node_id:
                raise ValueError(f"axis {cfg.name}: node {cfg.node_id} is the master's node-ID")
            seen_nodes.add((cfg.line, cfg.node_id))
            line = self._lines[cfg.line]
            node = canopen.RemoteNode(cfg.node_id, eds_path)
            line.network.add_node(node)
            axis = _Axis(cfg, line, node)
            line.axes.append(axis)
            self._axes[cfg.name] = axis
            self._subscribe(axis)

    # ------------------------------------------------------------------ public state
    @property
    def axis_names(self) -> list[str]:
        return list(self._axes)

    def node(self, axis: str) -> canopen.RemoteNode:
        """The `canopen.RemoteNode` of an axis (SDO access for diagnostics)."""
        return self._axis(axis).node

    @property
    def faults(self) -> list[AxisFault]:
        """Faults active now (cleared by an EMCY 0000, a returning heartbeat, a fault reset)."""
        with self._cond:
            return [f for a in self._axes.values() for f in a.active]

    def take_faults(self) -> list[AxisFault]:
        """Faults reported since the last call (or since the last cycle's feedback)."""
        with self._cond:
            out, self._new_faults = self._new_faults, []
            return out

    def state(self, axis: str) -> str:
        return power.state_name(self._axis(axis).sw)

    def position_mm(self, axis: str) -> float:
        a = self._axis(axis)
        return a.cfg.to_mm(a.pos)

    def _axis(self, name: str) -> _Axis:
        try:
            return self._axes[name]
        except KeyError:
            raise KeyError(f"unknown axis {name!r}; axes: {', '.join(self._axes)}") from None

    # ------------------------------------------------------------------ bus callbacks
    def _subscribe(self, axis: _Axis) -> None:
        net, n = axis.line.network, axis.node_id
        axis.line.cyclic[0x180 + n] = partial(self._on_tpdo1, axis)
        axis.line.cyclic[0x280 + n] = partial(self._on_tpdo2, axis)
        net.subscribe(0x180 + n, partial(_from_network, self._on_tpdo1, axis))
        net.subscribe(0x280 + n, partial(_from_network, self._on_tpdo2, axis))
        net.subscribe(0x080 + n, partial(_from_network, self._on_emcy, axis))
        net.subscribe(0x700 + n, partial(_from_network, self._on_heartbeat, axis))

    def _now(self) -> float:
        return self.time if self.lockstep else time.perf_counter() - self._t0

    def _on_tpdo1(self, axis: _Axis, data: bytes | bytearray) -> None:
        if len(data) < 6:
            return
        sw, pos = _TPDO1.unpack_from(data)
        with self._lock:  # the condition's lock, without Condition.__enter__'s Python frame
            axis.sw, axis.pos, axis.known = sw, pos, True
            axis.rx_cycle = self.cycle_count
            if not self.lockstep:
                axis.rx_time = time.perf_counter()
                self._waiting -= 1
                if self._waiting <= 0:
                    self._cond.notify_all()

    def _on_tpdo2(self, axis: _Axis, data: bytes | bytearray) -> None:
        if len(data) >= 4:
            axis.fe = _I32.unpack_from(data)[0]

    def _on_emcy(self, axis: _Axis, data: bytes | bytearray) -> None:
        if len(data) < 3:
            return
        code, register = _EMCY.unpack_from(data)
        with self._cond:
            if code & 0xFF00 == 0:  # error reset
                axis.active = [f for f in axis.active if f.source != "emcy"]
                return
            self._report(axis, code, register, power.emcy_text(code), "emcy")

    def _on_heartbeat(self, axis: _Axis, data: bytes | bytearray) -> None:
        if not data:
            return
        state = data[0] & 0x7F
        with self._cond:
            now = self._now()
            if state == 0:
                axis.booted = True
                axis.known = False
                if self._running and not axis.restarting:
                    self._report(
                        axis, 0, 0, "drive rebooted (boot-up seen): power cycle or reset", "bootup"
                    )
                self._cond.notify_all()
                return
            axis.hb_last = now
            if axis.hb_lost:
                axis.hb_lost = False
                axis.active = [f for f in axis.active if f.source != "heartbeat"]

    def _report(self, axis: _Axis, code: int, register: int, text: str, source: str) -> None:
        fault = AxisFault(axis.name, axis.node_id, code, register, text, self._now(), source)
        axis.active.append(fault)
        self.fault_log.append(fault)
        self._new_faults.append(fault)
        logger.warning("%s", fault)

    # ------------------------------------------------------------------ boot and configure
    def boot(self) -> None:
        """NMT reset node for every drive, then wait (bounded) for every boot-up frame."""
        self._running = False
        for axis in self._axes.values():
            axis.booted = False
            axis.known = False
            axis.hb_last = None
            axis.hb_lost = False
            axis.active.clear()
        for line in self._lines:
            for axis in line.axes:
                line.network.send_message(0x000, bytes([0x81, axis.node_id]))
        self._wait(
            lambda: all(a.booted for a in self._axes.values()),
            self.boot_timeout_s,
            lambda: (
                "no boot-up within "
                f"{self.boot_timeout_s} s after NMT reset node from "
                + ", ".join(f"axis {a.name} (node {a.node_id})" for a in self._unbooted())
            ),
        )

    def _unbooted(self) -> list[_Axis]:
        return [a for a in self._axes.values() if not a.booted]

    def plan(self) -> list[LoadPlan]:
        """Worst-case bus load per line for the configured cyclic traffic.

        Raises BusOverloadError (> 100 %, with the figures and the line) and warns
        BusLoadWarning (> 70 %).
        """
        plans = []
        for line in self._lines:
            frames = [CyclicFrame("SYNC", 0)]
            hb_s = self.heartbeat_ms / 1000.0
            for axis in line.axes:
                frames.append(CyclicFrame(f"{axis.name}.RPDO1", 6))
                frames.append(CyclicFrame(f"{axis.name}.TPDO1", 6))
                if self.following_error_every:
                    frames.append(
                        CyclicFrame(
                            f"{axis.name}.TPDO2", 4, per_sync=1 / self.following_error_every
                        )
                    )
                if hb_s:
                    frames.append(CyclicFrame(f"{axis.name}.heartbeat", 1, period_s=hb_s))
            if hb_s and self.master_node_id is not None:
                frames.append(CyclicFrame("master.heartbeat", 1, period_s=hb_s))
            bitrate = line.hub.bitrate if line.hub is not None else self.bitrate
            try:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    plan = plan_load(frames, sync_period_s=self.ipo_cycle_s, bitrate=bitrate)
            except BusOverloadError as exc:
                names = ", ".join(a.name for a in line.axes)
                exc.add_note(f"CAN line {line.index} ({line.channel}): axes {names}")
                raise
            for w in caught:
                names = ", ".join(a.name for a in line.axes)
                warnings.warn(
                    f"CAN line {line.index} ({line.channel}), axes {names}: {w.message}",
                    w.category,
                    stacklevel=2,
                )
            plans.append(plan)
        self.load_plans = plans
        return plans

    def configure(self) -> None:
        """Plan the bus load, write every drive's CSP configuration by SDO, NMT start."""
        self.plan()
        for axis in self._axes.values():
            for index, sub, value in self._configuration(axis):
                self._sdo_write(axis, index, sub, value)
        for line in self._lines:
            for axis in line.axes:
                line.network.send_message(0x000, bytes([0x01, axis.node_id]))
        self._running = True
        # Watch from now on: a drive that never sends a heartbeat is lost too. The first
        # master heartbeat goes out with the first cycle.
        now = self._now()
        for axis in self._axes.values():
            axis.hb_last = now
        self._hb_elapsed = self.heartbeat_ms / 1000.0

    def _configuration(self, axis: _Axis) -> list[tuple[int, int, int]]:
        """The SDO writes for one drive, in order (CiA 301 PDO mapping procedure)."""
        n, cfg = axis.node_id, axis.cfg
        off = 0x80000000
        writes: list[tuple[int, int, int]] = [
            # RPDO1: controlword + target position, synchronous (applied at the next SYNC)
            (0x1400, 1, off | (0x200 + n)),
            (0x1400, 2, 1),
            (0x1600, 0, 0),
            (0x1600, 1, 0x60400010),
            (0x1600, 2, 0x607A0020),
            (0x1600, 0, 2),
            *([(0x1400, 5, self.rpdo_deadline_ms)] if self.rpdo_deadline_ms else []),
            (0x1400, 1, 0x200 + n),
            (0x1401, 1, off | (0x300 + n)),
            (0x1402, 1, off | (0x400 + n)),
            (0x1403, 1, off | (0x500 + n)),
            # TPDO1: statusword + position actual, every SYNC
            (0x1800, 1, off | (0x180 + n)),
            (0x1800, 2, 1),
            (0x1A00, 0, 0),
            (0x1A00, 1, 0x60410010),
            (0x1A00, 2, 0x60640020),
            (0x1A00, 0, 2),
            (0x1800, 1, 0x180 + n),
            (0x1801, 1, off | (0x280 + n)),
        ]
        if self.following_error_every:
            writes += [
                (0x1801, 2, self.following_error_every),
                (0x1A01, 0, 0),
                (0x1A01, 1, 0x60F40020),
                (0x1A01, 0, 1),
                (0x1801, 1, 0x280 + n),
            ]
        writes += [(0x1802, 1, off | (0x380 + n)), (0x1803, 1, off | (0x480 + n))]
        value, index = power.interpolation_period(self.ipo_cycle_s)
        writes += [(0x60C2, 1, value), (0x60C2, 2, index & 0xFF if index < 0 else index)]
        u = cfg.units_per_mm
        if cfg.following_error_window_mm is not None:
            writes.append((0x6065, 0, round(cfg.following_error_window_mm * u)))
        if cfg.following_error_timeout_ms is not None:
            writes.append((0x6066, 0, int(cfg.following_error_timeout_ms)))
        if cfg.min_mm is not None:
            writes.append((0x607D, 1, cfg.to_units(cfg.min_mm)))
        if cfg.max_mm is not None:
            writes.append((0x607D, 2, cfg.to_units(cfg.max_mm)))
        if cfg.max_velocity_mm_s is not None:
            writes.append((0x607F, 0, round(cfg.max_velocity_mm_s * u)))
        if cfg.max_accel_mm_s2 is not None:
            acc = round(cfg.max_accel_mm_s2 * u)
            writes += [(0x6083, 0, acc), (0x6084, 0, acc)]
        if cfg.quick_stop_decel_mm_s2 is not None:
            writes.append((0x6085, 0, round(cfg.quick_stop_decel_mm_s2 * u)))
        writes.append((0x6060, 0, 8))
        writes.append((0x1017, 0, self.heartbeat_ms))
        if self.master_node_id is not None and self.heartbeat_ms:
            timeout = math.ceil(self.heartbeat_ms * self.heartbeat_timeout_factor)
            writes.append((0x1016, 1, (self.master_node_id << 16) | min(timeout, 0xFFFF)))
        if self.sync_watchdog:
            writes.append((0x1006, 0, round(self.ipo_cycle_s * 1e6)))
        return writes

    def _sdo_write(self, axis: _Axis, index: int, sub: int, value: int) -> None:
        obj = axis.node.object_dictionary[index]
        var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[sub]
        if index == 0x60C2 and sub == 2 and value > 127:
            value -= 256  # INTEGER8 exponent
        try:
            axis.node.sdo.download(index, sub, var.encode_raw(value))
        except (SdoError, can.CanError) as exc:
            raise AxisError(
                f"axis {axis.name} (node {axis.node_id}): SDO write "
                f"0x{index:04X}:{sub:02X} = {value} failed: {exc}",
                (axis.name,),
            ) from exc

    def sdo_read(
        self, axis: str, index: int, sub: int = 0
    ) -> int | float | str | bytes | bytearray:
        """Read an object of an axis's drive by SDO (diagnostics: 0x603F, 0x1001, ...)."""
        a = self._axis(axis)
        obj = a.node.object_dictionary[index]
        var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[sub]
        return var.decode_raw(a.node.sdo.upload(index, sub))

    # ------------------------------------------------------------------ the IPO cycle
    def cycle(self, targets: Mapping[str, float] | None = None) -> AxisFeedback:
        """One IPO cycle: RPDO targets (mm) + SYNC out, feedback in. Axes not named hold.

        Targets only act on axes in OPERATION ENABLED; any other axis holds its actual
        position as target, so that enabling never jumps.
        """
        self.begin_cycle(targets)
        return self.end_cycle()

    def begin_cycle(self, targets: Mapping[str, float] | None = None) -> None:
        """First half of `cycle`: (realtime: wait for the slot) send RPDOs and SYNC."""
        if targets:
            axes, isfinite = self._axes, math.isfinite
            for name, mm in targets.items():
                axis = axes.get(name) or self._axis(name)  # `_axis` raises for a wrong name
                if not isfinite(mm):
                    raise ValueError(f"axis {name}: target {mm!r} is not a finite number")
                axis.target = round(mm * axis.cfg.units_per_mm)
        if self.paced or not self.lockstep:
            self._pace()
        with self._cond:
            self.cycle_count += 1
            self._waiting = len(self._axes)
        pack = _RPDO.pack
        for line in self._lines:
            send = line.bus.send
            for axis in line.axes:
                if axis.sw & _OE_MASK != _OE or not axis.known:
                    axis.target = axis.pos  # hold: only an enabled axis follows targets
                send(owned_frame(axis.rpdo_cob, pack(axis.cw, axis.target)))
        self._heartbeat()
        if self.paced or not self.lockstep:
            self._sync_sent_at = time.perf_counter()
        for line in self._lines:
            line.bus.send(owned_frame(0x080, b""))

    def end_cycle(self) -> AxisFeedback:
        """Second half of `cycle`: let one IPO cycle pass (lockstep) or await the TPDOs."""
        n = self.cycle_count
        if self.lockstep:
            for hub in self._hubs:
                hub.advance(self.ipo_cycle_s)
            self.time += self.ipo_cycle_s
            if self.paced:
                done = time.perf_counter()
                self.stats.cycles += 1
                self.stats.tpdo_latency_s.append(done - self._sync_sent_at)
                if self._slot is not None and done > self._slot + self.ipo_cycle_s:
                    self.stats.late_cycles += 1
        else:
            self._await_tpdos(n)
            self.time = time.perf_counter() - self._t0
        self._watch()
        position, statusword, following, state, fresh = {}, {}, {}, {}, {}
        names = _STATE_NAMES
        for a in self._axes.values():  # one pass fills the five maps
            name, sw, upm, fe = a.name, a.sw, a.cfg.units_per_mm, a.fe
            position[name] = a.pos / upm
            statusword[name] = sw
            following[name] = None if fe is None else fe / upm
            text = names.get(sw)
            if text is None:
                text = names[sw] = power.state_name(sw)
            state[name] = text
            fresh[name] = a.rx_cycle == n
        feedback = AxisFeedback(
            time=self.time,
            cycle=n,
            position_mm=position,
            statusword=statusword,
            following_error_mm=following,
            state=state,
            fresh=fresh,
        )
        if self._new_faults:
            feedback.faults = self.take_faults()
        return feedback

    def _pace(self) -> None:
        """Realtime: wait for this cycle's slot (absolute deadlines, sleep then spin; the
        garbage collector runs in the slack, see `drives.realtime`)."""
        if not self._realtime_held:
            RealtimeProcess.acquire()  # released by close()
            self._realtime_held = True
        pacer = self._pacer
        skipped = pacer.skipped
        lateness = pacer.wait()
        self._slot = pacer.slot
        self.stats.skipped_slots += pacer.skipped - skipped
        self.stats.lateness_s.append(lateness)

    def _await_tpdos(self, n: int) -> None:
        deadline = (self._slot or time.perf_counter()) + self.ipo_cycle_s
        with self._cond:
            while self._waiting > 0:
                remaining = deadline - time.perf_counter()
                if remaining <= 0:
                    break
                self._cond.wait(remaining)
            complete = self._waiting <= 0
        stats = self.stats
        stats.cycles += 1
        if complete:
            last = max(a.rx_time for a in self._axes.values())
            stats.tpdo_latency_s.append(last - self._sync_sent_at)
        else:
            stats.late_cycles += 1

    def _heartbeat(self) -> None:
        if self.master_node_id is None or not self.heartbeat_ms or not self._running:
            return
        if self._hb_elapsed + 1e-9 >= self.heartbeat_ms / 1000.0:
            self._hb_elapsed = 0.0
            for line in self._lines:  # a frame per line: the bus keeps the one it is given
                line.bus.send(owned_frame(0x700 + self.master_node_id, b"\x05"))
        self._hb_elapsed += self.ipo_cycle_s

    def _watch(self) -> None:
        """Heartbeat consumer and statusword checks, once per cycle."""
        if not self._running:
            return
        now = self._now()
        limit = self.heartbeat_ms * self.heartbeat_timeout_factor / 1000.0
        with self._cond:
            for axis in self._axes.values():
                if (
                    limit
                    and axis.hb_last is not None
                    and not axis.hb_lost
                    and now - axis.hb_last > limit
                ):
                    axis.hb_lost = True
                    self._report(
                        axis,
                        0x8130,
                        0,
                        f"heartbeat lost (none for {limit * 1e3:.0f} ms)",
                        "heartbeat",
                    )
                self._watch_feedback(axis)
                if axis.sw & power.SW_FAULT and not axis.active:
                    self._report(
                        axis,
                        0,
                        0,
                        f"statusword 0x{axis.sw:04X} reports {power.state_name(axis.sw)}"
                        " without an EMCY",
                        "statusword",
                    )

    def _watch_feedback(self, axis: _Axis) -> None:
        """The cyclic feedback check (under the lock): TPDO1 of this cycle seen or not."""
        limit = self.feedback_timeout_cycles
        if not limit or not axis.known or axis.restarting:
            axis.missed = 0
            return
        if axis.rx_cycle == self.cycle_count:
            axis.missed = 0
            if axis.feedback_lost:
                axis.feedback_lost = False
                axis.active = [f for f in axis.active if f.source != "feedback"]
            return
        axis.missed += 1
        if axis.missed >= limit and not axis.feedback_lost:
            axis.feedback_lost = True
            self._report(
                axis,
                0x8100,
                0,
                f"cyclic feedback lost: no TPDO1 for {axis.missed} SYNC cycles "
                f"({axis.missed * self.ipo_cycle_s * 1e3:.0f} ms; lost, destroyed or late frames)",
                "feedback",
            )

    # ------------------------------------------------------------------ waiting
    def _wait(self, done, timeout_s: float, message) -> None:
        """Wait until `done()`: lockstep advances the hubs cycle by cycle, realtime sleeps."""
        if self.lockstep:
            for _ in range(math.ceil(timeout_s / self.ipo_cycle_s) + 1):
                if done():
                    return
                for hub in self._hubs:
                    hub.advance(self.ipo_cycle_s)
                self.time += self.ipo_cycle_s
            if done():
                return
        else:
            deadline = time.perf_counter() + timeout_s
            with self._cond:
                while not done():
                    remaining = deadline - time.perf_counter()
                    if remaining <= 0:
                        break
                    self._cond.wait(min(remaining, 0.01))
                if done():
                    return
        raise AxisError(message())

    def _run_cycles(self, step, timeout_s: float, what: str) -> AxisFeedback:
        """Cycle until `step(feedback)` returns True; AxisError naming what is stuck."""
        cycles = max(2, math.ceil(timeout_s / self.ipo_cycle_s))
        feedback = self.cycle()
        for _ in range(cycles):
            if step(feedback):
                return feedback
            feedback = self.cycle()
        if step(feedback):
            return feedback
        raise AxisError(f"{what} within {timeout_s} s")

    # ------------------------------------------------------------------ 402 sequences
    def _select(self, axes: Iterable[str] | None) -> list[_Axis]:
        return [self._axis(n) for n in axes] if axes is not None else list(self._axes.values())

    def enable(self, axes: Iterable[str] | None = None, timeout_s: float = 1.0) -> None:
        """Walk every axis to OPERATION ENABLED (0x06, 0x0F), holding its actual position."""
        chosen = self._select(axes)

        def step(fb: AxisFeedback) -> bool:
            done = True
            for axis in chosen:
                if not axis.known:
                    done = False
                    continue
                cw = power.enable_controlword(axis.sw)
                state = power.state_name(axis.sw)
                if cw is None and state in ("FAULT", "FAULT REACTION ACTIVE"):
                    raise AxisError(
                        f"axis {axis.name} (node {axis.node_id}) is in {state} "
                        f"(statusword 0x{axis.sw:04X}, 0x603F={self._error_code(axis)}): "
                        "fault_reset() first",
                        (axis.name,),
                    )
                if cw is not None:
                    done = False
                    axis.cw = cw
                else:
                    axis.cw = power.CW_ENABLE_OPERATION
            return done

        try:
            self._run_cycles(step, timeout_s, "enable")
        except AxisError as exc:
            if exc.axes:
                raise
            stuck = [
                a for a in chosen if not a.known or power.state_name(a.sw) != "OPERATION ENABLED"
            ]
            raise AxisError(
                "; ".join(
                    f"axis {a.name} (node {a.node_id}) did not reach OPERATION ENABLED within "
                    f"{timeout_s} s: "
                    + (
                        power.state_name(a.sw)
                        if a.known
                        else "no TPDO since NMT start (rebooted or silent: fault_reset() "
                        "restarts it)"
                    )
                    + " "
                    f"(statusword 0x{a.sw:04X})"
                    for a in stuck
                ),
                tuple(a.name for a in stuck),
            ) from None

    def _error_code(self, axis: _Axis) -> str:
        try:
            code = self.sdo_read(axis.name, 0x603F)
            return f"0x{code:04X}" if isinstance(code, int) else "unreadable"
        except Exception:  # diagnostics only: the message must still come out
            return "unreadable"

    def quick_stop(self, axes: Iterable[str] | None = None) -> None:
        """E-stop: controlword Quick stop (0x0002) from the next cycle on; targets ignored.

        The drives ramp down with 0x6085 (0x605A decides where they end up); `enable()`
        brings them back.
        """
        for axis in self._select(axes):
            axis.cw = power.CW_QUICK_STOP

    def fault_reset(self, axes: Iterable[str] | None = None, timeout_s: float = 0.1) -> None:
        """Fault reset edge (0x00 then 0x80) for faulted axes; AxisError if one stays in FAULT."""
        selected = self._select(axes)
        self.restart([a.name for a in selected if self._needs_restart(a)])
        with self._cond:  # faults of drives that are not in FAULT (e.g. a heartbeat) just clear
            for axis in selected:
                if not axis.sw & power.SW_FAULT:
                    axis.active.clear()
        chosen = [a for a in selected if a.sw & power.SW_FAULT]
        if not chosen:
            return
        t_reset = self._now()  # the faults this reset acknowledges were reported by now
        for axis in chosen:
            axis.cw = power.CW_DISABLE_VOLTAGE
        self.cycle()
        for axis in chosen:
            axis.cw = power.CW_FAULT_RESET

        def step(fb: AxisFeedback) -> bool:
            return all(not a.sw & power.SW_FAULT for a in chosen)

        try:
            self._run_cycles(step, timeout_s, "fault reset")
        except AxisError:
            stuck = [a for a in chosen if a.sw & power.SW_FAULT]
            raise AxisError(
                "; ".join(
                    f"axis {a.name} (node {a.node_id}) still in FAULT after fault reset "
                    f"(0x603F={code}): the cause is still present"
                    + (f": {REMEDIES[int(code, 16)]}" if int(code, 16) in REMEDIES else "")
                    for a in stuck
                    for code in [self._error_code(a).replace("unreadable", "0x0000")]
                ),
                tuple(a.name for a in stuck),
            ) from None
        finally:
            for axis in chosen:
                axis.cw = power.CW_DISABLE_VOLTAGE
        with self._cond:
            for axis in chosen:
                # a fault the drive raised after the reset (its EMCY came in while we waited)
                # is a new one: it stays, and the drive's statusword says FAULT again
                axis.active = [f for f in axis.active if f.time > t_reset]
                axis.hb_lost = False

    @staticmethod
    def _needs_restart(axis: _Axis) -> bool:
        """The drive rebooted (power cycle, its own reset) or sends no TPDO: its PDO mapping
        and heartbeat settings are gone (CiA 301 defaults after a reset)."""
        return not axis.known or any(f.source == "bootup" for f in axis.active)

    def restart(self, axes: Iterable[str] | None = None, timeout_s: float | None = None) -> None:
        """Bring drives back onto the cyclic traffic after a reboot or a bus-off: NMT reset
        communication, wait for the boot-up, write the configuration again by SDO, NMT start,
        wait for the first TPDO. AxisError names a drive that does not come back."""
        chosen = self._select(axes)
        if not chosen:
            return
        limit = timeout_s if timeout_s is not None else self.boot_timeout_s
        with self._cond:
            for axis in chosen:
                axis.booted = False
                axis.known = False
                axis.restarting = True
        try:
            self._restart(chosen, limit)
        finally:
            with self._cond:
                for axis in chosen:
                    axis.restarting = False
        logger.info("restarted %s", ", ".join(a.name for a in chosen))

    def _restart(self, chosen: list[_Axis], limit: float) -> None:
        for axis in chosen:
            line = self._lines[axis.cfg.line]
            line.network.send_message(0x000, bytes([0x82, axis.node_id]))

        def names(which: list[_Axis]) -> str:
            return ", ".join(f"axis {a.name} (node {a.node_id})" for a in which)

        self._wait(
            lambda: all(a.booted for a in chosen),
            limit,
            lambda: (
                f"no boot-up within {limit} s after NMT reset communication from "
                + names([a for a in chosen if not a.booted])
            ),
        )
        for axis in chosen:
            for index, sub, value in self._configuration(axis):
                self._sdo_write(axis, index, sub, value)
            self._lines[axis.cfg.line].network.send_message(0x000, bytes([0x01, axis.node_id]))
        now = self._now()
        with self._cond:
            for axis in chosen:
                axis.cw = power.CW_DISABLE_VOLTAGE
                axis.hb_last = now
                axis.hb_lost = False
        self._run_cycles(
            lambda fb: all(a.known for a in chosen),
            limit,
            "first TPDO after NMT start from " + names(chosen),
        )
        with self._cond:  # the boot-up and heartbeat reports are answered by the restart
            for axis in chosen:
                axis.active = [f for f in axis.active if f.source not in ("bootup", "heartbeat")]

    def disable(self, axes: Iterable[str] | None = None, timeout_s: float = 2.0) -> None:
        """Controlled stop: Disable operation (0x07, ramp per 0x605C), then Shutdown (0x06)."""
        chosen = self._select(axes)
        for axis in chosen:
            axis.cw = power.CW_SWITCH_ON

        def stopped(fb: AxisFeedback) -> bool:
            return all(power.state_name(a.sw) != "OPERATION ENABLED" for a in chosen)

        self._run_cycles(stopped, timeout_s, "disable operation")
        for axis in chosen:
            axis.cw = power.CW_SHUTDOWN

        def ready(fb: AxisFeedback) -> bool:
            return all(
                power.state_name(a.sw) in ("READY TO SWITCH ON", "SWITCH ON DISABLED", "FAULT")
                for a in chosen
            )

        self._run_cycles(ready, timeout_s, "shutdown")

    def home(self, axes: Iterable[str] | None = None, timeout_s: float | None = None) -> None:
        """CiA 402 homing (mode 6) of the axes at once, each with its configured method,
        speeds (search / creep), acceleration and home offset; then back to CSP (mode 8)."""
        chosen = self._select(axes)
        for axis in chosen:
            if power.state_name(axis.sw) != "OPERATION ENABLED":
                raise AxisError(
                    f"axis {axis.name} (node {axis.node_id}): homing needs OPERATION ENABLED, "
                    f"drive is {power.state_name(axis.sw)}: enable() first",
                    (axis.name,),
                )
        for axis in chosen:
            cfg, u = axis.cfg, axis.cfg.units_per_mm
            for index, sub, value in (
                (0x6098, 0, cfg.homing_method),
                (0x607C, 0, cfg.to_units(cfg.home_offset_mm)),
                (0x6099, 1, round(cfg.homing_search_mm_s * u)),
                (0x6099, 2, round(cfg.homing_creep_mm_s * u)),
                (0x609A, 0, round(cfg.homing_accel_mm_s2 * u)),
                (0x6060, 0, 6),
            ):
                self._sdo_write(axis, index, sub, value)
            axis.cw = power.CW_ENABLE_OPERATION
        self.cycle()  # bit 4 low for one cycle: the start is a rising edge
        for axis in chosen:
            axis.cw = power.CW_ENABLE_OPERATION | power.CW_HOMING_START
        pending = {a.name: a for a in chosen}
        limit = timeout_s if timeout_s is not None else max(a.cfg.homing_timeout_s for a in chosen)

        def step(fb: AxisFeedback) -> bool:
            for name, axis in list(pending.items()):
                state = power.state_name(axis.sw)
                status = power.homing_status(axis.sw)
                if state != "OPERATION ENABLED":
                    raise AxisError(
                        f"axis {name} (node {axis.node_id}): homing aborted, drive is {state} "
                        f"(statusword 0x{axis.sw:04X})",
                        (name,),
                    )
                if status.startswith("ERROR") or status == "INTERRUPTED":
                    raise AxisError(
                        f"axis {name} (node {axis.node_id}): homing method "
                        f"{axis.cfg.homing_method} failed: {status} (statusword 0x{axis.sw:04X})",
                        (name,),
                    )
                if status == "TARGET REACHED":
                    axis.cw = power.CW_ENABLE_OPERATION
                    del pending[name]
            return not pending

        try:
            self._run_cycles(step, limit, "homing")
        except AxisError as exc:
            for axis in chosen:
                axis.cw = power.CW_ENABLE_OPERATION
            if exc.axes:
                raise
            raise AxisError(
                "; ".join(
                    f"axis {a.name} (node {a.node_id}): homing not finished within {limit} s "
                    f"({power.homing_status(a.sw)}, statusword 0x{a.sw:04X})"
                    for a in pending.values()
                ),
                tuple(pending),
            ) from None
        for axis in chosen:
            self._sdo_write(axis, 0x6060, 0, 8)
            axis.target = axis.pos
        self.cycle()

    # ------------------------------------------------------------------ shutdown
    @property
    def scheduling(self) -> str:
        """What the paced cycle's thread runs with (`drives.realtime`: SCHED_FIFO on request)."""
        return self._pacer.scheduling

    def close(self) -> None:
        """Detach from the buses (the buses themselves stay open: they are the caller's)."""
        self._running = False
        self._pacer.restore_scheduling()  # the paced thread goes on at its old priority
        if self._realtime_held:
            self._realtime_held = False
            RealtimeProcess.release()
        for line in self._lines:
            line.close()

    def __enter__(self) -> AxisGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _from_network(
    handler: Callable[[_Axis, bytes | bytearray], None],
    axis: _Axis,
    cob_id: int,
    data: bytes | bytearray,
    timestamp: float,
) -> None:
    """A canopen Network subscriber (cob_id, data, timestamp) calling `handler(axis, data)`."""
    handler(axis, data)
