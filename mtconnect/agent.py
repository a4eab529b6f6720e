"""The cell's MTConnect agent: observations in, probe/current/sample documents out.

`Agent` is the core. Ingest (`ingest_line`, `observe`, `disconnected`) and the request
handlers (`probe`, `current`, `sample`, `request`) are plain methods; the only outside
inputs are the clock (injected) and SHDR text. Handlers return `(http_status, xml)` and
validate their parameters exactly as the reference agent cppagent does: the same defaults,
the same ranges, the same error codes and messages (docs/mtconnect.md).

Thread-safe: the SHDR connections ingest on an event loop while HTTP requests are served
from other threads.
"""

from __future__ import annotations

import datetime as _dt
import logging
import re
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from mtconnect.buffer import (
    DEFAULT_BUFFER_SIZE,
    DEFAULT_CHECKPOINT_FREQUENCY,
    UNAVAILABLE,
    CircularBuffer,
    Observation,
)
from mtconnect.errors import AgentError
from mtconnect.model import (
    AGENT_OWNED,
    QUALIFIERS,
    DataItem,
    Device,
    devices_element,
    devices_from_cell,
)
from mtconnect.path import PathError, select
from mtconnect.printer import (
    HeaderInfo,
    print_error,
    print_extension_schema,
    print_probe,
    print_streams,
)
from mtconnect.shdr import UNAVAILABLE_VALUES, ShdrValue, parse_line

log = logging.getLogger(__name__)

DEFAULT_COUNT = 100
DEFAULT_HEARTBEAT_MS = 10_000
XML = "application/xml"


class RestError(AgentError):
    """An MTConnectError document: error code, message and HTTP status."""

    def __init__(self, code: str, message: str, status: int = 400) -> None:
        super().__init__(f"{code}: {message}")
        self.code, self.message, self.status = code, message, status


def iso_time(seconds: float) -> str:
    t = _dt.datetime.fromtimestamp(seconds, _dt.UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


_ISO = re.compile(r"^\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?Z?$")


@dataclass
class DeviceState:
    connected: bool = False
    unknown_keys: set[str] | None = None


class Agent:
    def __init__(
        self,
        devices: Sequence[Device],
        *,
        buffer_size: int = DEFAULT_BUFFER_SIZE,
        checkpoint_frequency: int = DEFAULT_CHECKPOINT_FREQUENCY,
        sender: str = "fmscell",
        instance_id: int | None = None,
        clock: Callable[[], float] = time.time,
        ignore_timestamps: bool = False,
        filter_duplicates: bool = True,
    ) -> None:
        if not devices:
            raise ValueError("an agent needs at least one device")
        names = [d.name for d in devices]
        if len(set(names)) != len(names):
            raise ValueError(f"device names must be unique: {names}")
        self.devices = list(devices)
        self.buffer = CircularBuffer(buffer_size, checkpoint_frequency)
        self.sender = sender
        self.clock = clock
        self.instance_id = instance_id if instance_id is not None else max(1, int(clock()))
        self.ignore_timestamps = ignore_timestamps
        self.filter_duplicates = filter_duplicates
        self.device_model_change_time = iso_time(clock())
        self._lock = threading.RLock()
        self._by_name: dict[str, Device] = {}
        for d in self.devices:
            self._by_name[d.name] = d
            self._by_name[d.uuid] = d
        self._conditions = {
            d.name: {k for k, di in d.by_key.items() if di.category == "CONDITION"}
            for d in self.devices
        }
        self._by_id: dict[str, DataItem] = {di.id: di for d in self.devices for di in d.all_items}
        self.state = {d.name: DeviceState(unknown_keys=set()) for d in self.devices}
        self._document = ET.Element("MTConnectDevices")
        self._document.append(devices_element(self.devices))
        now = iso_time(clock())
        with self._lock:
            for d in self.devices:
                for di in d.all_items:
                    self._add(_unavailable(di, now))

    @classmethod
    def from_cell(cls, cell, **kwargs) -> Agent:
        """An agent with one device per machine of a `server.config.CellConfig`."""
        return cls(devices_from_cell(cell), **kwargs)

    # ------------------------------------------------------------------ lookup

    def device(self, name_or_uuid: str) -> Device:
        try:
            return self._by_name[name_or_uuid]
        except KeyError:
            raise RestError(
                "NO_DEVICE", f"Could not find the device '{name_or_uuid}'", 404
            ) from None

    def latest(self, device: str, key: str) -> Observation | tuple[Observation, ...] | None:
        """The newest observation of a data item (a tuple of activations for a condition)."""
        di = self.device(device).by_key[key]
        with self._lock:
            return self.buffer.latest.get(di.id)

    def value(self, device: str, key: str) -> str:
        """Current value of a sample/event, or a condition's level(s) joined by commas."""
        got = self.latest(device, key)
        if isinstance(got, tuple):
            return ",".join(o.level for o in got)
        return got.value if got is not None else UNAVAILABLE

    # ------------------------------------------------------------------ ingest

    def ingest_line(self, device: str, line: str) -> int:
        """Apply one SHDR data line from `device`'s adapter; returns observations added."""
        dev = self.device(device)
        ts_token, values = parse_line(line, self._conditions[dev.name])
        if self.ignore_timestamps or not _is_iso(ts_token):
            ts = iso_time(self.clock())
        else:
            ts = ts_token if ts_token.endswith("Z") else ts_token + "Z"
        added = 0
        with self._lock:
            for v in values:
                di = dev.by_key.get(v.key) or self._by_id.get(v.key)
                if di is None or di.type in AGENT_OWNED:
                    self._warn_once(dev.name, v.key, "unknown data item %r from the adapter")
                    continue
                obs = _observation(di, v, ts)
                if obs.value != UNAVAILABLE and not di.accepts(obs.value):
                    # A value the 2.5 schema rejects (a sample that is no number, a word
                    # outside the vocabulary) would make every document invalid: the item
                    # is UNAVAILABLE instead, and the adapter's mistake is logged once.
                    self._warn_once(
                        dev.name, f"{v.key}={obs.value}", "value %r is not valid for its type"
                    )
                    obs = _unavailable(di, ts)
                if self._add(obs) is not None:
                    added += 1
        return added

    def _warn_once(self, device: str, what: str, message: str) -> None:
        seen = self.state[device].unknown_keys
        if what not in seen:  # once per key (or key=value), like cppagent's unknown keys
            seen.add(what)
            log.warning("%s: " + message, device, what)

    def observe(self, device: str, key: str, value: str, timestamp: str | None = None) -> int:
        """Add one observation of a sample or event (tests, fault injection)."""
        ts = timestamp or iso_time(self.clock())
        return self.ingest_line(device, f"{ts}|{key}|{value}")

    def connected(self, device: str) -> None:
        self.state[self.device(device).name].connected = True

    def disconnected(self, device: str, timestamp: str | None = None) -> int:
        """The adapter is gone: every data item it feeds becomes UNAVAILABLE (once)."""
        dev = self.device(device)
        ts = timestamp or iso_time(self.clock())
        self.state[dev.name].connected = False
        added = 0
        with self._lock:
            for di in dev.by_key.values():
                if di.type in AGENT_OWNED:
                    continue
                if self._add(_unavailable(di, ts)) is not None:
                    added += 1
        return added

    def _add(self, obs: Observation) -> Observation | None:
        if self.filter_duplicates and self._duplicate(obs):
            return None
        return self.buffer.add(obs)

    def _duplicate(self, obs: Observation) -> bool:
        cur = self.buffer.latest.get(obs.item.id)
        if cur is None:
            return False
        if not isinstance(cur, tuple):
            return cur.value == obs.value
        if obs.level in (UNAVAILABLE, "NORMAL") and not obs.native_code:
            return len(cur) == 1 and cur[0].level == obs.level and not cur[0].native_code
        for a in cur:
            if a.native_code == obs.native_code:
                return (a.level, a.value, a.native_severity, a.qualifier) == (
                    obs.level,
                    obs.value,
                    obs.native_severity,
                    obs.qualifier,
                )
        return obs.level == "NORMAL"  # clearing a code that is not active changes nothing

    # ------------------------------------------------------------------ requests

    def header(self) -> HeaderInfo:
        return HeaderInfo(
            creation_time=iso_time(self.clock()),
            sender=self.sender,
            instance_id=self.instance_id,
            buffer_size=self.buffer.size,
            device_model_change_time=self.device_model_change_time,
        )

    def error_document(self, code: str, message: str) -> str:
        return print_error(self.header(), [(code, message)])

    def request(
        self, kind: str, device: str | None = None, params: Mapping[str, str] | None = None
    ) -> tuple[int, str]:
        """Serve `probe`, `current` or `sample` with raw query parameters: (status, XML).
        Every failure is an MTConnectError document, never an exception."""
        params = params or {}
        try:
            if kind == "probe":
                return 200, self.probe(device, **_probe_params(params))
            if kind == "current":
                return 200, self.current(device, **_current_params(params))
            if kind == "sample":
                return 200, self.sample(device, **_sample_params(params))
            raise RestError("INVALID_URI", f"Cannot find handler for: GET /{kind}", 404)
        except RestError as exc:
            return exc.status, self.error_document(exc.code, exc.message)

    def _devices_for(self, device: str | None, device_type: str | None) -> list[Device]:
        if device is not None:
            return [self.device(device)]
        if device_type == "Agent":
            # This agent publishes no Agent device, and a Devices document must hold at
            # least one Device: there is nothing to answer with.
            raise RestError("NO_DEVICE", "This agent publishes no Agent device", 404)
        return self.devices

    def extension_schema(self) -> str:
        """The XSD of the x: extension elements in this agent's Streams documents."""
        return print_extension_schema(self.devices)

    def probe(self, device: str | None = None, device_type: str | None = None) -> str:
        return print_probe(self.header(), self._devices_for(device, device_type))

    def _filter(
        self, device: str | None, path: str | None, device_type: str | None
    ) -> set[str] | None:
        if path is None and device is None and device_type is None:
            return None
        devices = self._devices_for(device, device_type)
        if path is None:
            wanted = {di.id for d in devices for di in d.all_items}
        else:
            doc = self._document
            if device is not None or device_type is not None:
                doc = ET.Element("MTConnectDevices")
                doc.append(devices_element(devices))
            try:
                wanted = select(doc, path)
            except PathError as exc:
                raise RestError(
                    "INVALID_PATH", f"The path could not be parsed. Invalid syntax: {exc}"
                ) from None
        if not wanted:
            raise RestError("INVALID_PATH", f"The path could not be parsed. Invalid syntax: {path}")
        return wanted

    def current(
        self,
        device: str | None = None,
        *,
        at: int | None = None,
        path: str | None = None,
        device_type: str | None = None,
        interval: int | None = None,
    ) -> str:
        if device is not None:
            self.device(device)
        if interval is not None:
            _check_range(interval, 0, 2**31 - 1, "interval")
            raise _streaming_unsupported()
        wanted = self._filter(device, path, device_type)
        with self._lock:
            first, seq = self.buffer.first_sequence, self.buffer.next_sequence
            if at is not None:
                _check_range(at, first - 1, seq, "at")
                observations = self.buffer.checkpoint_at(at).observations(wanted)
            else:
                observations = self.buffer.latest.observations(wanted)
        return print_streams(
            self.header(),
            self.devices,
            observations,
            next_sequence=seq,
            first_sequence=first,
            last_sequence=seq - 1,
        )

    def sample(
        self,
        device: str | None = None,
        *,
        count: int = DEFAULT_COUNT,
        from_: int | None = None,
        to: int | None = None,
        path: str | None = None,
        device_type: str | None = None,
        interval: int | None = None,
        heartbeat: int = DEFAULT_HEARTBEAT_MS,
    ) -> str:
        if device is not None:
            self.device(device)
        if interval is not None:
            _check_range(interval, -1, 2**31 - 1, "interval")
            _check_range(heartbeat, 1, 2**31 - 1, "heartbeat")
            raise _streaming_unsupported()
        return self.sample_page(
            device, count=count, from_=from_, to=to, path=path, device_type=device_type
        ).xml

    def sample_page(
        self,
        device: str | None = None,
        *,
        count: int = DEFAULT_COUNT,
        from_: int | None = None,
        to: int | None = None,
        path: str | None = None,
        device_type: str | None = None,
        wanted: set[str] | None = None,
    ) -> SamplePage:
        """One sample document and where the next one starts (the streaming loop's step)."""
        if wanted is None:
            wanted = self._filter(device, path, device_type)
        with self._lock:
            buf = self.buffer
            first, seq = buf.first_sequence, buf.next_sequence
            upper = buf.size + 1
            lower = -upper
            if from_ is not None:
                _check_range(from_, first - 1, seq + 1, "from")
            if to is not None:
                _check_range(to, from_ if from_ is not None else first, seq + 1, "to")
                lower = 0
            _check_range(count, lower, upper, "count", not_zero=True)
            observations, end, first_out, end_of_buffer = buf.observations(count, wanted, from_, to)
        xml = print_streams(
            self.header(),
            self.devices,
            observations,
            # a backwards walk that reached sequence 1 points at 0, which the 2.5 schema's
            # SequenceType (1..2^64-2) refuses: 1 says the same (nothing older is held)
            next_sequence=max(end, 1),
            first_sequence=first_out,
            last_sequence=seq - 1,
        )
        return SamplePage(xml, end, len(observations), end_of_buffer)

    def stream_plan(
        self, kind: str, device: str | None, params: Mapping[str, str]
    ) -> StreamPlan | None:
        """For a request with `interval`: the validated streaming parameters (None when the
        request does not stream). Raises RestError exactly where cppagent refuses."""
        if kind not in ("current", "sample") or "interval" not in params:
            return None
        if kind == "current":
            p = _current_params(params)
            if device is not None:
                self.device(device)
            _check_range(p["interval"], 0, 2**31 - 1, "interval")
            wanted = self._filter(device, p["path"], p["device_type"])
            return StreamPlan(
                kind, device, p["interval"], DEFAULT_HEARTBEAT_MS, DEFAULT_COUNT, None, wanted
            )
        p = _sample_params(params)
        _check_range(p["interval"], -1, 2**31 - 1, "interval")
        _check_range(p["heartbeat"], 1, 2**31 - 1, "heartbeat")
        if device is not None:
            self.device(device)
        if p["from_"] is not None:
            with self._lock:
                first, seq = self.buffer.first_sequence, self.buffer.next_sequence
            _check_range(p["from_"], first - 1, seq + 1, "from")
        wanted = self._filter(device, p["path"], p["device_type"])
        return StreamPlan(
            kind, device, p["interval"], p["heartbeat"], p["count"], p["from_"], wanted
        )

    def current_for(self, wanted: set[str] | None) -> str:
        """The current document for an already validated filter (streamed current)."""
        with self._lock:
            first, seq = self.buffer.first_sequence, self.buffer.next_sequence
            observations = self.buffer.latest.observations(wanted)
        return print_streams(
            self.header(),
            self.devices,
            observations,
            next_sequence=seq,
            first_sequence=first,
            last_sequence=seq - 1,
        )


@dataclass(frozen=True, slots=True)
class SamplePage:
    xml: str
    next_sequence: int
    count: int
    end_of_buffer: bool


@dataclass(frozen=True, slots=True)
class StreamPlan:
    kind: str  # current | sample
    device: str | None
    interval_ms: int
    heartbeat_ms: int
    count: int
    from_: int | None
    wanted: set[str] | None


# --- helpers -------------------------------------------------------------------------------


def _unavailable(di: DataItem, ts: str) -> Observation:
    if di.category == "CONDITION":
        return Observation(di, ts, "", level=UNAVAILABLE)
    return Observation(di, ts, UNAVAILABLE)


def _is_iso(token: str) -> bool:
    """An ISO 8601 date and time that is also a valid xs:dateTime (month 13 is not)."""
    if not _ISO.match(token):
        return False
    try:
        _dt.datetime.fromisoformat(token.removesuffix("Z"))
    except ValueError:
        return False
    return True


def _observation(di: DataItem, v: ShdrValue, ts: str) -> Observation:
    if di.category == "CONDITION":
        level = v.level if v.level in ("NORMAL", "WARNING", "FAULT") else UNAVAILABLE
        # 2.5 knows only HIGH and LOW; another qualifier is dropped, the activation kept.
        qualifier = v.qualifier.upper() if v.qualifier.upper() in QUALIFIERS else ""
        return Observation(di, ts, v.value, 0, level, v.native_code, v.native_severity, qualifier)
    value = UNAVAILABLE if v.value.upper() in UNAVAILABLE_VALUES else v.value
    return Observation(di, ts, value)


def _check_range(value: int, lo: int, hi: int, param: str, not_zero: bool = False) -> None:
    """cppagent's checkRange: lo and hi are exclusive bounds."""
    if value <= lo:
        msg = f"'{param}' must be greater than {lo}"
    elif value >= hi:
        msg = f"'{param}' must be less than {hi}"
    elif not_zero and value == 0:
        msg = f"'{param}' must not be zero(0)"
    else:
        return
    raise RestError("OUT_OF_RANGE", msg)


def _streaming_unsupported() -> RestError:
    return RestError(
        "UNSUPPORTED",
        "streaming (interval) is not supported by this agent; poll sample with "
        "from=nextSequence instead",
    )


_UNSIGNED = re.compile(r"^\+?\d+$")
_INTEGER = re.compile(r"^[+-]?\d+$")


def _unsigned(params: Mapping[str, str], name: str) -> int | None:
    raw = params.get(name)
    if raw is None:
        return None
    if not _UNSIGNED.match(raw.strip()):
        raise RestError("INVALID_REQUEST", f"'{name}' must be an unsigned integer, got '{raw}'")
    return int(raw)


def _integer(params: Mapping[str, str], name: str, default: int | None = None) -> int | None:
    raw = params.get(name)
    if raw is None:
        return default
    if not _INTEGER.match(raw.strip()):
        raise RestError("INVALID_REQUEST", f"'{name}' must be an integer, got '{raw}'")
    value = int(raw)
    if not -(2**31) <= value < 2**31:
        raise RestError("INVALID_REQUEST", f"'{name}' does not fit a 32-bit integer: '{raw}'")
    return value


def _common(params: Mapping[str, str]) -> dict:
    fmt = params.get("format")
    if fmt is not None and fmt.lower() != "xml":
        raise RestError("UNSUPPORTED", f"format '{fmt}' is not supported; use format=xml")
    device_type = params.get("deviceType")
    if device_type is not None and device_type not in ("Device", "Agent"):
        raise RestError(
            "INVALID_REQUEST", f"deviceType must be 'Device' or 'Agent', got '{device_type}'"
        )
    pretty = params.get("pretty")
    if pretty is not None and pretty.lower() not in ("true", "false"):
        raise RestError("INVALID_REQUEST", f"'pretty' must be true or false, got '{pretty}'")
    return {"device_type": device_type}


def _probe_params(params: Mapping[str, str]) -> dict:
    return _common(params)


def _current_params(params: Mapping[str, str]) -> dict:
    out = _common(params)
    out.update(
        at=_unsigned(params, "at"),
        path=params.get("path"),
        interval=_integer(params, "interval"),
    )
    return out


def _sample_params(params: Mapping[str, str]) -> dict:
    out = _common(params)
    out.update(
        count=_integer(params, "count", DEFAULT_COUNT),
        from_=_unsigned(params, "from"),
        to=_unsigned(params, "to"),
        path=params.get("path"),
        interval=_integer(params, "interval"),
        heartbeat=_integer(params, "heartbeat", DEFAULT_HEARTBEAT_MS),
    )
    return out
