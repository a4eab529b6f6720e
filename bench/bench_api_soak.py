"""A short soak of the REST API in one process: RSS and traced-allocation growth after warm-up.

The app over SQLite through Starlette's TestClient (no sockets: the growth measured is the
app's, not a client's). One round = upload a program, health, list programs, jobs and
dispatches, release the revision, dispatch it, make a job of it, a 404 and a 405: ten
requests. After `--warm` rounds, RSS is read, tracemalloc (1 frame) started and `--rounds`
more run; the JSON gives the RSS growth per 1000 requests, the traced growth and the sites
that grew most (a leak shows as a site growing with every round; a bounded cache stops).

    .venv/bin/python bench/bench_api_soak.py [--warm 300] [--rounds 300]
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEY = "soak-admin-key-0123456789abcdef"
PROG = "%\nO{n} (P)\nG0 X0 Y0\nG1 X10 F100\nM30\n%\n"


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--warm", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=300)
    args = ap.parse_args()

    from fastapi.testclient import TestClient

    from dnc.db import make_engine, migrate, session_factory
    from dnc.dispatch import Dispatches
    from dnc.jobs import Jobs
    from dnc.library import Library
    from web_api.app import create_app
    from web_api.settings import ApiSettings

    db = Path(tempfile.mkdtemp()) / "soak.db"
    engine = make_engine(f"sqlite:///{db}")
    migrate(engine)
    s = session_factory(engine)
    lib = Library(s, upload_limit=1 << 20)
    lib.register_machine("mill-1", "mill", memory_bytes=65536)
    settings = ApiSettings.from_mapping(
        {"api_keys": [{"user": "soak", "role": "admin", "key": KEY}]}
    )
    app = create_app(settings, library=lib, dispatches=Dispatches(s), jobs=Jobs(s), sessions=s)
    h = {"X-API-Key": KEY}
    counter = iter(range(1, 10**9))

    def one_round(c) -> None:
        i = next(counter)
        number = i % 90000 + 1
        body = {"number": number, "name": f"p{i}", "text": PROG.format(n=number)}
        r = c.post("/api/programs", json=body, headers=h)
        c.get("/api/health")
        c.get("/api/programs?limit=5", headers=h)
        c.get("/api/jobs", headers=h)
        c.get("/api/dispatches", headers=h)
        if r.status_code == 201:
            rev = r.json()["revision"]["id"]
            c.post(f"/api/revisions/{rev}/release", json={"comment": "ok"}, headers=h)
            c.post(
                "/api/dispatches",
                json={"revision_id": rev, "machine": "mill-1"},
                headers={**h, "Idempotency-Key": f"k{i}"},
            )
            c.post("/api/jobs", json={"revision_id": rev, "quantity": 1}, headers=h)
        c.get("/api/nope", headers=h)
        c.put("/api/programs", headers=h)

    with TestClient(app) as c:
        for _ in range(args.warm):
            one_round(c)
        gc.collect()
        before = rss_mb()
        tracemalloc.start(1)
        first = tracemalloc.take_snapshot()
        t0 = time.perf_counter()
        for _ in range(args.rounds):
            one_round(c)
        seconds = time.perf_counter() - t0
        gc.collect()
        last = tracemalloc.take_snapshot()
        tracemalloc.stop()
        grown = rss_mb() - before
    stats = last.compare_to(first, "lineno")
    requests = args.rounds * 10
    print(
        json.dumps(
            {
                "requests": requests,
                "seconds": round(seconds, 1),
                "rss_growth_mb": round(grown, 2),
                "rss_growth_mb_per_1000_requests": round(grown / requests * 1000, 3),
                "traced_growth_kb": round(sum(x.size_diff for x in stats) / 1024, 1),
                "top_sites": [
                    {
                        "site": f"{x.traceback[0].filename}:{x.traceback[0].lineno}",
                        "kb": round(x.size_diff / 1024, 1),
                        "count": x.count_diff,
                    }
                    for x in stats[:5]
                ],
                "note": "RSS under tracemalloc includes its own bookkeeping",
            }
        )
    )


if __name__ == "__main__":
    main()
