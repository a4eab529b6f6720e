"""The Python contract: an unchanged stock `canopen.BaseNode402` master drives a VirtualDrive
served in realtime on python-can's `virtual` interface.

Realtime on purpose: BaseNode402 waits on the wall clock (0.2-0.8 s per step). Every wait
here is the stock library's own, bounded by its timeouts; the event timer 0x1800:05 makes the
statusword TPDO periodic (50 ms) as canopen 2.4.1 expects once it has seen two of them.
(`homing()` reads the status right after one TPDO wait: a timer TPDO already in flight
when the start bit goes out would show the old status; a longer timer makes that rare.)
"""

from __future__ import annotations

import time

import can
import canopen
import pytest

from drives import EDS_PATH, VirtualDrive
from drives.plant import PlantParams

CHANNEL = "fmscell-stock-master"
NODE = 2


@pytest.fixture
def stock():
    drive_bus = can.Bus(interface="virtual", channel=CHANNEL)
    vd = VirtualDrive(
        NODE,
        drive_bus,
        switches={"initial_position": 0.016},  # 6 mm above the dog's edge
        objects={(0x6099, 1): 40_000, (0x6099, 2): 4_000, 0x609A: 1_000_000},
    ).start()
    network = canopen.Network()
    node = canopen.BaseNode402(NODE, EDS_PATH)
    network.add_node(node)
    network.connect(interface="virtual", channel=CHANNEL)
    yield network, node, vd
    network.disconnect()
    vd.stop()
    drive_bus.shutdown()


def _boot_and_enable(network, node):
    node.nmt.send_command(0x81)  # reset node
    node.nmt.wait_for_bootup(timeout=2.0)
    node.sdo[0x1017].raw = 50
    # The default RPDOs carry one object each, so op_mode goes out in RPDO2 on its own and
    # a controlword change never carries a stale target. TPDOs every 50 ms (event timer).
    node.pdo.read()
    for n in (1, 2):
        node.tpdo[n].event_timer = 50
    node.tpdo.save()
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    assert node.nmt.wait_for_heartbeat(timeout=1.0) == "OPERATIONAL"
    node.tpdo[1].wait_for_reception(timeout=1.0)
    node.state = "SWITCH ON DISABLED"
    node.state = "OPERATION ENABLED"
    assert node.state == "OPERATION ENABLED"


def test_stock_master_boots_enables_homes_moves_and_follows(stock):
    network, node, vd = stock
    _boot_and_enable(network, node)
    assert vd.state_name == "OPERATION ENABLED"

    # homing with dog and creep: method 21 (negative home switch, final approach positive)
    node.sdo[0x6098].raw = 21
    node.sdo[0x607C].raw = 0
    assert node.homing(timeout=10.0) is True
    assert vd.drive.homed
    assert vd.table_position_m - vd.position_actual * 1e-6 == pytest.approx(0.010, abs=5e-6)

    # modes: switch and read back through the stock op_mode property
    node.op_mode = "PROFILED VELOCITY"
    assert node.op_mode == "PROFILED VELOCITY"
    assert vd.drive.mode_display == 3
    assert vd.state_name == "OPERATION ENABLED"  # the mode change did not disturb the state

    # profile position: a relative-free absolute move of 5 mm
    node.op_mode = "PROFILED POSITION"
    assert node.op_mode == "PROFILED POSITION"
    node.sdo[0x6081].raw = 50_000  # 50 mm/s
    node.rpdo_pointers[0x607A].raw = 5_000  # RPDO3 carries the target position alone
    node.rpdo_pointers[0x607A].pdo_parent.transmit()
    node.controlword = 0x0F
    node.controlword = 0x1F  # new set-point
    deadline = time.monotonic() + 3.0
    while not node.statusword & 0x1000:  # set-point acknowledge
        assert time.monotonic() < deadline, f"no set-point acknowledge: 0x{node.statusword:04X}"
        node.check_statusword(timeout=0.5)
    node.controlword = 0x0F  # release the set-point bit: handshake done
    tpdo = node.tpdo[1]
    while not (node.statusword & 0x0400 and abs(tpdo["Position actual value"].raw - 5_000) < 10):
        assert time.monotonic() < deadline, f"PP move not done: 0x{node.statusword:04X}"
        node.check_statusword(timeout=0.5)
    assert node.state == "OPERATION ENABLED"

    # cyclic synchronous position: SYNC + RPDO targets from the master, TPDO positions back
    node.op_mode = "CYCLIC SYNCHRONOUS POSITION"
    assert node.op_mode == "CYCLIC SYNCHRONOUS POSITION"
    node.sdo[0x60C2][1].raw = 5  # 5 ms interpolation period
    node.rpdo[3].trans_type = 1  # target position applied at each SYNC
    node.rpdo.save()
    node.tpdo[1].trans_type = 1
    node.tpdo[1].event_timer = 0
    node.tpdo.save()
    seen = []
    node.tpdo[1].add_callback(lambda m: seen.append(m["Position actual value"].raw))
    rpdo = node.rpdo[3]
    start, step_um, period = 5_000, 50, 0.005
    sent_at = []
    next_t = time.perf_counter()
    for k in range(1, 201):  # 1 s at 5 ms: 10 mm/s ramp from 5 mm
        rpdo["Target position"].raw = start + step_um * k
        rpdo.transmit()
        network.sync.transmit()
        sent_at.append(time.perf_counter())
        # The master's cycle pacing, as a real SYNC producer: a late cycle is late, the next
        # one follows a period after it. Catching up would send a burst of SYNCs, each a
        # 50 um target step in no time, which no drive follows with its Kv lag.
        next_t = max(next_t + period, time.perf_counter())
        time.sleep(max(0.0, next_t - time.perf_counter()))
    # one TPDO answers each SYNC: wait for the answer to the last one (a loaded host may
    # still have several in flight), to a deadline with a wide margin
    deadline = time.monotonic() + 10.0
    while len(seen) < 200:
        assert time.monotonic() < deadline, f"{len(seen)} of 200 SYNCs answered"
        node.tpdo[1].wait_for_reception(timeout=0.5)
    assert seen[-1] > seen[len(seen) // 2] > start  # it follows the ramp
    # Kv lag: the following error is the speed over the last loop time constants / Kv.
    # 10 mm/s / 16.67 1/s = 0.6 mm when the master keeps its 5 ms cycle; a master slowed by
    # the host's load moved the target slower, and the drive lags less, by the same law.
    kv = PlantParams().loops.kv  # 1/s, the drive's default position loop gain
    recent = sent_at[-25:]  # 120 ms at 5 ms, two time constants of the position loop
    speed = step_um * (len(recent) - 1) / (recent[-1] - recent[0])  # um/s
    assert start + step_um * 200 - seen[-1] == pytest.approx(speed / kv, rel=0.25, abs=50)
    assert node.state == "OPERATION ENABLED"
