"""Event fan-out: fifty machines' status at 10 Hz over SSE to a hundred clients.

The real app on uvicorn (127.0.0.1, ephemeral port, real HTTP) over the real outbox on
SQLite. A producer thread in the server process plays the cell host's monitor: each of 50
machines changes status 10 times a second (500 events/s, phases spread evenly), and every
10 ms the producer writes the changes that came due through the path the cell records
machine events by (`dnc.events.record` in one transaction, as `server.host.AlarmWatch`
does), each stamped with the wall time the change happened. 100 SSE clients in two
separate processes (httpx streaming) parse every event and record latency = receive time -
change time; a sentinel event ends the run, after which each client reports what it got:
lost, duplicated and out-of-order events are counted against what the producer wrote.

Target from issue 7: p95 latency < 200 ms. The peer in the same run is the old fan-out
(`events_fanout: poll`: each client polls the outbox itself every 0.25 s), shorter. A third
run, when the time budget allows, puts the producer in its own process: the hub cannot be
nudged by its commits and polls every 50 ms. Latency is also given from the start of the
write transaction (`latency_from_record_ms`), which leaves out a producer that fell behind
on a loaded box; CPU times and the load average stand next to every figure.

    .venv/bin/python bench/bench_api_events.py [--seconds 10] [--peer-seconds 5] [--budget 55]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import select
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEY = "bench-viewer-key-0123456789"
BIN_MS = 0.25  # latency histogram resolution
TARGET_P95_MS = 200.0


# ------------------------------------------------------------------ client process

END = object()


def parse_block(block: bytes):
    """One SSE event: (id, changed_at, recorded_at), END for the sentinel, None for a
    comment. The id comes from the `id:` line (what a client resumes with); the two
    stamps are found in the data without a full json.loads, which would make the two client
    processes, not the server, the slowest part on a 2-core box."""
    if not block.startswith(b"id: "):
        return None
    nl = block.index(b"\n")
    data = block[block.index(b"data: ", nl) + 6 :]
    i = data.rfind(b'"changed_at":')
    k = data.rfind(b'"recorded_at":')
    if i < 0 or k < i:
        event = json.loads(data)
        if event.get("action") == "bench.end":
            return END
        return int(block[4:nl]), event["changed_at"], event["recorded_at"]
    changed_at = float(data[i + 13 : data.index(b",", i)])
    recorded_at = float(data[k + 14 : data.index(b"}", k)])
    return int(block[4:nl]), changed_at, recorded_at


async def one_client(
    client, url: str, hist: dict, from_record: dict, result: dict, ready: asyncio.Event
) -> None:
    """One SSE client: parse every event, bin its latency, note ids for loss/dup/order."""
    ids: list[int] = []
    result["ids"] = ids  # what arrived counts even if the run is cut short
    buf = b""
    async with client.stream("GET", url, headers={"X-API-Key": KEY}) as r:
        r.raise_for_status()
        async for chunk in r.aiter_raw():
            now = time.time()  # one receive time per chunk: parsing is the client's cost
            if not ready.is_set():
                ready.set()
            buf += chunk
            *blocks, buf = buf.split(b"\n\n")
            for block in blocks:
                parsed = parse_block(block)
                if parsed is None:
                    continue  # a comment (opening, keep-alive)
                if parsed is END:
                    result["finished"] = True
                    return
                event_id, changed_at, recorded_at = parsed
                ids.append(event_id)
                b = int((now - changed_at) * 1000.0 / BIN_MS)
                hist[b] = hist.get(b, 0) + 1
                b = int((now - recorded_at) * 1000.0 / BIN_MS)
                from_record[b] = from_record.get(b, 0) + 1


async def client_process(url: str, count: int, deadline_s: float) -> dict:
    import httpx

    cpu0, wall0 = time.process_time(), time.perf_counter()
    hist: dict[int, int] = {}
    from_record: dict[int, int] = {}
    results = [{} for _ in range(count)]
    readies = [asyncio.Event() for _ in range(count)]
    limits = httpx.Limits(max_connections=count + 4, max_keepalive_connections=count + 4)
    timeout = httpx.Timeout(30.0, read=30.0)
    async with httpx.AsyncClient(limits=limits, timeout=timeout) as client:
        tasks = [
            asyncio.ensure_future(
                one_client(client, url, hist, from_record, results[i], readies[i])
            )
            for i in range(count)
        ]
        await asyncio.wait_for(asyncio.gather(*(e.wait() for e in readies)), 30)
        print("ready", flush=True)
        done, pending = await asyncio.wait(tasks, timeout=deadline_s)
        for t in pending:
            t.cancel()
        errors = [repr(t.exception()) for t in done if t.exception() is not None]
    clients = []
    for res in results:
        ids = res.get("ids", [])
        clients.append(
            {
                "received": len(ids),
                "unique": len(set(ids)),
                "out_of_order": sum(1 for a, b in zip(ids, ids[1:], strict=False) if b <= a),
                "finished": res.get("finished", False),
            }
        )
    return {
        "hist": hist,
        "from_record": from_record,
        "clients": clients,
        "errors": errors[:3],
        "cpu_s": time.process_time() - cpu0,
        "wall_s": time.perf_counter() - wall0,
    }


# ------------------------------------------------------------------ server side


def start_server(sessions, library, fanout: str, poll_s: float | None = None):
    from api_server import serve_api

    from web_api.settings import ApiSettings

    settings = ApiSettings.from_mapping(
        {
            "api_keys": [{"user": "bench", "role": "viewer", "key": KEY}],
            "events_fanout": fanout,
            **({"events_poll_s": poll_s} if poll_s else {}),
        }
    )
    return serve_api(sessions, library, settings)


class Producer:
    """50 machines x 10 Hz status changes, written every `tick_s` through dnc.events.record."""

    STATES = ("ACTIVE", "ACTIVE", "ACTIVE", "FEED_HOLD", "ACTIVE", "READY")

    def __init__(self, sessions, machines: list[str], hz: float, tick_s: float = 0.01):
        self.sessions, self.machines, self.hz, self.tick_s = sessions, machines, hz, tick_s
        self.produced = 0
        self.transactions = 0
        self.max_behind_ms = 0.0
        self.cpu_s = 0.0

    def run(self, seconds: float) -> None:
        from dnc.db import transaction
        from dnc.events import record

        cpu0 = time.thread_time()
        period = 1.0 / self.hz
        n = len(self.machines)
        t0 = time.monotonic()
        wall0 = time.time()
        changes = [0] * n
        # machine i changes at t0 + i*period/n + k*period
        nxt = [t0 + i * period / n for i in range(n)]
        end = t0 + seconds
        tick = t0
        while True:
            # Wall-paced: a starved producer writes the overdue changes late (their change
            # time stays when they happened) rather than stretching the run.
            tick = max(tick + self.tick_s, time.monotonic() - self.tick_s)
            delay = tick - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            now = time.monotonic()
            due = [i for i in range(n) if nxt[i] <= now and nxt[i] < end]
            if not due and now >= end:
                break
            if not due:
                continue
            # how long after it happened the oldest change is written (the tick adds <= 10 ms)
            self.max_behind_ms = max(self.max_behind_ms, (now - min(nxt[i] for i in due)) * 1000)
            with transaction(self.sessions) as s:
                recorded_at = time.time()
                for i in due:
                    changes[i] += 1
                    changed_at = wall0 + (nxt[i] - t0)
                    record(
                        s,
                        now=datetime.fromtimestamp(changed_at, UTC),
                        actor="monitor",
                        action="machine.status",
                        entity="machine",
                        entity_id=None,
                        machine=self.machines[i],
                        execution=self.STATES[changes[i] % len(self.STATES)],
                        line=10 * changes[i],
                        changed_at=changed_at,
                        recorded_at=recorded_at,
                    )
                    nxt[i] += period
                    self.produced += 1
            self.transactions += 1
        self.cpu_s = time.thread_time() - cpu0

    def end(self) -> None:
        from dnc.db import transaction
        from dnc.events import record

        with transaction(self.sessions) as s:
            record(
                s,
                now=datetime.now(UTC),
                actor="bench",
                action="bench.end",
                entity="machine",
                entity_id=None,
                produced=self.produced,
            )


def read_line(proc: subprocess.Popen, deadline: float) -> str:
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.2)
        if ready:
            line = proc.stdout.readline()
            if not line:
                raise RuntimeError(f"client process ended early: {proc.stderr.read()[-500:]}")
            return line.strip()
    raise TimeoutError("client process did not answer in time")


def percentile(hist: dict[int, int], q: float) -> float:
    total = sum(hist.values())
    if not total:
        return math.nan
    rank = max(1, math.ceil(q * total))
    seen = 0
    for b in sorted(hist):
        seen += hist[b]
        if seen >= rank:
            return round((b + 1) * BIN_MS, 2)  # the bin's upper edge: never flattering
    return math.nan


def run_phase(fanout: str, args, producer_apart: bool = False) -> dict:
    from dnc.db import make_engine, migrate, session_factory
    from dnc.library import Library

    tmp = tempfile.mkdtemp(prefix="bench-api-events-")
    engine = make_engine(f"sqlite:///{tmp}/fmscell.db")
    migrate(engine)
    sessions = session_factory(engine)
    library = Library(sessions)
    machines = [f"mill-{i:02d}" for i in range(1, args.machines + 1)]
    for name in machines:
        library.register_machine(name, "mill", memory_bytes=64 * 1024)
    from web_api.event_hub import latest_event_id

    after = latest_event_id(sessions)
    # A producer in its own process is not seen committing: the hub finds its events by
    # polling, so that run polls every 50 ms (one query per server, not per client).
    poll_s = 0.05 if producer_apart else None
    app, server, thread, sock = start_server(sessions, library, fanout, poll_s)
    url = f"http://127.0.0.1:{sock.getsockname()[1]}/api/events?after={after}"
    per_proc = [
        args.clients // args.procs + (i < args.clients % args.procs) for i in range(args.procs)
    ]
    seconds = args.seconds if fanout == "hub" else args.peer_seconds
    limit_s = seconds + 12
    procs = [
        subprocess.Popen(
            [sys.executable, __file__, "--client-process", url, str(k), str(limit_s)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k in per_proc
    ]
    try:
        deadline = time.monotonic() + 40
        for p in procs:
            if read_line(p, deadline) != "ready":
                raise RuntimeError("client process did not get ready")
        load_before = os.getloadavg()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        hub = app.state.event_hub
        polls0 = hub.polls
        if producer_apart:
            maker = subprocess.Popen(
                [sys.executable, __file__, "--producer-process", f"{tmp}/fmscell.db"]
                + [str(args.machines), str(args.hz), str(seconds)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            procs.append(maker)
            producer = Producer(None, machines, args.hz)
            vars(producer).update(json.loads(read_line(maker, time.monotonic() + seconds + 30)))
        else:
            producer = Producer(sessions, machines, args.hz)
            producer.run(seconds)
            producer.end()
        outs = [
            json.loads(read_line(p, time.monotonic() + limit_s)) for p in procs[: len(per_proc)]
        ]
        server_cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        load_after = os.getloadavg()
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()
        server.should_exit = True
        thread.join(timeout=20)
        sock.close()
        engine.dispose()
    hist: dict[int, int] = {}
    from_record: dict[int, int] = {}
    for o in outs:
        for b, c in o["hist"].items():
            hist[int(b)] = hist.get(int(b), 0) + c
        for b, c in o["from_record"].items():
            from_record[int(b)] = from_record.get(int(b), 0) + c
    clients = [c for o in outs for c in o["clients"]]
    per_client = [c["received"] for c in clients]
    received = sum(per_client)
    return {
        "fanout": fanout,
        "seconds": seconds,
        "events": producer.produced,
        "events_per_s": round(producer.produced / seconds, 1),
        "write_transactions": producer.transactions,
        "producer_max_behind_ms": round(producer.max_behind_ms, 1),
        "clients": args.clients,
        "client_processes": args.procs,
        "deliveries": received,
        "latency_ms": {
            "p50": percentile(hist, 0.50),
            "p95": percentile(hist, 0.95),
            "p99": percentile(hist, 0.99),
            "max": round((max(hist) + 1) * BIN_MS, 2) if hist else None,
        },
        "latency_from_record_ms": {
            "p50": percentile(from_record, 0.50),
            "p95": percentile(from_record, 0.95),
            "p99": percentile(from_record, 0.99),
        },
        "events_per_client": {
            "min": min(per_client),
            "max": max(per_client),
            "mean": round(sum(per_client) / len(per_client), 1),
        },
        # Against what the producer wrote. The sentinel comes after every status event in
        # id order, so a client that saw it and misses one lost it; a client cut short by
        # the time limit had the rest still on its way (overload, not loss).
        "lost": sum(max(0, producer.produced - c["unique"]) for c in clients if c["finished"]),
        "undelivered_at_time_limit": sum(
            max(0, producer.produced - c["unique"]) for c in clients if not c["finished"]
        ),
        "duplicated": sum(c["received"] - c["unique"] for c in clients),
        "out_of_order": sum(c["out_of_order"] for c in clients),
        "clients_not_finished": sum(not c["finished"] for c in clients),
        "client_errors": [e for o in outs for e in o["errors"]][:3],
        "outbox_reads_by_hub": hub.polls - polls0 if fanout == "hub" else None,
        "server_process_cpu_s": round(server_cpu, 2),
        "server_process_cpu_per_wall": round(server_cpu / wall, 2),
        "producer": "own process" if producer_apart else "thread in the server process",
        "events_poll_s": poll_s or 0.25,
        "producer_cpu_s": round(producer.cpu_s, 2),
        # the server process less the producer (which plays the cell host's monitor)
        "fanout_cpu_us_per_delivery": round(
            (server_cpu - (0 if producer_apart else producer.cpu_s)) / max(received, 1) * 1e6,
            2,
        ),
        "client_processes_cpu_s": round(sum(o["cpu_s"] for o in outs), 2),
        "wall_s": round(wall, 2),
        "load_average": [round(x, 2) for x in (*load_before, *load_after)],
    }


def main() -> int:
    if len(sys.argv) == 6 and sys.argv[1] == "--producer-process":
        from dnc.db import make_engine, session_factory

        _, _, db, machines, hz, seconds = sys.argv
        engine = make_engine(f"sqlite:///{db}")
        names = [f"mill-{i:02d}" for i in range(1, int(machines) + 1)]
        producer = Producer(session_factory(engine), names, float(hz))
        producer.run(float(seconds))
        producer.end()
        print(json.dumps({k: v for k, v in vars(producer).items() if k != "sessions"}))
        return 0
    if len(sys.argv) == 5 and sys.argv[1] == "--client-process":
        out = asyncio.run(client_process(sys.argv[2], int(sys.argv[3]), float(sys.argv[4])))
        print(json.dumps(out), flush=True)
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--machines", type=int, default=50)
    ap.add_argument("--hz", type=float, default=10.0)
    ap.add_argument("--clients", type=int, default=100)
    ap.add_argument("--procs", type=int, default=2, help="client processes")
    ap.add_argument("--seconds", type=float, default=10.0, help="producing time, hub fan-out")
    ap.add_argument("--peer-seconds", type=float, default=5.0, help="the old fan-out; 0: skip")
    ap.add_argument("--budget", type=float, default=55.0, help="seconds for the whole run")
    args = ap.parse_args()
    if not (1 <= args.procs <= args.clients):
        ap.error("--procs must be between 1 and --clients")
    started = time.monotonic()
    hub = run_phase("hub", args)
    # Stop by ourselves: the peer runs only if it fits in the budget (a loaded box slows
    # everything, and the old fan-out most of all).
    spent = time.monotonic() - started
    if args.peer_seconds <= 0:
        peer = None
    elif spent + 1.5 * args.peer_seconds + 8 > args.budget:
        peer = {"skipped": f"the hub run took {spent:.0f} s of the {args.budget:.0f} s budget"}
    else:
        peer = run_phase("poll", args)
    spent = time.monotonic() - started
    if args.peer_seconds <= 0 or spent + 1.5 * args.seconds + 8 > args.budget:
        apart = {"skipped": f"{spent:.0f} s of the {args.budget:.0f} s budget spent"}
    else:
        apart = run_phase("hub", args, producer_apart=True)
    p95 = hub["latency_ms"]["p95"]
    out = {
        "machines": args.machines,
        "status_hz": args.hz,
        "clients": args.clients,
        "target": f"p95 change-to-client latency < {TARGET_P95_MS:.0f} ms, nothing lost",
        "meets": bool(
            p95 < TARGET_P95_MS
            and hub["lost"] == hub["duplicated"] == hub["out_of_order"] == 0
            and hub["clients_not_finished"] == 0
        ),
        **{k: hub[k] for k in ("events", "latency_ms", "events_per_client", "lost", "duplicated")},
        "hub": hub,
        "peer_per_client_polling": peer,
        "hub_producer_in_own_process": apart,
        "database": "SQLite (WAL) file",
        "cpu_count": os.cpu_count(),
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
