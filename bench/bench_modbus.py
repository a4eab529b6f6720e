"""Modbus TCP throughput: our face vs pymodbus 3.16's stock server, same map, same run.

FC03 read of 10 holding registers, sequential request/response per connection (one request
outstanding per connection), on 1 and on 8 connections, loopback only. Each server runs in its
own process; clients run in separate processes on raw sockets so neither the client nor a
shared GIL dominates. Both servers run at once and the clients alternate 1 s slices between
them, so a busy neighbour on the box costs both the same. Our face runs with a 10 ms fake scan thread publishing snapshots, as in a
PLC; the stock server (ModbusTcpServer + ModbusDeviceContext over ModbusSequentialDataBlock,
coils 9216 / di 1024 / ir 1024 / hr 2048 like our default map) has no scan.

Besides wall figures (req/s, round-trip percentiles) it reports CPU per answered request: the
server process's user+system time over its slices (/proc, all threads, scan included) and the
client processes' time.process_time(), so a busy box can be told from a costly server.

Prints one JSON object. Targets: >= 15k req/s on one connection, >= 30k req/s on eight.
Usage: bench_modbus.py [--seconds 10] [--client-procs 2] [--switch-interval 0.0005] [--floor]

--floor adds a trivial asyncio responder (fixed answer, no Modbus) to the same alternation:
the ceiling of any asyncio server on the box at that moment, to tell a slow face from a busy
box.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import socket
import struct
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

TARGET_1 = 15_000
TARGET_8 = 30_000
REQUEST_REGS = 10
SLICE_S = 1.0


# -- servers (each in its own process) --------------------------------------------------


def serve_ours(ready, stop, switch_interval: float) -> None:
    import threading

    sys.setswitchinterval(switch_interval)
    from plc.image import ImageSize, ProcessImage, WriteQueue
    from plc.modbus import ModbusFace

    size = ImageSize()
    image = ProcessImage(size)
    queue = WriteQueue()
    state = {"snap": image.snapshot(0)}

    lateness: list[tuple[float, float]] = []

    def scan_loop() -> None:
        # Stand-in for the PLC runtime: drain writes, change some words, publish, every 10 ms;
        # its wake lateness shows what the face costs a scan thread in the same process.
        n = 0
        next_t = time.monotonic()
        while not stop.is_set():
            now = time.monotonic()
            lateness.append((now, now - next_t))
            for batch in queue.drain():
                for w in batch:
                    image.apply(w)
            n += 1
            image.qw[0] = n & 0x7FFF
            state["snap"] = image.snapshot(n)
            next_t += 0.010
            time.sleep(max(0.0, next_t - time.monotonic()))

    scan = threading.Thread(target=scan_loop, daemon=True)
    scan.start()
    face = ModbusFace(lambda: state["snap"], queue, size, port=0, idle_timeout=None)
    face.start_in_thread()
    ready.put(face.bound_port)
    stop.wait()
    face.stop_thread()
    scan.join()
    ready.put(lateness)


def serve_pymodbus(ready, stop, switch_interval: float) -> None:
    import asyncio
    import logging

    sys.setswitchinterval(switch_interval)
    from pymodbus.datastore import (
        ModbusDeviceContext,
        ModbusSequentialDataBlock,
        ModbusServerContext,
    )
    from pymodbus.server import ModbusTcpServer

    logging.disable(logging.WARNING)  # the legacy datastore logs deprecation warnings

    async def main() -> None:
        device = ModbusDeviceContext(
            co=ModbusSequentialDataBlock(1, [False] * 9216),
            di=ModbusSequentialDataBlock(1, [False] * 1024),
            ir=ModbusSequentialDataBlock(1, [0] * 1024),
            hr=ModbusSequentialDataBlock(1, [0] * 2048),
        )
        port = _free_port()
        server = ModbusTcpServer(ModbusServerContext(devices=device), address=("127.0.0.1", port))
        await server.serve_forever(background=True)
        ready.put(port)
        while not stop.is_set():
            await asyncio.sleep(0.05)
        await server.shutdown()

    asyncio.run(main())


def serve_floor(ready, stop, switch_interval: float) -> None:
    """Reference, not a Modbus server: an asyncio protocol that answers every segment with a
    fixed 29-byte FC03 response. The ceiling any asyncio server can reach on this box now."""
    import asyncio

    sys.setswitchinterval(switch_interval)
    answer = struct.pack(">HHHBBB", 1, 0, 23, 1, 3, 20) + bytes(20)

    class Echo(asyncio.Protocol):
        def connection_made(self, transport) -> None:
            self.transport = transport

        def data_received(self, data: bytes) -> None:
            self.transport.write(answer)

    async def main() -> None:
        server = await asyncio.get_running_loop().create_server(Echo, "127.0.0.1", 0)
        ready.put(server.sockets[0].getsockname()[1])
        while not stop.is_set():
            await asyncio.sleep(0.05)
        server.close()

    asyncio.run(main())


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# -- clients ----------------------------------------------------------------------------


def client_worker(ports: dict[str, int], connections: int, pipe) -> None:
    """Hold `connections` sockets to each server; on command, keep one FC03 outstanding on
    each socket to one server during a time window and report the answers counted."""
    socks = {name: [_connect(port) for _ in range(connections)] for name, port in ports.items()}
    req = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, REQUEST_REGS)
    size = 9 + 2 * REQUEST_REGS
    while (cmd := pipe.recv()) is not None:
        name, start_at, end_at = cmd
        group = socks[name]
        count = bad = 0
        lat: list[float] = []
        cpu0 = None
        while True:
            t0 = time.monotonic()
            for s in group:
                s.sendall(req)
            for s in group:
                data = s.recv(size)
                while len(data) < size:
                    chunk = s.recv(size - len(data))
                    if not chunk:
                        raise ConnectionError(f"{name} closed the connection")
                    data += chunk
                bad += data[7] != 3
            now = time.monotonic()
            if now >= start_at:
                if cpu0 is None:
                    cpu0 = time.process_time()
                if now > end_at:
                    break
                count += len(group)
                lat.append(now - t0)
        pipe.send((count, lat, bad, time.process_time() - (cpu0 or time.process_time())))
    for group in socks.values():
        for s in group:
            s.close()


def _connect(port: int) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (all its threads), from /proc."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(
    ports: dict[str, int], pids: dict[str, int], connections: int, procs: int, seconds: float
) -> dict:
    """Alternate short slices between the servers so both see the same background load."""
    procs = min(procs, connections)
    per = [connections // procs + (i < connections % procs) for i in range(procs)]
    pipes, workers = [], []
    for n in per:
        here, there = mp.Pipe()
        w = mp.Process(target=client_worker, args=(ports, n, there))
        w.start()
        pipes.append(here)
        workers.append(w)
    slices = max(1, round(seconds / SLICE_S))
    # count, latencies, bad, windows, server CPU s, client CPU s
    totals = {name: [0, [], 0, [], 0.0, 0.0] for name in ports}
    order = list(ports)
    for k in range(slices + 1):  # slice 0 is a warm-up for both, not counted
        for name in order if k % 2 else order[::-1]:
            start_at = time.monotonic() + 0.05
            end_at = start_at + (0.3 if k == 0 else seconds / slices)
            for p in pipes:
                p.send((name, start_at, end_at))
            time.sleep(max(0.0, start_at - time.monotonic()))
            cpu0 = _cpu_s(pids[name])
            results = [p.recv() for p in pipes]
            server_cpu = _cpu_s(pids[name]) - cpu0
            if k == 0:
                continue
            t = totals[name]
            t[4] += server_cpu
            t[5] += sum(r[3] for r in results)
            t[0] += sum(r[0] for r in results)
            for r in results:
                t[1].extend(r[1])
            t[2] += sum(r[2] for r in results)
            t[3].append((start_at, end_at))
    for p in pipes:
        p.send(None)
    for w in workers:
        w.join()
    out = {}
    for name, (count, lat, bad, windows, server_cpu, client_cpu) in totals.items():
        lat.sort()
        out[name] = {
            "windows": windows,
            "req_per_s": round(count / seconds),
            # CPU per answered request (/proc ticks of 10 ms, so +-10 ms per 1 s slice);
            # the server figure includes its scan thread, wall-clock independent of the box
            "server_cpu_us_per_req": round(server_cpu / count * 1e6, 1) if count else None,
            "client_cpu_us_per_req": round(client_cpu / count * 1e6, 1) if count else None,
            "round_p50_us": round(lat[len(lat) // 2] * 1e6, 1) if lat else None,
            "round_p99_us": round(lat[int(len(lat) * 0.99)] * 1e6, 1) if lat else None,
            "bad_answers": bad,
        }
    return out


def start_server(target, switch: float):
    ready, stop = mp.Queue(), mp.Event()
    server = mp.Process(target=target, args=(ready, stop, switch), daemon=True)
    server.start()
    return server, ready, stop, ready.get(timeout=20)  # (process, ..., port)


def stop_server(server, stop) -> None:
    stop.set()
    server.join(10)
    if server.is_alive():
        server.kill()


def _lateness_stats(xs: list[float]) -> dict:
    if not xs:
        return {}
    xs = sorted(xs)
    return {
        "scans": len(xs),
        "p50_ms": round(xs[len(xs) // 2] * 1e3, 3),
        "p99_ms": round(xs[min(len(xs) - 1, int(len(xs) * 0.99))] * 1e3, 3),
        "max_ms": round(xs[-1] * 1e3, 3),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0, help="per measurement and server")
    ap.add_argument("--client-procs", type=int, default=2, help="client processes for 8 conns")
    ap.add_argument(
        "--switch-interval",
        type=float,
        default=0.0005,
        help="sys.setswitchinterval in both server processes (the anchor's scan-thread advice)",
    )
    ap.add_argument(
        "--floor",
        action="store_true",
        help="also measure a trivial asyncio responder (the box's asyncio ceiling right now)",
    )
    args = ap.parse_args()
    load_before = os.getloadavg()[0]
    ours_srv, ours_ready, ours_stop, ours_port = start_server(serve_ours, args.switch_interval)
    peer_srv, _, peer_stop, peer_port = start_server(serve_pymodbus, args.switch_interval)
    ports = {"ours": ours_port, "pymodbus": peer_port}
    pids = {"ours": ours_srv.pid, "pymodbus": peer_srv.pid}
    extra = []
    if args.floor:
        floor_srv, _, floor_stop, ports["asyncio_floor"] = start_server(
            serve_floor, args.switch_interval
        )
        extra.append((floor_srv, floor_stop))
        pids["asyncio_floor"] = floor_srv.pid
    try:
        one = measure(ports, pids, 1, 1, args.seconds)
        eight = measure(ports, pids, 8, args.client_procs, args.seconds)
    finally:
        ours_stop.set()
        lateness = ours_ready.get(timeout=20)
        stop_server(ours_srv, ours_stop)
        stop_server(peer_srv, peer_stop)
        for srv, stop in extra:
            stop_server(srv, stop)
    for run in (one, eight):
        windows = run["ours"]["windows"]
        run["ours"]["scan_lateness"] = _lateness_stats(
            [x for t, x in lateness if any(a <= t <= b for a, b in windows)]
        )
        for r in run.values():
            del r["windows"]
    o1, o8 = one["ours"]["req_per_s"], eight["ours"]["req_per_s"]
    p1, p8 = one["pymodbus"]["req_per_s"], eight["pymodbus"]["req_per_s"]
    floor = (
        {
            "asyncio_floor_1conn_req_s": one["asyncio_floor"]["req_per_s"],
            "asyncio_floor_8conn_req_s": eight["asyncio_floor"]["req_per_s"],
            "asyncio_floor_detail": {
                "1conn": one["asyncio_floor"],
                "8conn": eight["asyncio_floor"],
            },
        }
        if args.floor
        else {}
    )
    print(
        json.dumps(
            {
                "workload": f"FC03 x {REQUEST_REGS} registers, 1 outstanding per connection",
                "seconds_per_measurement": args.seconds,
                "client_processes_for_8": args.client_procs,
                "server_switch_interval_s": args.switch_interval,
                "cpus": os.cpu_count(),
                "loadavg_1min_before_after": [round(load_before, 2), round(os.getloadavg()[0], 2)],
                "ours_1conn_req_s": o1,
                "ours_8conn_req_s": o8,
                "pymodbus_1conn_req_s": p1,
                "pymodbus_8conn_req_s": p8,
                "server_cpu_us_per_req_1conn": {
                    name: r["server_cpu_us_per_req"] for name, r in one.items()
                },
                "server_cpu_us_per_req_8conn": {
                    name: r["server_cpu_us_per_req"] for name, r in eight.items()
                },
                "ratio_1conn": round(o1 / p1, 2) if p1 else None,
                "ratio_8conn": round(o8 / p8, 2) if p8 else None,
                "target_1conn_req_s": TARGET_1,
                "target_8conn_req_s": TARGET_8,
                "meets_target_1conn": o1 >= TARGET_1,
                "meets_target_8conn": o8 >= TARGET_8,
                **floor,
                "ours_detail": {"1conn": one["ours"], "8conn": eight["ours"]},
                "pymodbus_detail": {"1conn": one["pymodbus"], "8conn": eight["pymodbus"]},
                "peer": "pymodbus 3.16.1 ModbusTcpServer + ModbusDeviceContext "
                "(ModbusSequentialDataBlock)",
                "method": f"both servers up at once; {SLICE_S} s slices alternate between them "
                "so both see the same background load",
                "note": "ours includes a 10 ms fake scan thread in the server process whose "
                "wake lateness (during our slices) is reported; round = one request on each of "
                "a client process's connections; loopback; figures depend on other load on "
                "the box",
            }
        )
    )


if __name__ == "__main__":
    main()
