"""Program uploads through the REST API: time and the host's peak RSS growth.

The real app on uvicorn in a child process (127.0.0.1, ephemeral port, real HTTP) over
SQLite with the host's NC check (`dnc.checker.nc_checker`). Cases, each on a fresh server:

- file_1mb .. file_15mb: one program of 1, 5, 10, 15 MB as a multipart file (the streamed
  path, dnc/upload.py); `file_growth_mb_per_upload_mb`: how the peak grows with the size
  (0 = flat);
- file_4x15mb: four 15 MB programs at once, multipart;
- peer json_10mb / json_4x15mb: the same programs as JSON bodies, the path that still holds
  the body and its text in memory (what every upload did before streaming).

RSS is the server process's VmRSS sampled every 5 ms; growth = peak - RSS before the case.
Time is the wall time until every response is in (the NC check is most of it: about 1 s
per MB on this box in pure Python, compiled more than twice as fast).

    .venv/bin/python bench/bench_api_upload.py [--scale 1.0]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEY = "bench-programmer-key-0123456789"
MB = 1024 * 1024


def program(size: int, number: int) -> bytes:
    block = "".join(f"G1 X{i % 50}.{i % 10} Y{i % 7}.5 F300\n" for i in range(4000)).encode()
    head = f"%\nO{number} (UPLOAD BENCH)\nG21 G90 G17\n".encode()
    body = block * (size // len(block) + 1)
    return head + body[: size - len(head) - 6] + b"M30\n%\n"


def serve(port_file: str) -> None:
    """Child process: the app on an ephemeral port; writes the port to `port_file`."""
    import socket

    import uvicorn

    from dnc.checker import nc_checker
    from dnc.db import make_engine, migrate, session_factory
    from dnc.dispatch import Dispatches
    from dnc.jobs import Jobs
    from dnc.library import Library
    from web_api.app import create_app
    from web_api.settings import ApiSettings

    db = Path(tempfile.mkdtemp()) / "bench.db"
    engine = make_engine(f"sqlite:///{db}")
    migrate(engine)
    sessions = session_factory(engine)
    settings = ApiSettings.from_mapping(
        {
            "api_keys": [{"user": "bench", "role": "programmer", "key": KEY}],
            "upload_limit_bytes": 32 * MB,
        }
    )
    library = Library(sessions, checker=nc_checker, upload_limit=32 * MB)
    app = create_app(
        settings,
        library=library,
        dispatches=Dispatches(sessions),
        jobs=Jobs(sessions),
        sessions=sessions,
    )
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(2048)  # uvicorn's default backlog, as `fmscell run` listens: 64 dropped SYNs
    # of a burst of 200 connections (retried after 1, 3, 7 s...: a p95 of many seconds)
    Path(port_file).write_text(str(sock.getsockname()[1]))
    uvicorn.Server(uvicorn.Config(app, log_level="warning")).run(sockets=[sock])


def rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


class Sampler:
    def __init__(self, pid: int) -> None:
        self.pid, self.peak, self._stop = pid, 0, threading.Event()
        self.base = rss_kb(pid)
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, rss_kb(self.pid))
            time.sleep(0.005)

    def stop(self) -> float:
        self._stop.set()
        self.thread.join()
        self.peak = max(self.peak, rss_kb(self.pid))
        return (self.peak - self.base) / 1024


def run_case(kind: str, sizes: list[int]) -> dict:
    import httpx

    with tempfile.TemporaryDirectory() as tmp:
        port_file = os.path.join(tmp, "port")
        proc = subprocess.Popen([sys.executable, __file__, "--serve", port_file])
        try:
            deadline = time.monotonic() + 60
            while not (os.path.exists(port_file) and Path(port_file).read_text()):
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError("the API server did not start")
                time.sleep(0.05)
            base = f"http://127.0.0.1:{Path(port_file).read_text()}"
            bodies = [program(size, 1000 + i) for i, size in enumerate(sizes)]
            with httpx.Client(base_url=base, timeout=600) as warm:
                # warm-up: a small program of each kind, so the NC check's imports and the
                # first connections are in the baseline, not in the case's growth
                warm.get("/api/health")
                small = program(64 * 1024, 999)
                warm.post(
                    "/api/programs", files={"file": ("O999.nc", small)}, headers={"X-API-Key": KEY}
                )
                warm.post(
                    "/api/programs",
                    json={
                        "number": 998,
                        "name": "w",
                        "text": small.decode().replace("O999", "O998"),
                    },
                    headers={"X-API-Key": KEY},
                )

            def upload(i: int) -> int:
                headers = {"X-API-Key": KEY}
                with httpx.Client(base_url=base, timeout=600) as c:
                    if kind == "file":
                        files = {"file": (f"O{1000 + i}.nc", bodies[i])}
                        return c.post("/api/programs", files=files, headers=headers).status_code
                    doc = {"number": 1000 + i, "name": f"p{i}", "text": bodies[i].decode()}
                    return c.post("/api/programs", json=doc, headers=headers).status_code

            sampler = Sampler(proc.pid)
            t0 = time.perf_counter()
            with ThreadPoolExecutor(len(sizes)) as pool:
                statuses = list(pool.map(upload, range(len(sizes))))
            seconds = time.perf_counter() - t0
            growth = sampler.stop()
        finally:
            proc.terminate()
            proc.wait(30)
    return {
        "seconds": round(seconds, 2),
        "rss_growth_mb": round(growth, 1),
        "statuses": statuses,
        "mb": round(sum(sizes) / MB, 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scale", type=float, default=1.0, help="program sizes x this")
    ap.add_argument("--serve", help=argparse.SUPPRESS)
    ap.add_argument("--cases", help="comma-separated case names (default: all)")
    args = ap.parse_args()
    if args.serve:
        serve(args.serve)
        return
    fifteen = int(15 * MB * args.scale)
    cases = {f"file_{mb}mb": ("file", [int(mb * MB * args.scale)]) for mb in (1, 5, 10, 15)}
    cases["file_4x15mb"] = ("file", [fifteen] * 4)
    cases["peer_json_10mb"] = ("json", [int(10 * MB * args.scale)])
    cases["peer_json_4x15mb"] = ("json", [fifteen] * 4)
    wanted = args.cases.split(",") if args.cases else list(cases)
    out: dict = {name: run_case(*cases[name]) for name in wanted}
    if "file_1mb" in out and "file_15mb" in out:
        # flat in size: the peak's growth per MB uploaded, from the 1 MB to the 15 MB case
        small, large = out["file_1mb"], out["file_15mb"]
        out["file_growth_mb_per_upload_mb"] = round(
            (large["rss_growth_mb"] - small["rss_growth_mb"]) / (large["mb"] - small["mb"]), 2
        )
    if "file_4x15mb" in out and "peer_json_4x15mb" in out:
        out["rss_ratio_4x15mb_file_vs_json"] = round(
            out["file_4x15mb"]["rss_growth_mb"]
            / max(out["peer_json_4x15mb"]["rss_growth_mb"], 0.1),
            3,
        )
    out["scale"] = args.scale
    print(json.dumps(out))


if __name__ == "__main__":
    main()
