"""The MQTT face through a real broker: 50 machines changing at 10 Hz, latency and loss.

Synthetic machines, the real publishing code: each cell is a `server.mqtt.CellFace` over
a MonitoringModel and MTConnect agent, as in `fmscell run`; a feeder thread plays the SHDR
streams (every machine's block line and X position change every 100 ms, observed with the
wall clock). A subscriber on the same broker receives everything under the bench's prefix.

- `latency_ms`: from the state change (the observation's timestamp, which the message
  carries) to the subscriber's receipt, for every `line` message: the face's polling
  period, paho, the broker and back. Target p95 < 200 ms.
- `messages_lost`: state messages the faces handed to the broker minus those received.
  Target 0.
- `changes_coalesced`: line changes never published because a newer one replaced them
  before the face's next reading (a retained topic carries the last value, by design).

Prints one JSON object. Usage: bench_mqtt.py [--broker 127.0.0.1:1883] [--machines 50]
[--cells 5] [--hz 10] [--seconds 10] [--period 0.05]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import threading
import time
import uuid
from datetime import datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from server.mqtt import CellFace, MqttSettings, parse_broker, utc_now  # noqa: E402
from tests.server.mqtt_support import Subscriber, broker_answers, clear_retained, live_state  # noqa: E402

TARGET_P95_MS = 200.0


def percentile(values: list[float], q: float) -> float | None:
    if not values:
        return None
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


def listen(host: str, port: int, prefix: str, conn) -> None:
    """The subscriber process: latency of every `line` message (receipt minus the state
    change's timestamp it carries), and the state messages received once the cells say how
    many they published."""
    latencies: list[float] = []
    lines: set[tuple[str, int]] = set()
    sub = Subscriber(host, port, [f"{prefix}/#"])
    real_on_message = sub._on_message

    def on_message(client, userdata, msg) -> None:
        got = time.time()
        real_on_message(client, userdata, msg)
        if msg.topic.endswith("/line"):
            body = sub.messages[-1][1]
            sent = datetime.fromisoformat(body["timestamp"]).timestamp()
            latencies.append((got - sent) * 1000.0)
            if body["value"]:  # 0: before the feed
                lines.add((body["machine"], body["value"]))

    sub.client.on_message = on_message
    conn.send("subscribed" if sub.subscribed.wait(10) else "no")
    published = conn.recv()

    def state(ms) -> int:
        return sum(1 for t, _, _ in ms if not t.endswith("/status"))

    end = time.monotonic() + 10.0
    while state(sub.messages) < published and time.monotonic() < end:
        time.sleep(0.05)  # drain: what the broker still delivers
    sub.close()
    conn.send({"latencies": latencies, "received": state(sub.messages), "lines": len(lines)})


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--broker", default="127.0.0.1:1883")
    ap.add_argument("--machines", type=int, default=50)
    ap.add_argument("--cells", type=int, default=5)
    ap.add_argument("--hz", type=float, default=10.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--period", type=float, default=0.05, help="the faces' period_s")
    args = ap.parse_args()
    host, port = parse_broker(args.broker, "--broker")
    if not broker_answers(host, port):
        print(json.dumps({"error": f"no MQTT broker answers on {host}:{port}"}))
        return 1

    prefix = f"bench-{uuid.uuid4().hex[:8]}"
    per_cell = -(-args.machines // args.cells)
    names = [f"m{i:02d}" for i in range(args.machines)]
    groups = [names[i : i + per_cell] for i in range(0, len(names), per_cell)]
    states = [live_state(tuple(g)) for g in groups]
    where = {n: st for g, st in zip(groups, states, strict=True) for n in g}
    period = 1.0 / args.hz

    # the subscriber is a process of its own, as a SCADA would be: its receipt times are
    # not held up by the cells' threads (forked before any thread starts)
    parent, child = multiprocessing.Pipe()
    listener = multiprocessing.Process(target=listen, args=(host, port, prefix, child))
    listener.start()
    if not parent.poll(30) or parent.recv() != "subscribed":
        print(json.dumps({"error": "the subscriber did not subscribe"}))
        return 1

    faces = [
        CellFace(
            MqttSettings(
                host,
                port,
                prefix=prefix,
                cell_id=f"cell{i + 1}",
                period_s=args.period,
                position_period_s=period,
            ),
            st,
        ).start()
        for i, st in enumerate(states)
    ]
    for f in faces:
        f.connected.wait(10)

    fed = 0
    stop = threading.Event()

    def feed() -> None:
        nonlocal fed
        line, nxt = 0, time.monotonic()
        while not stop.is_set():
            line += 1
            for n in names:
                ts = utc_now()
                agent = where[n].agent
                agent.observe(n, "line", str(line), ts)
                agent.observe(n, "Xact", f"{-line * 0.01:.3f}", ts)
            fed += len(names)
            nxt += period
            stop.wait(max(0.0, nxt - time.monotonic()))

    t0, cpu0 = time.monotonic(), time.process_time()
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    time.sleep(args.seconds)  # the bench's run time
    stop.set()
    feeder.join()
    elapsed = time.monotonic() - t0
    cpu = time.process_time() - cpu0  # the cells' process: faces, paho, the feeder
    time.sleep(0.5)  # the faces' last readings
    published = sum(f.published for f in faces)
    parent.send(published)
    got = parent.recv() if parent.poll(30) else {"latencies": [], "received": 0, "lines": 0}
    listener.join(10)
    for f in faces:
        f.stop()
    clear_retained(host, port, prefix)
    latencies, received, line_published = got["latencies"], got["received"], got["lines"]
    load = os.getloadavg()[0]
    p95 = percentile(latencies, 0.95)
    print(
        json.dumps(
            {
                "broker": f"{host}:{port}",
                "cells": len(faces),
                "machines": len(names),
                "rate_hz": args.hz,
                "seconds": round(elapsed, 2),
                "line_changes_fed": fed,
                "messages_published": published,
                "messages_received": received,
                "messages_lost": max(0, published - received),
                "messages_per_s": round(received / elapsed, 1),
                "changes_coalesced": fed - line_published,
                "latency_ms": {
                    "samples": len(latencies),
                    "p50": round(percentile(latencies, 0.50) or 0, 1),
                    "p95": round(p95 or 0, 1),
                    "p99": round(percentile(latencies, 0.99) or 0, 1),
                    "max": round(max(latencies, default=0), 1),
                },
                "target_p95_ms": TARGET_P95_MS,
                "period_s": args.period,
                "cells_cpu_percent_of_a_core": round(100.0 * cpu / elapsed, 1),
                "cpu_count": os.cpu_count(),
                "load_average_1min": round(load, 1),
                "p95_within_target": p95 is not None and p95 < TARGET_P95_MS,
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
