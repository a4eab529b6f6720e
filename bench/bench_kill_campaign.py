"""kill -9 campaign: the host process and the machine processes of a running cell killed at
random moments and started again; afterwards nothing lost, nothing made twice, nothing stuck.

A cell of mills, each a `fmscell machine` process, under a host `fmscell run --processes`
(fast clock, ideal axes) on SQLite and on PostgreSQL. Jobs are kept queued while the
campaign runs. At seeded random moments the host (`kill -9`, then started again: it adopts
the machines, which cut on) or one machine process (`kill -9`, then started again on its
ports, well within the cell's contact time-out) dies. Then the jobs run out, and the books
are checked against the machines' own part counters:

- lost: parts ordered and never counted (a job that did not complete), or counted by the
  DNC and made by no machine;
- duplicates: parts a machine made beyond those the DNC counted (each such part was made
  again elsewhere);
- per machine, its part counter equals the allocations the DNC completed on it;
- stuck: allocations still `dispatched`/`running` once every job has completed.

Recovery time: from the kill to the host answering with every machine connected again
(host kills), or to the host seeing the restarted machine answer (machine kills).

    python bench/bench_kill_campaign.py                  # short: 3 host + 2 machine kills, SQLite
    python bench/bench_kill_campaign.py --kills 20       # 20 host + 20 machine kills, both databases

Prints ONE JSON object. PostgreSQL: 127.0.0.1:5432, database `test`, trust auth (or
FMSCELL_TEST_PG_URL); a scratch database per campaign, dropped after. If it does not answer,
its entry says `skipped` and why, a `SKIP postgresql: ...` line goes to stderr, and the exit
status is 2: a campaign asked to cover PostgreSQL that did not is not a pass. A run that may
go without it says so: `--allow-missing-pg` (the same line, exit 0 when the rest kept the
books).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import httpx
import yaml

ROOT = Path(__file__).resolve().parent.parent
KEY = "kill-campaign-admin-key-0123456789"
DEFAULT_PG = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
# a part of a few hundred milliseconds on the fast clock: long enough to be killed mid-cut
PROGRAM = """%
O1001 (KILL CAMPAIGN PART)
N10 G21 G90 G17
N20 G0 X-40 Y-30 Z-10
N30 G1 Z-50 F6000
N40 G1 X-240 Y-60 F3000
N50 G0 Z-20
N60 M30
%
"""
JOB_SIZE = 3
QUEUED_PARTS = 6  # parts kept waiting while the campaign runs


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    with contextlib.suppress(OSError):  # a zombie of ours is dead
        if Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] == "Z":
            return False
    return True


def wait(predicate, timeout_s: float, what: str, interval_s: float = 0.05):
    end = time.monotonic() + timeout_s
    last = None
    while time.monotonic() < end:
        last = predicate()
        if last:
            return last
        time.sleep(interval_s)
    raise TimeoutError(f"{what}: not within {timeout_s} s (last: {last!r})")


def pct(values: list[float]) -> dict:
    if not values:
        return {"p50": None, "max": None}
    return {"p50": round(statistics.median(values), 2), "max": round(max(values), 2)}


class CellUnderTest:
    """The host process and its machine processes in one scratch directory."""

    def __init__(self, work: Path, machines: list[str], database_url: str) -> None:
        self.work, self.names, self.database_url = work, machines, database_url
        self.port = free_port()
        doc = {
            "machines": {
                n: {
                    "base": "mill3",
                    "ports": {
                        "host": "127.0.0.1",
                        "dnc": free_port(),
                        "modbus": free_port(),
                        "shdr": free_port(),
                    },
                }
                for n in machines
            },
            # machine restarts are well within it: the restart, not the time-out, ends a run
            "host": {
                "lost_contact_s": 300.0,
                "auth": {"api_keys": [{"user": "bench", "role": "admin", "key": KEY}]},
            },
        }
        self.config = work / "cell.yaml"
        self.config.write_text(yaml.safe_dump(doc))
        self.api = httpx.Client(
            base_url=f"http://127.0.0.1:{self.port}", headers={"X-API-Key": KEY}, timeout=30
        )
        self.host: subprocess.Popen | None = None
        self.restarted: dict[str, subprocess.Popen] = {}  # machine processes this bench started
        self.env = {
            **{k: v for k, v in os.environ.items() if k != "FMSCELL_DATABASE_URL"},
            "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        }

    # -------------------------------------------------------------- processes
    def start_host(self) -> None:
        cmd = [sys.executable, "-m", "server.cli", "run", "--config", str(self.config)]
        cmd += ["--clock", "fast", "--processes", "--ideal-axes", "--port", str(self.port)]
        cmd += ["--database-url", self.database_url]
        with open(self.work / "host.log", "ab") as log:
            self.host = subprocess.Popen(
                cmd, cwd=self.work, stdout=log, stderr=log, stdin=subprocess.DEVNULL, env=self.env
            )

    def kill_host(self) -> None:
        self.host.send_signal(signal.SIGKILL)
        self.host.wait(30)

    def machine_pid(self, name: str) -> int:
        return json.loads((self.work / f"{name}.machine.json").read_text())["pid"]

    def kill_machine(self, name: str) -> None:
        pid = self.machine_pid(name)
        os.kill(pid, signal.SIGKILL)
        if name in self.restarted:
            self.restarted.pop(name).wait(30)
        wait(lambda: not alive(pid), 30, f"{name} (pid {pid}) dead")
        # seen lost by the host before the restart: else its view of the old connection
        # could pass for the restarted machine answering
        wait(lambda: not self.machine_answering(name), 60, f"{name} seen lost", interval_s=0.05)

    def start_machine(self, name: str) -> None:
        """The operator's restart of a machine's control, on its configured ports."""
        from server.supervisor import SECRET_ENV, machine_command

        state = self.work / f"{name}.machine.json"
        state.unlink(missing_ok=True)
        secret = (self.work / f"{name}.machine.secret").read_text().strip()
        cmd = machine_command(
            self.config, name, ready_file=state, fast=True, simulation=False, ideal=True
        )
        with open(self.work / f"{name}.restarted.log", "ab") as log:
            self.restarted[name] = subprocess.Popen(
                cmd,
                cwd=self.work,
                env={**self.env, SECRET_ENV: secret},
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
                start_new_session=True,  # outlives a host killed meanwhile, as the host's own
            )

    def stop(self) -> None:
        """A clean host stop (it stops the machines it adopted); then whatever is left."""
        if self.host is not None and self.host.poll() is None:
            self.host.send_signal(signal.SIGTERM)
            try:
                self.host.wait(60)
            except subprocess.TimeoutExpired:
                self.host.kill()
                self.host.wait(10)
        for proc in self.restarted.values():
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(5)
        for state in self.work.glob("*.machine.json"):  # machines of a host killed last
            with contextlib.suppress(OSError, ValueError, KeyError):
                pid = json.loads(state.read_text())["pid"]
                if alive(pid):
                    os.kill(pid, signal.SIGKILL)
        self.api.close()

    # -------------------------------------------------------------- the host's view
    def get(self, path: str, **params):
        r = self.api.get(path, params=params or None)
        r.raise_for_status()
        return r.json()

    def status(self, name: str) -> dict:
        return self.get(f"/api/machines/{name}")["status"]

    def answering(self) -> bool:
        if self.host.poll() is not None:
            tail = (self.work / "host.log").read_text(errors="replace")[-3000:]
            raise RuntimeError(f"host exited {self.host.returncode}: {tail}")
        try:
            return all(self.status(n)["connected"] for n in self.names)
        except httpx.HTTPError:
            return False

    def machine_answering(self, name: str) -> bool:
        """The host sees the machine answer with its part counter."""
        with contextlib.suppress(httpx.HTTPError):
            s = self.status(name)
            return bool(s["connected"]) and s["counters"]["part_count"] is not None
        return False


class Campaign:
    def __init__(self, cell: CellUnderTest, rng: random.Random) -> None:
        self.cell, self.rng = cell, rng
        self.jobs: list[int] = []
        self.ordered = 0
        self.revision: int | None = None

    def upload(self) -> None:
        api = self.cell.api
        r = api.post(
            "/api/programs",
            json={"number": 1001, "name": "kill campaign", "text": PROGRAM, "machine_kind": "mill"},
        )
        r.raise_for_status()
        rev = r.json()["revision"]["id"]
        api.post(f"/api/revisions/{rev}/release", json={"comment": "bench"}).raise_for_status()
        self.revision = rev

    def feed(self) -> None:
        """Keep parts queued: a new job whenever fewer than QUEUED_PARTS wait."""
        try:
            waiting = 0
            for job in self.jobs:
                j = self.cell.get(f"/api/jobs/{job}")
                if j["status"] not in ("completed", "cancelled"):
                    waiting += j["quantity"] - j["done"]
            while waiting < QUEUED_PARTS:
                r = self.cell.api.post(
                    "/api/jobs",
                    json={"revision_id": self.revision, "quantity": JOB_SIZE},
                    headers={"Idempotency-Key": uuid.uuid4().hex},
                )
                r.raise_for_status()
                self.jobs.append(r.json()["id"])
                self.ordered += JOB_SIZE
                waiting += JOB_SIZE
        except httpx.HTTPError:
            pass  # a host just killed: fed at the next look

    def run_until(self, deadline: float) -> None:
        while time.monotonic() < deadline:
            self.feed()
            time.sleep(0.2)

    def drain(self, timeout_s: float) -> float:
        t0 = time.monotonic()

        def done():
            return all(self.cell.get(f"/api/jobs/{j}")["status"] == "completed" for j in self.jobs)

        with contextlib.suppress(TimeoutError):
            wait(done, timeout_s, "every job completed", interval_s=0.5)
        return time.monotonic() - t0


def campaign(
    database_url: str,
    *,
    host_kills: int,
    machine_kills: int,
    seed: int,
    machines: int = 2,
    gap_s: tuple[float, float] = (2.0, 6.0),
    drain_s: float = 300.0,
    work: Path | None = None,
) -> dict:
    """One campaign on one database; its figures."""
    rng = random.Random(seed)
    names = [f"mill{i + 1}" for i in range(machines)]
    kinds = ["host"] * host_kills + ["machine"] * machine_kills
    rng.shuffle(kinds)
    moments = [
        {"kind": k, "after_s": round(rng.uniform(*gap_s), 2), "target": "host"}
        if k == "host"
        else {"kind": k, "after_s": round(rng.uniform(*gap_s), 2), "target": rng.choice(names)}
        for k in kinds
    ]
    scratch = None
    if work is None:
        scratch = tempfile.TemporaryDirectory(prefix="kill-campaign-")
        work = Path(scratch.name)
    cell = CellUnderTest(work, names, database_url)
    recovery: dict[str, list[float]] = {"host": [], "machine": []}
    started = time.monotonic()
    try:
        cell.start_host()
        wait(cell.answering, 180, "host answering, machines connected", interval_s=0.2)
        run = Campaign(cell, rng)
        run.upload()
        for moment in moments:
            run.run_until(time.monotonic() + moment["after_s"])
            t0 = time.monotonic()
            if moment["kind"] == "host":
                cell.kill_host()
                cell.start_host()
                wait(cell.answering, 180, "host answering after its restart", interval_s=0.1)
            else:
                name = moment["target"]
                cell.kill_machine(name)
                cell.start_machine(name)
                ready = cell.work / f"{name}.machine.json"
                wait(
                    lambda n=name, f=ready: f.exists() and cell.machine_answering(n),
                    180,
                    f"{name} answering after its restart",
                    interval_s=0.1,
                )
            recovery[moment["kind"]].append(time.monotonic() - t0)
        drained_s = run.drain(drain_s)
        figures = books(cell, run, names)
    finally:
        cell.stop()
        if scratch is not None:
            scratch.cleanup()
    return {
        "kills": {"host": host_kills, "machine": machine_kills},
        "moments": moments,
        **figures,
        "recovery_s": {k: pct(v) for k, v in recovery.items()},
        "drain_s": round(drained_s, 1),
        "wall_s": round(time.monotonic() - started, 1),
    }


def books(cell: CellUnderTest, run: Campaign, names: list[str]) -> dict:
    """Parts ordered, counted by the DNC and made by the machines; what went wrong."""
    jobs = [cell.get(f"/api/jobs/{j}") for j in run.jobs]
    counted = sum(j["done"] for j in jobs)
    allocations = [a for j in jobs for a in j["allocations"]]
    per_machine = {}
    for name in names:
        per_machine[name] = {
            "part_counter": cell.status(name)["counters"]["part_count"],
            "allocations_completed": sum(
                a["machine"] == name and a["status"] == "completed" for a in allocations
            ),
        }
    made = sum(m["part_counter"] or 0 for m in per_machine.values())
    incomplete = [j["id"] for j in jobs if j["status"] != "completed"]
    dispatches, cursor = [], None
    while True:
        page = cell.get("/api/dispatches", limit=200, **({"cursor": cursor} if cursor else {}))
        dispatches += page["items"]
        if not (cursor := page.get("next_cursor")):
            break
    return {
        "parts": {"ordered": run.ordered, "counted": counted, "made": made},
        "duplicates": max(0, made - counted),
        "lost": (run.ordered - counted) + max(0, counted - made),
        "stuck": sum(a["status"] in ("dispatched", "running") for a in allocations),
        "jobs": {"created": len(jobs), "not_completed": incomplete},
        "per_machine": per_machine,
        "machines_off_the_books": sorted(
            n for n, m in per_machine.items() if m["part_counter"] != m["allocations_completed"]
        ),
        "allocations": {
            s: sum(a["status"] == s for a in allocations)
            for s in sorted({a["status"] for a in allocations})
        },
        "starts_in_doubt": sum(
            d["state"] == "failed" and "host stopped while starting" in (d["error"] or "")
            for d in dispatches
        ),
    }


def postgres_database() -> tuple[str | None, str, object]:
    """(URL of a fresh scratch database, "", dropper) or (None, why not, None)."""
    from sqlalchemy import create_engine, text

    from dnc.db import normalise_url

    admin_url = normalise_url(os.environ.get("FMSCELL_TEST_PG_URL") or DEFAULT_PG)
    try:
        admin = create_engine(
            admin_url, isolation_level="AUTOCOMMIT", connect_args={"connect_timeout": 3}
        )
        name = f"fmscell_kill_{uuid.uuid4().hex[:10]}"
        with admin.connect() as conn:
            conn.execute(text(f'CREATE DATABASE "{name}"'))
    except Exception as exc:  # noqa: BLE001 - the reason goes into the JSON
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        return None, f"PostgreSQL not reachable at {admin_url.split('@')[-1]}: {first}", None

    def drop() -> None:
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()

    return admin_url.rsplit("/", 1)[0] + f"/{name}", "", drop


def ok(result: dict) -> bool:
    return (
        result["duplicates"] == 0
        and result["lost"] == 0
        and result["stuck"] == 0
        and not result["machines_off_the_books"]
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--kills", type=int, default=None, help="host kills = machine kills = N")
    p.add_argument("--host-kills", type=int, default=3)
    p.add_argument("--machine-kills", type=int, default=2)
    p.add_argument("--seed", type=int, default=None, help="default: random, printed")
    p.add_argument("--machines", type=int, default=2)
    p.add_argument(
        "--backends", default=None, help="sqlite,postgresql (default: sqlite; both with --kills)"
    )
    p.add_argument(
        "--allow-missing-pg",
        action="store_true",
        help="a PostgreSQL that does not answer is a skip (exit 0), not a failure (exit 2)",
    )
    args = p.parse_args(argv)
    if args.kills is not None:
        args.host_kills = args.machine_kills = args.kills
    backends = (args.backends or ("sqlite,postgresql" if args.kills else "sqlite")).split(",")
    seed = args.seed if args.seed is not None else random.SystemRandom().randrange(1 << 31)
    out: dict = {
        "bench": "kill_campaign",
        "seed": seed,
        "machines": args.machines,
        "kills_per_campaign": {"host": args.host_kills, "machine": args.machine_kills},
    }
    for backend in backends:
        if backend == "sqlite":
            with tempfile.TemporaryDirectory(prefix="kill-campaign-") as tmp:
                out["sqlite"] = campaign(
                    f"sqlite:///{tmp}/cell.db",
                    host_kills=args.host_kills,
                    machine_kills=args.machine_kills,
                    seed=seed,
                    machines=args.machines,
                    work=Path(tmp),
                )
        elif backend == "postgresql":
            url, why, drop = postgres_database()
            if url is None:
                out["postgresql"] = {"skipped": why}
                allowed = "allowed by --allow-missing-pg" if args.allow_missing_pg else "exit 2"
                print(f"SKIP postgresql: {why} ({allowed})", file=sys.stderr, flush=True)
                continue
            try:
                out["postgresql"] = campaign(
                    url,
                    host_kills=args.host_kills,
                    machine_kills=args.machine_kills,
                    seed=seed,
                    machines=args.machines,
                )
            finally:
                drop()
        else:
            p.error(f"--backends: {backend!r} is not sqlite or postgresql")
    ran = [out[b] for b in backends if "skipped" not in out[b]]
    skipped = [b for b in backends if "skipped" in out[b]]
    out["ok"] = all(ok(r) for r in ran)
    print(json.dumps(out))
    if not out["ok"]:
        return 1
    # a backend asked for and not run proves nothing about it
    return 2 if skipped and not args.allow_missing_pg else 0


if __name__ == "__main__":
    sys.exit(main())
