"""The DNC host's side of the cell: the monitoring model and the host loops.

The monitoring model reads each machine's live status from the MTConnect agent (which the
machines' SHDR streams feed), never from the machine objects: the host sees an in-process
machine exactly as it would see one on another computer. The scheduler takes its view of
the machines from it, the REST API shows it, the starter waits on it.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping

from dnc.scheduler import ALARM, BUSY, IDLE, OFFLINE, MachineView
from server.errors import ServerError
from server.supervisor import MachineLink, MachineUnavailable, wait_for

log = logging.getLogger(__name__)

IN_CYCLE = frozenset({"ACTIVE", "INTERRUPTED", "FEED_HOLD", "OPTIONAL_STOP", "PROGRAM_STOPPED"})
CONDITIONS = ("nc_cond", "plc_cond", "bus_cond", "dnc_cond", "servo")


def _text(value) -> str:
    """An EVENT's text; UNAVAILABLE (nothing reported) reads as empty."""
    return "" if value in (None, "UNAVAILABLE") else str(value)


def _num(text: str) -> float | None:
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def _tool_tip(agent, name: str) -> dict | None:
    """mill5: the tool tip (forward kinematics, workpiece frame) and its deviation from the
    programmed straight line, now and the program's peak; None on other machines."""
    if "tip" not in agent.device(name).by_key:
        return None

    def v(key: str) -> str:
        return agent.value(name, key)

    tip = v("tip")
    parts = [_num(p) for p in str(tip).split()]
    return {
        "position": parts if len(parts) == 3 and None not in parts else None,
        "deviation_mm": _num(v("tip_dev")),
        "peak_deviation_mm": _num(v("tip_dev_peak")),
    }


class MonitoringModel:
    """Each machine's live status, from the MTConnect agent's current values."""

    def __init__(
        self,
        agent,
        links: Mapping[str, MachineLink],
        *,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.agent = agent
        self.links = dict(links)
        self._monotonic = monotonic
        # when each machine was first seen without contact (cleared when it answers again);
        # a host that restarts starts counting afresh, which only delays a reroute
        self._lost_since: dict[str, float] = {}

    def status(self, name: str) -> dict:
        a, link = self.agent, self.links[name]
        v = lambda key: a.value(name, key)  # noqa: E731
        spindle = "S" if "C" in link.axes else "C"
        alarms = []
        for key in (*CONDITIONS, *(f"{ax}servo" for ax in link.axes)):
            got = a.latest(name, key)
            for obs in got if isinstance(got, tuple) else ():
                if obs.level in ("FAULT", "WARNING"):
                    alarms.append(
                        {
                            "condition": key,
                            "level": obs.level,
                            "code": obs.native_code,
                            "text": obs.value,
                        }
                    )
        connected = a.state[name].connected
        ref = v("referenced") or ""
        feed = _num(v("path_feedrate"))
        part_count = _num(v("part_count"))
        return {
            "connected": connected,
            "availability": v("avail"),
            "emergency_stop": v("estop"),
            "mode": v("mode"),
            "mode_detail": v("mode_detail"),
            "execution": v("exec"),
            "program": v("program"),
            "line": int(_num(v("line")) or 0),
            "block": v("block"),
            "actual": {ax: _num(v(f"{ax}act")) for ax in link.axes},
            "commanded": {ax: _num(v(f"{ax}cmd")) for ax in link.axes},
            "feed_mm_min": None if feed is None else round(feed * 60.0, 3),
            "overrides": {
                "feed": _num(v("feed_ovr")),
                "rapid": _num(v("rapid_ovr")),
                "spindle": _num(v(f"{spindle}ovr")),
            },
            "spindle": {
                "speed_rpm": _num(v(f"{spindle}speed")),
                "load_percent": _num(v(f"{spindle}load")),
                "mode": v(f"{spindle}mode"),
            },
            "alarms": alarms,
            # homed since power-on / the last loss of reference (None: not reported)
            "referenced": (
                True if ref == "REFERENCED" else False if ref.startswith("NOT_REFERENCED") else None
            ),
            "unreferenced_axes": ref.split()[1:] if ref.startswith("NOT_REFERENCED") else [],
            # the NC's reason for the last refused cycle start ("" after a start or select)
            "cycle_start_refused": _text(v("start_refused")),
            "counters": {"part_count": None if part_count is None else int(part_count)},
            "bus_load": {
                "mean_percent": _num(v("bus_load")),
                "peak_percent": _num(v("bus_load_peak")),
            },
            "plc": {"scan_time_ms": _num(v("plc_scan"))},
            "tool_tip": _tool_tip(a, name),
        }

    def all(self) -> dict[str, dict]:
        return {name: self.status(name) for name in self.links}

    def state(self, name: str) -> str:
        """idle | busy | alarm | offline, as the scheduler sees the machine."""
        return self._state(self.status(name))

    @staticmethod
    def _state(s: dict) -> str:
        if not s["connected"] or s["availability"] != "AVAILABLE":
            return OFFLINE
        # an alarm first: a machine stopped by one may still say INTERRUPTED or FEED_HOLD
        if any(x["level"] == "FAULT" for x in s["alarms"]) or s["emergency_stop"] == "TRIGGERED":
            return ALARM
        if s["execution"] in IN_CYCLE:
            return BUSY
        if s["mode"] != "AUTOMATIC":
            return OFFLINE  # in the operator's hands (REF, JOG, MDI): not for the cell
        if s["referenced"] is False:
            # READY in AUTO but not homed (a reset after a fault that lost the reference):
            # it cannot cut, a part on it is lost, and nothing is dispatched to it until
            # the operator homes it (warning 3031 says so per axis)
            return ALARM
        return IDLE

    def offline_s(self, name: str, connected: bool) -> float:
        """How long contact with the machine has been lost (0 while it answers)."""
        if connected:
            self._lost_since.pop(name, None)
            return 0.0
        now = self._monotonic()
        return now - self._lost_since.setdefault(name, now)

    def views(self) -> list[MachineView]:
        out = []
        for name, link in self.links.items():
            s = self.status(name)
            faults = [a for a in s["alarms"] if a["level"] == "FAULT"]
            count = s["counters"]["part_count"]
            # Connected but its part counter not reported yet (the adapter's first lines after
            # a reconnect, every value UNAVAILABLE until then) is not yet an answer: a counter
            # read as 0 there would look like a restarted control and cost a counted part.
            answering = bool(s["connected"]) and count is not None
            out.append(
                MachineView(
                    name,
                    link.kind,
                    self._state(s),
                    count or 0,
                    connected=answering,
                    offline_s=self.offline_s(name, answering),
                    in_cycle=s["execution"] in IN_CYCLE,
                    program=s["program"] or "",
                    estop=s["emergency_stop"] == "TRIGGERED",
                    alarm=_alarm_text(faults[0]) if faults else None,
                    warnings=tuple(_alarm_text(a) for a in s["alarms"] if a not in faults),
                    axes=link.axes,
                )
            )
        return out


def _alarm_text(alarm: dict) -> str:
    code = f"{alarm['code']} " if alarm.get("code") else ""
    return f"{alarm['condition']} {alarm['level']} {code}{alarm['text'] or ''}".strip()


class AlarmWatch:
    """Writes each machine's alarms raised and cleared to the outbox (the event stream and
    MQTT show them), as the monitoring model sees them change."""

    def __init__(self, sessions, monitor: MonitoringModel) -> None:
        self.sessions, self.monitor = sessions, monitor
        self.known: dict[str, set[tuple]] = {}

    def check(self) -> int:
        from datetime import UTC, datetime

        # deferred: SQLAlchemy; `fmscell --help` loads this module (server.factory)
        from dnc.db import transaction
        from dnc.events import record

        changes = []
        for name in self.monitor.links:
            alarms = self.monitor.status(name)["alarms"]
            now = {(a["condition"], a["level"], a["code"], a["text"]) for a in alarms}
            before = self.known.get(name, set())
            changes += [(name, "machine.alarm", a) for a in sorted(now - before)]
            changes += [(name, "machine.alarm_cleared", a) for a in sorted(before - now)]
            self.known[name] = now
        if changes:
            at = datetime.now(UTC)
            with transaction(self.sessions) as s:
                for name, action, (cond, level, code, text) in changes:
                    record(
                        s,
                        now=at,
                        actor="monitor",
                        action=action,
                        entity="machine",
                        entity_id=None,
                        machine=name,
                        condition=cond,
                        level=level,
                        code=code,
                        text=text,
                    )
        return len(changes)


class StartRefused(ServerError, MachineUnavailable):
    """The NC (or the PLC) refused the cycle start; the text carries its reason."""

    refused = True  # definitive: the transfer worker records the start as never made


def start_refused_text(machine: str, program: str, reason: str) -> str:
    """The dispatch's failure for a cycle start the NC refused. The NC's reason starts with
    its own "cycle start refused: " (cnc.controller.contract); said once here, not twice."""
    why = reason.removeprefix("cycle start refused: ")
    return f"{machine}: cycle start of {program} refused by the NC: {why}"


def make_starter(
    links: Mapping[str, MachineLink],
    monitor: MonitoringModel,
    timeout_s: float = 30.0,
    look_s: float = 5.0,
) -> Callable[[str, int], int | None]:
    """The transfer worker's cycle start: select the program and press cycle start on the
    machine's Modbus remote panel, and wait until the machine reports it running. Returns
    the machine's part counter from just before the press (the allocation's baseline).

    Cycle start is pressed once. The host's view of the machine (SHDR -> agent) trails the
    machine, by seconds on a loaded host: READY with the program selected and the counter
    unchanged may be a start taken and not yet seen, or a part already made. A second press
    on that view made a part twice; after `look_s` without news the starter asks the NC
    itself (in cycle, on the Modbus face) and otherwise waits for the view to catch up."""

    def start(machine: str, number: int) -> int | None:
        link = links[machine]
        name = f"O{number:04d}"
        before = monitor.status(machine)["counters"]["part_count"]
        link.select_program(number)  # Modbus remote panel, answered by the NC
        wait_for(
            lambda: monitor.status(machine)["program"] == name,
            timeout_s,
            f"{machine}: program {name} selected",
        )
        link.panel("cycle_start")
        looked = [time.monotonic()]

        def running() -> bool:
            s = monitor.status(machine)
            if s["execution"] in IN_CYCLE and s["program"] == name:
                return True
            if s["cycle_start_refused"] and s["program"] == name:
                # the NC said no (not homed, an alarm, the door...): say why now, not after
                # the timeout
                raise StartRefused(start_refused_text(machine, name, s["cycle_start_refused"]))
            # a very short program may have run and ended between two looks
            if (s["counters"]["part_count"] or 0) > (before or 0):
                return True
            # No news yet: ask the NC on its own face, now and then (a Modbus round trip)
            if time.monotonic() - looked[0] > look_s:
                looked[0] = time.monotonic()
                try:
                    with link.remote_panel() as panel:
                        if panel.nc_state()["NcInCycle"]:
                            return True
                except MachineUnavailable:
                    pass  # the face is busy or gone: the view and the timeout decide
            return False

        try:
            wait_for(running, timeout_s, f"{machine}: {name} running")
            return before
        except StartRefused:
            raise
        except MachineUnavailable as exc:
            panel = link.panel_status()
            if panel.get("CycleStartRefused"):
                raise StartRefused(f"{machine}: the PLC refused cycle start") from None
            s = monitor.status(machine)
            raise MachineUnavailable(
                f"{exc} (machine: {s['mode']} {s['execution']} program {s['program']!r}, "
                f"parts {s['counters']['part_count']}, alarms {s['alarms']}; panel {panel})"
            ) from None

    return start


class Loop:
    """Runs `fn` every `period_s` on its own thread until stopped; errors are logged and the
    loop carries on (a database that is briefly down must not end the host)."""

    def __init__(self, name: str, fn: Callable[[], object], period_s: float) -> None:
        self.name, self.fn, self.period_s = name, fn, period_s
        self._stop = threading.Event()
        self.errors = 0
        self.runs = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> Loop:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self.fn()
                self.runs += 1
            except Exception:  # noqa: BLE001 - a loop of the host never dies of one error
                self.errors += 1
                log.exception("%s failed", self.name)
            self._stop.wait(max(0.0, self.period_s - (time.monotonic() - t0)))

    def stop(self, timeout_s: float = 30.0) -> None:
        """Stop after the current run (its database writes finish first)."""
        self._stop.set()
        self._thread.join(timeout_s)
