"""Many requests at once: 1000 requests, 200 in flight, against the REST API.

The server is bench_api_upload's (the real app on uvicorn in a child process, 127.0.0.1,
SQLite with 200 programs); the client sends `--requests` requests with `--concurrency` of
them in flight at any time (asyncio, one connection each, as 200 separate clients would),
a mix of GET /api/health, /api/programs?limit=20, /api/jobs, /api/dispatches and
/api/programs/{id}. Latency is from sending to the whole body; the JSON gives p50, p95,
p99, max, the throughput and the server's CPU seconds per request.

    .venv/bin/python bench/bench_api_load.py [--requests 1000] [--concurrency 200]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_api_upload import KEY  # noqa: E402

PATHS = (
    "/api/health",
    "/api/programs?limit=20",
    "/api/jobs",
    "/api/dispatches",
    "/api/programs/{id}",
)


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else 0.0


async def load(base: str, requests: int, concurrency: int) -> tuple[list[float], dict, float]:
    import httpx

    latencies: list[float] = []
    statuses: dict[str, int] = {}
    queue: asyncio.Queue[int] = asyncio.Queue()
    for i in range(requests):
        queue.put_nowait(i)

    async def client() -> None:
        limits = httpx.Limits(max_connections=1)
        async with httpx.AsyncClient(
            base_url=base, headers={"X-API-Key": KEY}, timeout=120, limits=limits
        ) as c:
            while True:
                try:
                    i = queue.get_nowait()
                except asyncio.QueueEmpty:
                    return
                path = PATHS[i % len(PATHS)].format(id=i % 200 + 1)
                t0 = time.perf_counter()
                try:
                    r = await c.get(path)
                    key = str(r.status_code)
                except httpx.HTTPError as exc:
                    key = type(exc).__name__
                latencies.append(time.perf_counter() - t0)
                statuses[key] = statuses.get(key, 0) + 1

    t0 = time.perf_counter()
    await asyncio.gather(*(client() for _ in range(concurrency)))
    return latencies, statuses, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--requests", type=int, default=1000)
    ap.add_argument("--concurrency", type=int, default=200)
    args = ap.parse_args()
    import httpx

    here = Path(__file__).resolve().parent
    with tempfile.TemporaryDirectory() as tmp:
        port_file = os.path.join(tmp, "port")
        proc = subprocess.Popen(
            [sys.executable, str(here / "bench_api_upload.py"), "--serve", port_file]
        )
        try:
            deadline = time.monotonic() + 60
            while not (os.path.exists(port_file) and Path(port_file).read_text()):
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError("the API server did not start")
                time.sleep(0.05)
            base = f"http://127.0.0.1:{Path(port_file).read_text()}"
            with httpx.Client(base_url=base, headers={"X-API-Key": KEY}, timeout=60) as c:
                for n in range(1, 201):
                    text = f"%\nO{n} (LOAD {n})\nG0 X0 Y0\nG1 X{n} F100\nM30\n%\n"
                    c.post("/api/programs", json={"number": n, "name": f"p{n}", "text": text})
                for p in PATHS:  # warm-up: every route once
                    c.get(p.format(id=1))
            cpu0 = cpu_s(proc.pid)
            latencies, statuses, seconds = asyncio.run(load(base, args.requests, args.concurrency))
            cpu = cpu_s(proc.pid) - cpu0
        finally:
            proc.terminate()
            proc.wait(30)
    print(
        json.dumps(
            {
                "requests": args.requests,
                "concurrency": args.concurrency,
                "seconds": round(seconds, 2),
                "requests_per_s": round(args.requests / seconds, 1),
                "p50_ms": round(pct(latencies, 0.50) * 1e3, 1),
                "p95_ms": round(pct(latencies, 0.95) * 1e3, 1),
                "p99_ms": round(pct(latencies, 0.99) * 1e3, 1),
                "max_ms": round(max(latencies) * 1e3, 1),
                "server_cpu_ms_per_request": round(cpu / args.requests * 1e3, 2),
                "statuses": statuses,
                "load_avg_1min": os.getloadavg()[0],
            }
        )
    )


if __name__ == "__main__":
    main()
