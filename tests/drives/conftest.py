"""Shared fixtures for the drives tests: a trivial profile application and a lockstep cell."""

from __future__ import annotations

import io

import pytest

from drives.application import (
    ABORT_NOT_EXIST,
    ABORT_READ_ONLY,
    ABORT_VALUE_RANGE,
    EmcyRequest,
    ObjectAccessError,
)
from drives.bus import CanHub, candump_frame


class FakeDrive:
    """A DriveApplication that only stores values, records calls and can raise EMCYs.

    Owns the CiA 402 range; controlword writes above 0x00FF are refused with 0x06090030 and
    writes to the statusword with 0x06010002 (stand-ins for what a real profile refuses).
    """

    def __init__(self) -> None:
        self.values: dict[tuple[int, int], int | float | bytes] = {
            (0x6041, 0): 0x0250,
            (0x6064, 0): 1000,
            (0x6061, 0): 0,
        }
        self.calls: list[tuple] = []
        self.emcy: list[EmcyRequest] = []
        self.sync_count = 0
        self.time_s = 0.0

    def owns(self, index: int) -> bool:
        return 0x6000 <= index <= 0x67FF

    def read_object(self, index: int, subindex: int):
        if index == 0x6502:
            return 0x1A5
        if index == 0x6000:
            raise ObjectAccessError(ABORT_NOT_EXIST)
        return self.values.get((index, subindex), 0)

    def write_object(self, index: int, subindex: int, value) -> None:
        if index == 0x6041:
            raise ObjectAccessError(ABORT_READ_ONLY)
        if index == 0x6040 and value > 0xFF:
            raise ObjectAccessError(ABORT_VALUE_RANGE)
        self.calls.append(("write", index, subindex, value))
        self.values[(index, subindex)] = value

    def on_sync(self) -> None:
        self.sync_count += 1
        self.calls.append(("sync",))

    def advance(self, dt_s: float) -> None:
        self.time_s += dt_s

    def on_nmt_state(self, state: str) -> None:
        self.calls.append(("nmt", state))

    def on_communication_fault(self, error_code: int) -> None:
        self.calls.append(("fault", error_code))

    def take_emcy(self) -> list[EmcyRequest]:
        out, self.emcy = self.emcy, []
        return out


class Cell:
    """A lockstep hub with a trace, a master endpoint and helpers to talk raw frames."""

    def __init__(self) -> None:
        self.trace = io.StringIO()
        self.hub = CanHub(log=self.trace)
        self.master = self.hub.endpoint("master")
        self.frames: list = []
        self.master.add_listener(self.frames.append)

    def send(self, text: str) -> list[str]:
        """Send a frame in candump notation (`605#4000100000000000`, `705#R`); return replies."""
        import can

        ident, _, payload = text.partition("#")
        remote = payload == "R"
        start = len(self.frames)
        self.master.send(
            can.Message(
                arbitration_id=int(ident, 16),
                is_extended_id=len(ident) > 3,
                is_remote_frame=remote,
                data=b"" if remote else bytes.fromhex(payload),
                dlc=1 if remote else None,
            )
        )
        return [candump_frame(m) for m in self.frames[start:]]

    def advance(self, dt: float) -> list[str]:
        start = len(self.frames)
        self.hub.advance(dt)
        return [candump_frame(m) for m in self.frames[start:]]

    def seen(self) -> list[str]:
        return [candump_frame(m) for m in self.frames]


@pytest.fixture
def app():
    return FakeDrive()


@pytest.fixture
def cell():
    c = Cell()
    yield c
    c.hub.close()


@pytest.fixture
def slave(cell, app):
    from drives.cia301 import CanopenSlave

    return CanopenSlave(5, cell.hub.endpoint("node5"), app)
