"""A machine's DNC-facing parts (program memory, drip buffers, alarms) behind a real DncPort."""

from __future__ import annotations

import socket

from cnc.faces.dnc_port import DncPort
from cnc.faces.drip import DripBuffer
from cnc.faces.loop_thread import LoopThread
from cnc.program_memory import ProgramMemory
from dnc.transfer import DncClient


class Machine:
    """The parts of a machine the DNC port touches, with its alarms collected."""

    def __init__(self, *, capacity=4096, parity=False, drip_capacity=1024, policy=None):
        self.memory = ProgramMemory(capacity)
        self.alarms: list[tuple[int, str]] = []
        self.warnings: list[tuple[int, str]] = []
        self.drip_buffers: list[DripBuffer] = []
        self.loop = LoopThread("dnc-test").start()

        def new_drip():
            buf = DripBuffer(drip_capacity)
            self.drip_buffers.append(buf)
            return buf

        self.port = DncPort(
            self.memory,
            parity=parity,
            drip=new_drip,
            on_alarm=lambda n, t: self.alarms.append((n, t)),
            on_warning=lambda n, t: self.warnings.append((n, t)),
            policy=policy,
            idle_timeout_s=5,
        )
        self.loop.run(self.port.start)

    def client(self, **kw) -> DncClient:
        return DncClient(
            "127.0.0.1", self.port.bound_port, parity=self.port.parity, timeout_s=5, **kw
        )

    def raw(self) -> socket.socket:
        s = socket.create_connection(("127.0.0.1", self.port.bound_port), timeout=5)
        return s

    def close(self):
        self.loop.run(self.port.stop)
        self.loop.stop()
