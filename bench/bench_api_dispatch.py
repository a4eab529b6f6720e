"""Dispatch requests per second through the REST API.

The real app on uvicorn (127.0.0.1, ephemeral port, real HTTP) over SQLite. A client
process keeps several connections busy with `POST /api/dispatches` for a released revision
against three machines:

- new: every request has its own Idempotency-Key, so each one is checked, recorded with its
  audit entry and outbox event, and answered 202;
- replay: the keys of the first phase again with the same bodies, answered 200 with the
  stored dispatch (`Idempotent-Replayed`);
- peer: `GET /api/health` on the same connections, the floor of one request through the
  app, auth and the database on this box.

No transfer worker runs: a dispatch stays pending. The worker's job is the DNC port (a
transfer to a machine takes as long as the tape at its baud rate), which the DNC transfer
benchmark measures; here only the API and the database are timed. Every row the API
answered 202 for is counted back from the database afterwards.

    .venv/bin/python bench/bench_api_dispatch.py [--seconds 5] [--connections 8]
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
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEY = "bench-operator-key-0123456789"
MACHINES = ("mill-1", "mill-2", "mill-3")
PROGRAM = "%\nO1001 (BRACKET)\nG21 G90 G54\nG0 X0 Y0\nG1 X10 F100\nG1 Y10\nM30\n%\n"


# ------------------------------------------------------------------ client process


async def client_process(
    base: str, phase: str, seconds: float, conns: int, rev: int, keys: int
) -> dict:
    import httpx

    headers = {"X-API-Key": KEY}
    latencies: list[float] = []
    statuses: dict[str, int] = {}
    errors: list[str] = []
    counter = iter(range(10**9))
    stop_at = time.perf_counter() + seconds

    def request_for(n: int) -> tuple[str, str, dict]:
        machine = MACHINES[n % len(MACHINES)]
        body = {"revision_id": rev, "machine": machine, "mode": "memory", "start": False}
        return "POST", "/api/dispatches", {"json": body, "headers": {"Idempotency-Key": f"k{n}"}}

    async def worker(client: httpx.AsyncClient, w: int) -> None:
        replay = 0
        while time.perf_counter() < stop_at:
            if phase == "new":
                method, url, kw = request_for(next(counter))
            elif phase == "replay":
                # keys the new phase used, spread over the connections
                method, url, kw = request_for((w * 7919 + replay) % keys)
                replay += 1
            else:
                method, url, kw = "GET", "/api/health", {}
            t = time.perf_counter()
            try:
                r = await client.request(method, url, **kw)
                latencies.append((time.perf_counter() - t) * 1000)
                statuses[str(r.status_code)] = statuses.get(str(r.status_code), 0) + 1
                if r.status_code >= 400 and len(errors) < 3:
                    errors.append(r.text[:200])
            except httpx.HTTPError as exc:
                statuses["transport"] = statuses.get("transport", 0) + 1
                if len(errors) < 3:
                    errors.append(repr(exc))

    cpu0, wall0 = time.process_time(), time.perf_counter()
    limits = httpx.Limits(max_connections=conns, max_keepalive_connections=conns)
    async with httpx.AsyncClient(
        base_url=base, headers=headers, limits=limits, timeout=30
    ) as client:
        await asyncio.gather(*(worker(client, w) for w in range(conns)))
    return {
        "latencies": latencies,
        "statuses": statuses,
        "errors": errors,
        "wall_s": time.perf_counter() - wall0,
        "cpu_s": time.process_time() - cpu0,
    }


# ------------------------------------------------------------------ server side


def read_line(proc: subprocess.Popen, deadline: float) -> str:
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.2)
        if ready:
            line = proc.stdout.readline()
            if not line:
                raise RuntimeError(f"client process ended early: {proc.stderr.read()[-500:]}")
            return line.strip()
    proc.kill()
    raise TimeoutError("client process did not answer in time")


def pct(sorted_ms: list[float], q: float) -> float | None:
    if not sorted_ms:
        return None
    return round(sorted_ms[min(len(sorted_ms) - 1, math.ceil(q * len(sorted_ms)) - 1)], 2)


def run_phase(base: str, phase: str, seconds: float, conns: int, rev: int, keys: int = 1) -> dict:
    load_before = os.getloadavg()
    cpu0 = time.process_time()
    proc = subprocess.Popen(
        [sys.executable, __file__, "--client-process", base, phase, str(seconds), str(conns)]
        + [str(rev), str(keys)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        out = json.loads(read_line(proc, time.monotonic() + seconds + 30))
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    server_cpu = time.process_time() - cpu0
    lat = sorted(out["latencies"])
    ok = sum(n for s, n in out["statuses"].items() if s in ("200", "202"))
    failed = sum(n for s, n in out["statuses"].items() if s not in ("200", "202"))
    return {
        "requests": len(lat) + out["statuses"].get("transport", 0),
        "req_per_s": round(len(lat) / out["wall_s"], 1),
        "latency_ms": {"p50": pct(lat, 0.50), "p95": pct(lat, 0.95), "p99": pct(lat, 0.99)},
        "statuses": out["statuses"],
        "ok": ok,
        "errors": failed,
        "error_samples": out["errors"],
        "server_cpu_ms_per_request": round(server_cpu / max(len(lat), 1) * 1000, 3),
        "client_cpu_s": round(out["cpu_s"], 2),
        "wall_s": round(out["wall_s"], 2),
        "load_average": [round(x, 2) for x in (*load_before, *os.getloadavg())],
    }


def main() -> int:
    if len(sys.argv) == 8 and sys.argv[1] == "--client-process":
        _, _, base, phase, seconds, conns, rev, keys = sys.argv
        out = asyncio.run(
            client_process(base, phase, float(seconds), int(conns), int(rev), int(keys))
        )
        print(json.dumps(out), flush=True)
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="per phase")
    ap.add_argument("--connections", type=int, default=8)
    args = ap.parse_args()
    if not 1 <= args.connections <= 64:
        ap.error("--connections must be 1..64")

    from api_server import serve_api
    from sqlalchemy import func, select

    from dnc import models as m
    from dnc.db import make_engine, migrate, session_factory, transaction
    from dnc.library import Library
    from web_api.settings import ApiSettings

    tmp = tempfile.mkdtemp(prefix="bench-api-dispatch-")
    engine = make_engine(f"sqlite:///{tmp}/fmscell.db")
    migrate(engine)
    sessions = session_factory(engine)
    library = Library(sessions)
    for name in MACHINES:
        library.register_machine(name, "mill", memory_bytes=64 * 1024)
    _, rev = library.create_program(number=1001, name="bracket", text=PROGRAM)
    library.release(rev.id, approver="bench", comment="bench")
    settings = ApiSettings.from_mapping(
        {"api_keys": [{"user": "bench", "role": "operator", "key": KEY}]}
    )
    _, server, thread, sock = serve_api(sessions, library, settings, backlog=128)
    base = f"http://127.0.0.1:{sock.getsockname()[1]}"
    try:
        new = run_phase(base, "new", args.seconds, args.connections, rev.id)
        made = new["statuses"].get("202", 0)
        if not made:
            raise RuntimeError(f"no dispatch was accepted: {new['error_samples']}")
        replay = run_phase(base, "replay", args.seconds, args.connections, rev.id, made)
        health = run_phase(base, "health", args.seconds / 2, args.connections, rev.id)
        with transaction(sessions) as s:
            stored = s.scalar(select(func.count()).select_from(m.Dispatch))
            pending = s.scalar(
                select(func.count()).select_from(m.Dispatch).where(m.Dispatch.state == "pending")
            )
    finally:
        server.should_exit = True
        thread.join(timeout=20)
        sock.close()
        engine.dispose()
    accepted = new["statuses"].get("202", 0)
    out = {
        "dispatch_req_per_s": new["req_per_s"],
        "latency_ms": new["latency_ms"],
        "errors": new["errors"] + replay["errors"],
        "replay_req_per_s": replay["req_per_s"],
        "replay_latency_ms": replay["latency_ms"],
        "peer_health_req_per_s": health["req_per_s"],
        "accepted_202": accepted,
        "stored_dispatches": stored,
        "stored_matches_accepted": stored == accepted,
        "connections": args.connections,
        "transfer_worker": "not running: dispatches stay pending; transfers are the DNC "
        "port's time (bench_dnc_transfer), this measures the API and the database",
        "pending_after": pending,
        "new": new,
        "replay": replay,
        "health": health,
        "database": "SQLite (WAL) file",
        "cpu_count": os.cpu_count(),
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
