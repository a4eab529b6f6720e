"""Frame handling cost per PDO: the fmscell CiA 301 slave against plain `canopen.LocalNode`.

One "PDO exchange" = receive RPDO1 (controlword + target position) and hand both values to
the application, then on SYNC sample statusword + position actual from the application and
send TPDO1. Both paths run in this process on a sink bus (sending costs only the
`can.Message` construction), with the same trivial application, so the figure is the
protocol layer's own cost. The LocalNode path is what its maintainers advise (#555): a PDO
callback that writes the values on, and a SYNC subscription that fills the TPDO and calls
`transmit()`. Also reported: lockstep hub cost per frame with 6 receivers, and 1 s of a
6-axis 1 ms SYNC cycle through hub + slaves (301 layer only, trivial application).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import time
from pathlib import Path

import can
import canopen

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from drives import EDS_PATH  # noqa: E402
from drives.bus import CanHub  # noqa: E402
from drives.cia301 import CanopenSlave  # noqa: E402

N = 20_000
REPEATS = 5


class SinkBus(can.BusABC):
    """Accepts frames and drops them."""

    def __init__(self) -> None:
        self.sent = 0
        super().__init__(channel="sink")

    def send(self, msg, timeout=None):
        self.sent += 1

    def _recv_internal(self, timeout):
        return None, False


class Drive:
    """The same trivial application for both paths."""

    def __init__(self) -> None:
        self.values = {0x6041: 0x0237, 0x6064: 1000, 0x6040: 0, 0x607A: 0}

    def owns(self, index):
        return 0x6000 <= index <= 0x67FF

    def read_object(self, index, subindex):
        return self.values.get(index, 0)

    def write_object(self, index, subindex, value):
        self.values[index] = value

    def on_sync(self):
        self.values[0x6064] += 1

    def advance(self, dt_s):
        pass

    def on_nmt_state(self, state):
        pass

    def on_communication_fault(self, error_code):
        pass

    def take_emcy(self):
        return []


RPDO = can.Message(arbitration_id=0x205, data=b"\x0f\x00\xe8\x03\x00\x00", is_extended_id=False)
SYNC = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)


def ours() -> tuple[float, float, int]:
    bus = SinkBus()
    slave = CanopenSlave(5, bus, Drive())
    slave.handle(can.Message(arbitration_id=0, data=b"\x01\x05", is_extended_id=False))
    # TPDO1 synchronous (type 1) so SYNC triggers exactly one TPDO; RPDO1 stays type 255.
    slave.od.write(0x1800, 1, (0x80000185).to_bytes(4, "little"))
    slave.od.write(0x1800, 2, b"\x01")
    slave.od.write(0x1800, 1, (0x185).to_bytes(4, "little"))
    slave.od.write(0x1801, 1, (0x80000285).to_bytes(4, "little"))
    handle = slave.handle
    before = bus.sent
    start = time.perf_counter_ns()
    for _ in range(N):
        handle(RPDO)
    mid = time.perf_counter_ns()
    for _ in range(N):
        handle(SYNC)
    end = time.perf_counter_ns()
    bus.shutdown()
    return (mid - start) / N / 1e3, (end - mid) / N / 1e3, bus.sent - before


def local_node() -> tuple[float, float, int]:
    bus = SinkBus()
    network = canopen.Network(bus)
    node = canopen.LocalNode(5, EDS_PATH)
    network.add_node(node)
    app = Drive()
    node.rpdo.read(from_od=True)
    node.tpdo.read(from_od=True)
    rpdo, tpdo = node.rpdo[1], node.tpdo[1]
    cw, target = rpdo["Controlword"], rpdo["Target position"]
    sw, pos = tpdo["Statusword"], tpdo["Position actual value"]

    def on_rpdo(pdo_map):
        app.write_object(0x6040, 0, cw.raw)
        app.write_object(0x607A, 0, target.raw)

    def on_sync(can_id, data, timestamp):
        app.on_sync()
        sw.raw = app.read_object(0x6041, 0)
        pos.raw = app.read_object(0x6064, 0)
        tpdo.transmit()

    rpdo.add_callback(on_rpdo)
    network.subscribe(0x080, on_sync)
    notify = network.notify
    rpdo_data, sync_data = bytearray(RPDO.data), bytearray()
    start = time.perf_counter_ns()
    for _ in range(N):
        notify(0x205, rpdo_data, 0.0)
    mid = time.perf_counter_ns()
    for _ in range(N):
        notify(0x080, sync_data, 0.0)
    end = time.perf_counter_ns()
    bus.shutdown()
    return (mid - start) / N / 1e3, (end - mid) / N / 1e3, bus.sent


def hub_per_frame(receivers: int = 6) -> float:
    hub = CanHub()
    sender = hub.endpoint("tx")
    for i in range(receivers):
        hub.endpoint(f"rx{i}").add_listener(lambda msg: None)
    msg = can.Message(arbitration_id=0x181, data=b"\x37\x02\xe8\x03\x00\x00", is_extended_id=False)
    start = time.perf_counter_ns()
    for _ in range(N):
        sender.send(msg)
    elapsed = time.perf_counter_ns() - start
    hub.close()
    return elapsed / N / 1e3


def lockstep_six_axes(seconds: float = 1.0) -> dict:
    hub = CanHub()
    master = hub.endpoint("master")
    slaves = [CanopenSlave(n, hub.endpoint(f"n{n}"), Drive()) for n in range(1, 7)]
    for slave in slaves:
        slave.od.write(0x1800, 1, (0x80000180 + slave.node_id).to_bytes(4, "little"))
        slave.od.write(0x1800, 2, b"\x01")
        slave.od.write(0x1800, 1, (0x180 + slave.node_id).to_bytes(4, "little"))
        slave.od.write(0x1801, 1, (0x80000280 + slave.node_id).to_bytes(4, "little"))
    master.send(can.Message(arbitration_id=0, data=b"\x01\x00", is_extended_id=False))
    rpdos = [
        can.Message(arbitration_id=0x200 + n, data=RPDO.data, is_extended_id=False)
        for n in range(1, 7)
    ]
    cycles = round(seconds / 0.001)
    start, cpu_start = time.perf_counter(), time.process_time()
    for _ in range(cycles):
        for msg in rpdos:
            master.send(msg)
        master.send(SYNC)
        hub.advance(0.001)
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    summary = hub.load.summary()
    hub.close()
    return {
        "machine_time_s": seconds,
        "wall_s": round(wall, 4),
        "cpu_s": round(cpu, 4),
        "realtime_factor": round(seconds / wall, 2),
        "frames": summary["total_frames"],
        "bus_load_mean": round(summary["mean_load"], 4),
        "bus_load_peak": round(summary["peak_load"], 4),
    }


def best(fn) -> tuple[float, float, int]:
    runs = [fn() for _ in range(REPEATS)]
    return (
        statistics.median(r[0] for r in runs),
        statistics.median(r[1] for r in runs),
        runs[-1][2],
    )


def main() -> None:
    our_rx, our_tx, our_sent = best(ours)
    ln_rx, ln_tx, ln_sent = best(local_node)
    assert our_sent == N and ln_sent == N, (our_sent, ln_sent)
    ours_total, ln_total = our_rx + our_tx, ln_rx + ln_tx
    result = {
        "bench": "can_frames",
        "iterations": N,
        "ours_us_per_pdo_exchange": round(ours_total, 2),
        "ours_rpdo_us": round(our_rx, 2),
        "ours_sync_tpdo_us": round(our_tx, 2),
        "peer": "canopen.LocalNode 2.4.1 + callbacks (RPDO callback, SYNC -> tpdo.transmit)",
        "peer_us_per_pdo_exchange": round(ln_total, 2),
        "peer_rpdo_us": round(ln_rx, 2),
        "peer_sync_tpdo_us": round(ln_tx, 2),
        "ratio_ours_over_peer": round(ours_total / ln_total, 3),
        "target": "ours <= peer per PDO exchange (ratio <= 1.0)",
        "hub_us_per_frame_6_receivers": round(hub_per_frame(), 2),
        "lockstep_6_axes_1ms_301_only": lockstep_six_axes(),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "note": "6 axes x 2 PDOs at 1 ms exceed 1 Mbit/s (the plan refuses it): wire backlog",
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
