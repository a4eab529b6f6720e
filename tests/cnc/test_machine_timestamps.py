"""Where a machine's SHDR timestamps come from (issue 14, item 8: they were 1.8e9 + machine
time, a 2027 date that fell further behind whenever the machine ran slow).

Lockstep: the declared epoch (LOCKSTEP_EPOCH, 2000-01-01T00:00:00Z) + machine time,
deterministic. Under a realtime runner (real time or the fast clock): the wall clock (UTC)
at publish, whatever the machine's pace.
"""

from __future__ import annotations

import datetime as dt
import socket
import time

import pytest

from cnc.config import load_machine_config
from cnc.faces.shdr import shdr_timestamp
from cnc.machine import Machine, RealtimeRunner
from cnc.machine.machine import LOCKSTEP_EPOCH


class Recorder:
    """Stands in for the SHDR adapter: keeps what the machine publishes."""

    def __init__(self) -> None:
        self.stamps: list[float] = []

    def publish(self, status, timestamp) -> list[str]:
        self.stamps.append(timestamp)
        return []


def machine(**kw) -> Machine:
    ports = {"dnc": None, "modbus": None, "shdr": None, "simulation": None}
    return Machine(load_machine_config({"base": "mill3", "ports": ports}), "m1", ideal=True, **kw)


def parse(stamp: str) -> float:
    return dt.datetime.fromisoformat(stamp.removesuffix("Z")).replace(tzinfo=dt.UTC).timestamp()


def test_declared_lockstep_epoch_is_2000_01_01_utc():
    assert shdr_timestamp(LOCKSTEP_EPOCH) == "2000-01-01T00:00:00.000000Z"


@pytest.mark.parametrize("epoch", [None, 1_700_000_000.0])
def test_lockstep_timestamps_are_epoch_plus_machine_time(epoch):
    m = machine(epoch=epoch)
    try:
        rec = m.shdr = Recorder()
        m.step(50)
        base = LOCKSTEP_EPOCH if epoch is None else epoch
        assert rec.stamps, "the machine published"
        assert rec.stamps[-1] == base + m.t
        assert m.timestamp() == base + m.t
        # machine time only: a second run gives the same stamps
        m2 = machine(epoch=epoch)
        try:
            rec2 = m2.shdr = Recorder()
            m2.step(50)
            assert rec2.stamps == rec.stamps
        finally:
            m2.close()
    finally:
        m.close()


def test_realtime_timestamps_follow_the_wall_clock_not_machine_time():
    """A machine that runs slow (here: 0.1 s of machine time while the wall clock moves on
    by hours) still stamps what it reports with the wall clock."""
    wall = [1_795_000_000.0]  # 2026-11-18
    m = machine()
    try:
        RealtimeRunner(m, rt_priority=0, wall_clock=lambda: wall[0])
        rec = m.shdr = Recorder()
        m.step(10)
        assert rec.stamps[-1] == 1_795_000_000.0
        wall[0] += 3600.0
        m.step(40)
        assert rec.stamps[-1] == 1_795_003_600.0
        assert m.t == pytest.approx(0.1)
    finally:
        m.close()


def test_realtime_shdr_stream_carries_utc_wall_clock_over_a_real_socket():
    """The real SHDR face of a machine owned by a realtime runner with the default clock:
    each line's timestamp lies between the wall clock before and after the publish."""
    ports = {"dnc": None, "modbus": None, "shdr": 0, "simulation": None}
    m = Machine(load_machine_config({"base": "mill3", "ports": ports}), "m1", ideal=True)
    try:
        faces = m.start_faces()
        RealtimeRunner(m, rt_priority=0)
        with socket.create_connection(("127.0.0.1", faces.ports()["shdr"]), timeout=5) as s:
            s.settimeout(5)
            before = time.time()
            got = b""
            deadline = time.monotonic() + 30.0
            while b"|avail|" not in got:
                assert time.monotonic() < deadline, got
                m.step(5)  # publishes every scan; the face sends on its own thread
                try:
                    got += s.recv(65536)
                except TimeoutError:
                    continue
            after = time.time()
        line = next(x for x in got.decode().splitlines() if "|avail|" in x)
        stamp = parse(line.split("|")[0])
        # microsecond text: allow 1 us of rounding on each side
        assert before - 1e-6 <= stamp <= after + 1e-6, (before, line, after)
    finally:
        m.close()
