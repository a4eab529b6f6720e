"""Scan lateness of the machine-tool PLC program while its Modbus face is under full load.

The machine's PLC as a machine process runs it: the program `plc/programs/machine_tool.ld`
with the simulated machine (`MachineIO`) in a `RealtimeRunner` at 10 ms, the `ModbusFace`
(remote-panel allow-list) in the same process, and a small NC thread doing T / M6 / M3 / M5
handshakes through the signal table so the program is busy. Client processes on loopback
hammer the face with a read/write mix (FC03 x10 status registers, FC01 x16 status coils,
FC16 x3 override registers, FC05 remote feed-hold-free coil writes), each keeping one request
outstanding per connection, for a bounded time.

Phases in the same run: `idle` (no Modbus traffic) as the peer figure, then `loaded`.
Prints one JSON object: lateness p50/p99/max per phase, overruns, missed periods, requests/s
served, handshakes completed, the 1 ms p99 target.

Two runtime remedies (plc/runtime/realtime.py) are off by default, as in the runtime:
`--scan-gate` builds the face with `scan_gate=runner.gate` (the face steps aside, GIL released,
just before each scan) and `--rt-priority N` asks SCHED_FIFO N for the scan thread (the JSON
says whether it was granted); `--face-rt-priority M` (M below N) also gives the face's thread
SCHED_FIFO so that ordinary processes cannot deschedule it while it holds the GIL. Compare
runs with and without them, alternated, in one session.

Usage: bench_plc_lateness.py [--seconds 10] [--idle-seconds 3] [--client-procs 2]
                             [--connections 8] [--client-nice 0]
                             [--scan-gate] [--rt-priority N] [--face-rt-priority M]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import socket
import struct
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

TARGET_P99_MS = 1.0
PERIOD_MS = 10


def _frames() -> list[tuple[bytes, int]]:
    """(request, answer length) of the mix: 3 reads for every write."""
    from plc.remote_panel import COMMAND_REGISTERS, STATUS_COILS, STATUS_REGISTERS

    hr0 = min(STATUS_REGISTERS.values())
    co0 = min(STATUS_COILS.values())
    ovr = COMMAND_REGISTERS["RemFeedOvr"]
    fc03 = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, hr0, 10)
    fc01 = struct.pack(">HHHBBHH", 1, 0, 6, 1, 1, co0, 16)
    fc16 = struct.pack(">HHHBBHHB3H", 1, 0, 13, 1, 16, ovr, 3, 6, 100, 100, 100)
    return [(fc03, 9 + 20), (fc01, 9 + 2), (fc03, 9 + 20), (fc16, 12)]


def client_worker(port, connections, frames, start_at, end_at, nice, out) -> None:
    if nice:
        os.nice(nice)  # stands for clients on other hosts: they yield the CPU to the PLC
    socks = []
    for _ in range(connections):
        s = socket.create_connection(("127.0.0.1", port), timeout=5)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        socks.append(s)
    count = exceptions = 0
    k = 0
    while time.monotonic() < start_at:
        time.sleep(0.001)
    while time.monotonic() < end_at:
        req, size = frames[k % len(frames)]
        k += 1
        for s in socks:
            s.sendall(req)
        for s in socks:
            data = b""
            while len(data) < 9:
                chunk = s.recv(size - len(data))
                if not chunk:
                    raise ConnectionError("the face closed the connection")
                data += chunk
            if data[7] & 0x80:
                exceptions += 1
            else:
                while len(data) < size:
                    data += s.recv(size - len(data))
            count += 1
    for s in socks:
        s.close()
    out.put((count, exceptions))


class NcDriver(threading.Thread):
    """A stand-in NC: tool changes and spindle on/off through the signal table, forever."""

    def __init__(self, nc) -> None:
        super().__init__(name="nc", daemon=True)
        self.nc = nc
        self.stop = threading.Event()
        self.handshakes = 0
        self.timeouts = 0

    def handshake(self, kind: str, value: int) -> None:
        nc = self.nc
        nc.set(kind + "Code", value)
        nc.set(kind + "Strobe", True)
        deadline = time.monotonic() + 10
        while not nc.get(kind + "Finish"):
            if self.stop.wait(0.002):
                return
            if time.monotonic() > deadline:
                self.timeouts += 1
                break
        nc.set(kind + "Strobe", False)
        while nc.get(kind + "Finish") and not self.stop.wait(0.002):
            pass
        self.handshakes += 1

    def run(self) -> None:
        nc = self.nc
        nc.set("NcReady", True)
        nc.set("NcMode", 1)
        tool = 1
        while not self.stop.is_set():
            tool = tool % 20 + 1
            nc.set("SCode", 2000 + 100 * tool)
            for kind, value in (("T", tool), ("M", 6), ("M", 3), ("M", 8), ("M", 9), ("M", 5)):
                if self.stop.is_set():
                    return
                self.handshake(kind, value)


def _lateness(samples: list[float]) -> dict:
    if not samples:
        return {"scans": 0}
    xs = sorted(samples)
    return {
        "scans": len(xs),
        "p50_ms": round(xs[len(xs) // 2], 3),
        "p99_ms": round(xs[min(len(xs) - 1, int(len(xs) * 0.99))], 3),
        "max_ms": round(xs[-1], 3),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0, help="loaded phase")
    ap.add_argument("--idle-seconds", type=float, default=3.0, help="unloaded phase")
    ap.add_argument("--client-procs", type=int, default=2)
    ap.add_argument("--connections", type=int, default=8, help="in total, over the processes")
    ap.add_argument(
        "--client-nice", type=int, default=0, help="nice increment of the client processes"
    )
    ap.add_argument(
        "--scan-gate",
        action="store_true",
        help="the face steps aside before each scan (ModbusFace(scan_gate=runner.gate))",
    )
    ap.add_argument(
        "--rt-priority",
        type=int,
        default=None,
        help="SCHED_FIFO priority of the scan thread (default: FMSCELL_PLC_RT_PRIORITY or 0)",
    )
    ap.add_argument(
        "--face-rt-priority",
        type=int,
        default=0,
        help="SCHED_FIFO priority of the face's thread (below --rt-priority; 0 = ordinary)",
    )
    args = ap.parse_args()
    if not 0 < args.seconds <= 60 or not 0 < args.idle_seconds <= 60:
        ap.error("--seconds and --idle-seconds must be in (0, 60]")

    from plc.machine_io import machine_plc
    from plc.modbus import ModbusFace
    from plc.remote_panel import WRITABLE
    from plc.runtime import RealtimeRunner, RuntimeConfig

    load_before = os.getloadavg()[0]
    rt, io = machine_plc(RuntimeConfig(period_ms=PERIOD_MS))
    runner = RealtimeRunner(rt, rt_priority=args.rt_priority)
    face = ModbusFace(
        lambda: rt.snapshot,
        rt.writes,
        rt.image.size,
        port=0,
        writable=WRITABLE,
        idle_timeout=None,
        scan_gate=runner.gate if args.scan_gate else None,
    )
    face.start_in_thread(rt_priority=args.face_rt_priority)
    nc = NcDriver(io.nc)
    runner.start()
    nc.start()

    def phase(seconds: float, load: bool) -> dict:
        stats = rt.stats
        c0, o0, m0, r0 = stats.count, stats.overruns, stats.missed, face.stats.requests
        h0 = nc.handshakes
        t0, cpu0 = time.monotonic(), time.process_time()
        served = exceptions = 0
        if load:
            procs = max(1, min(args.client_procs, args.connections))
            per = [args.connections // procs + (i < args.connections % procs) for i in range(procs)]
            # spawn, not fork: the parent runs the scan, face and NC threads
            ctx = mp.get_context("spawn")
            q = ctx.Queue()
            frames = _frames()
            start_at = time.monotonic() + 2.0  # spawned and connected before the window
            end_at = start_at + seconds
            workers = [
                ctx.Process(
                    target=client_worker,
                    args=(face.bound_port, n, frames, start_at, end_at, args.client_nice, q),
                )
                for n in per
            ]
            for w in workers:
                w.start()
            time.sleep(max(0.0, start_at - time.monotonic()))
            c0, o0, m0, r0 = stats.count, stats.overruns, stats.missed, face.stats.requests
            h0, t0, cpu0 = nc.handshakes, time.monotonic(), time.process_time()
            results = [q.get(timeout=seconds + 30) for _ in workers]
            for w in workers:
                w.join(10)
                if w.is_alive():
                    w.kill()
            served = sum(r[0] for r in results)
            exceptions = sum(r[1] for r in results)
        else:
            time.sleep(seconds)
        elapsed = time.monotonic() - t0
        cpu = time.process_time() - cpu0
        n = stats.count - c0
        samples = list(stats.late_ms)[-n:] if n else []
        out = {
            "lateness": _lateness(samples),
            "overruns": stats.overruns - o0,
            "missed_periods": stats.missed - m0,
            "nc_handshakes": nc.handshakes - h0,
            "seconds": round(elapsed, 2),
            # CPU of this process (scan + face + NC threads) per wall second: 1.0 = one core
            "process_cpu_per_s": round(cpu / elapsed, 3),
        }
        if load:
            out["requests_per_s"] = round(served / elapsed)
            out["process_cpu_us_per_request"] = round(cpu / served * 1e6, 1) if served else None
            out["face_requests_per_s"] = round((face.stats.requests - r0) / elapsed)
            out["exception_answers"] = exceptions
        return out

    try:
        time.sleep(0.5)  # warm-up: first scans, drive ready
        idle = phase(args.idle_seconds, load=False)
        loaded = phase(args.seconds, load=True)
    finally:
        nc.stop.set()
        nc.join(2)
        runner.stop()
        face.stop_thread()
    ex = rt.stats.execution()
    p99 = loaded["lateness"].get("p99_ms")
    print(
        json.dumps(
            {
                "program": "plc/programs/machine_tool.ld with MachineIO, RealtimeRunner",
                "period_ms": PERIOD_MS,
                "client_processes": args.client_procs,
                "connections": args.connections,
                "client_nice": args.client_nice,
                "scan_gate": args.scan_gate,
                "scan_thread_scheduling": runner.scheduling,
                "face_thread_scheduling": face.thread_scheduling,
                "gate_holds": runner.gate.holds,
                "gate_hold_timeouts": runner.gate.hold_timeouts,
                "workload": "FC03x10, FC01x16, FC03x10, FC16x3 in turn; 1 outstanding/conn",
                "loaded": loaded,
                "idle": idle,
                "scan_exec_us": {
                    "mean": round(ex.mean, 1),
                    "p99": round(ex.p99, 1),
                    "max": round(ex.max, 1),
                },  # fmt: skip
                "target_p99_ms": TARGET_P99_MS,
                "meets_target": p99 is not None and p99 <= TARGET_P99_MS,
                "ratio_loaded_to_idle_p99": (
                    round(p99 / idle["lateness"]["p99_ms"], 2)
                    if p99 is not None and idle["lateness"].get("p99_ms")
                    else None
                ),
                "nc_handshake_timeouts": nc.timeouts,
                "plc_alarms": sorted(rt.alarms),
                "cpus": os.cpu_count(),
                "loadavg_1min_before_after": [round(load_before, 2), round(os.getloadavg()[0], 2)],
                "note": "peer = the same runner with no Modbus traffic (idle phase), same run; "
                "the face, the scan thread and the NC thread share one process and its GIL; "
                "figures depend on other load on the box",
            }
        )
    )


if __name__ == "__main__":
    main()
