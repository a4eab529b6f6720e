"""Helpers of the MQTT tests and bench: a broker check, a cell's live state without
machines (an agent fed like the SHDR streams feed it), a subscriber, a private broker."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path
from types import SimpleNamespace

SHARED_BROKER = ("127.0.0.1", 1883)


def broker_answers(host: str = SHARED_BROKER[0], port: int = SHARED_BROKER[1]) -> bool:
    try:
        socket.create_connection((host, port), timeout=1).close()
        return True
    except OSError:
        return False


def _agent_class():
    """The MTConnect agent: `server.mtconnect` here, its own package `mtconnect` once the
    seams change of issue 17 is in (a sibling checkout's package must not be taken)."""
    import importlib

    import server

    here = Path(server.__file__).parent / "mtconnect"
    return importlib.import_module("server.mtconnect" if here.is_dir() else "mtconnect").Agent


def live_state(names=("mill1", "lathe1"), *, bases=None):
    """A MonitoringModel over a real MTConnect agent for machines named `names` (mill3, or
    lathe2 for a name starting with "lathe"), each connected, AVAILABLE, AUTOMATIC, READY."""
    from server.config import load_cell_config
    from server.host import MonitoringModel

    Agent = _agent_class()

    bases = bases or {n: "lathe2" if n.startswith("lathe") else "mill3" for n in names}
    config = load_cell_config(
        {
            "machines": {
                n: {"base": bases[n], "ports": {"dnc": None, "modbus": None, "shdr": None}}
                for n in names
            }
        }
    )
    agent = Agent.from_cell(config)
    links = {
        n: SimpleNamespace(name=n, kind=m.kind, axes=tuple(m.axes))
        for n, m in config.machines.items()
    }
    for n in names:
        agent.connected(n)
        for key, value in (("avail", "AVAILABLE"), ("mode", "AUTOMATIC"), ("exec", "READY")):
            agent.observe(n, key, value)
        agent.observe(n, "part_count", "0")
    return MonitoringModel(agent, links)


class Subscriber:
    """A paho subscriber keeping every message (topic, payload JSON or None, retained)."""

    def __init__(self, host: str, port: int, topics, *, client_id: str = "", clean: bool = True):
        import paho.mqtt.client as mqtt

        self.messages: list[tuple[str, object, bool]] = []
        self.cond = threading.Condition()
        self.subscribed = threading.Event()
        self.client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=clean
        )
        self.client.reconnect_delay_set(1, 2)
        self.client.on_connect = lambda c, *_: c.subscribe([(t, 1) for t in topics])
        self.client.on_subscribe = lambda *_: self.subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect_async(host, port, keepalive=10)
        self.client.loop_start()

    def _on_message(self, client, userdata, msg) -> None:
        body = json.loads(msg.payload) if msg.payload else None
        with self.cond:
            self.messages.append((msg.topic, body, bool(msg.retain)))
            self.cond.notify_all()

    def wait_for(self, predicate, timeout_s: float = 10.0, what: str = "messages"):
        end = time.monotonic() + timeout_s
        with self.cond:
            while not predicate(self.messages):
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {what} within {timeout_s} s: {self.messages[-20:]}")
                self.cond.wait(left)

    def last(self, topic: str):
        for t, body, _ in reversed(self.messages):
            if t == topic:
                return body
        return None

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def clear_retained(host: str, port: int, prefix: str, seconds: float = 1.0) -> None:
    """Remove the retained topics a test left under `prefix` on a shared broker."""
    import paho.mqtt.client as mqtt

    sub = Subscriber(host, port, [f"{prefix}/#"])
    try:
        sub.subscribed.wait(5)
        time.sleep(seconds)  # the retained messages arrive right after the SUBACK
        topics = {t for t, _, retained in sub.messages if retained}
    finally:
        sub.close()
    pub = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    pub.connect(host, port)
    pub.loop_start()
    for t in topics:
        pub.publish(t, b"", 1, True).wait_for_publish(5)
    pub.disconnect()
    pub.loop_stop()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PrivateBroker:
    """A Mosquitto of the test's own on a free loopback port (persistence in `workdir`), to
    stop and start again without touching the shared broker."""

    def __init__(self, workdir: Path) -> None:
        self.exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.port = free_port()
        self.dir = Path(workdir)
        self.conf = self.dir / "mosquitto.conf"
        self.conf.write_text(
            # `user root`: started by root, mosquitto would otherwise become the user
            # mosquitto, who cannot write the test's directory (no effect for other users)
            f"user root\nlistener {self.port} 127.0.0.1\nallow_anonymous true\npersistence true\n"
            f"persistence_location {self.dir}/\nautosave_interval 1\n"
            f"log_dest file {self.dir}/mosquitto.log\n"
        )
        self.proc: subprocess.Popen | None = None

    @staticmethod
    def available() -> bool:
        return bool(shutil.which("mosquitto") or os.path.exists("/usr/sbin/mosquitto"))

    def start(self, timeout_s: float = 10.0) -> None:
        self.proc = subprocess.Popen([self.exe, "-c", str(self.conf)], stdin=subprocess.DEVNULL)
        end = time.monotonic() + timeout_s
        while not broker_answers("127.0.0.1", self.port):
            if self.proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"mosquitto on port {self.port} did not start: {self.log()}")
            time.sleep(0.05)

    def stop(self) -> None:
        """SIGTERM: a broker's orderly restart (it saves its persistent sessions)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(10)
        self.proc = None

    def log(self) -> str:
        p = self.dir / "mosquitto.log"
        return p.read_text()[-2000:] if p.exists() else ""
