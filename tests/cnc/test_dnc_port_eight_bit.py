"""8-bit bytes on a DNC port without parity (issue 14, item 9): they had been stored as U+FFFD
with an OK and a hash, and PUNCH of that program then dropped the connection without ERR.

Real sockets, a raw client (as socat or a serial bridge would send) and the pure decoder.
"""

from __future__ import annotations

import asyncio
import socket

import pytest

from cnc.faces.dnc_port import ALARM_EIGHT_BIT, DncPort
from cnc.faces.tape import TapeDecoder
from cnc.program_memory import ProgramMemory

TAPE = "%\nO0100\nG0 X1 (ok)\nG1 X2 F100\nM30\n%\n"


@pytest.mark.parametrize(
    ("data", "offset", "line", "byte"),
    [
        (b"%\nO0100\nG0 X1 (caf\xc3\xa9)\nM30\n%\n", 18, 3, 0xC3),
        (b"\xff%\nO1\n%\n", 0, 1, 0xFF),  # in the leader
        (b"%\n\x80", 2, 2, 0x80),
        (b"%\nO1\nG1 X1" + b"A" * 5000 + b"\xe9\n%\n", 5010, 3, 0xE9),  # beyond a block limit
    ],
)
def test_decoder_stops_at_the_first_eight_bit_byte(data, offset, line, byte):
    for chunk in (len(data), 1, 3):  # whole, byte by byte, odd chunks
        d = TapeDecoder(max_block=8192)
        events = []
        for i in range(0, len(data), chunk):
            events += d.feed(data[i : i + chunk])
        bad = [e for e in events if e.kind == "eight_bit"]
        assert [(e.offset, e.line, e.code) for e in bad] == [(offset, line, byte)], chunk
        assert d.failed and not any(e.kind == "end" for e in events)


def test_decoder_ignores_eight_bit_trailer_after_the_closing_percent():
    d = TapeDecoder()
    events = d.feed(b"%\nO1\nM30\n%\n\xff\xfe garbage")
    assert [e.kind for e in events][-1] == "end" and d.ended


def test_decoder_with_parity_is_unchanged_by_the_check():
    from cnc.faces.tape import add_parity

    d = TapeDecoder(parity=True)
    events = d.feed(add_parity(TAPE.encode()))
    assert events[-1].kind == "end"


class Port:
    def __init__(self, memory: ProgramMemory) -> None:
        self.loop = asyncio.new_event_loop()
        self.port = DncPort(memory, idle_timeout_s=30)
        self.alarms: list[tuple[int, str]] = []
        self.port._on_alarm = lambda n, t: self.alarms.append((n, t))
        import threading

        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        asyncio.run_coroutine_threadsafe(self.port.start(), self.loop).result(10)

    def talk(self, data: bytes) -> bytes:
        with socket.create_connection(("127.0.0.1", self.port.bound_port), timeout=10) as s:
            s.sendall(data)
            out = b""
            while True:
                chunk = s.recv(4096)
                if not chunk:
                    return out
                out += chunk

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self.port.stop(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


@pytest.fixture
def port():
    memory = ProgramMemory(64 * 1024)
    p = Port(memory)
    yield p, memory
    p.close()


def test_eight_bit_program_is_refused_with_err_and_nothing_stored(port):
    p, memory = port
    answer = p.talk(b"READ\n%\nO0100\nG0 X1 (caf\xc3\xa9)\nM30\n%\n")
    assert answer.startswith(f"ERR {ALARM_EIGHT_BIT} 8-bit byte 0xC3 at byte 18 (line 3)".encode())
    assert b"OK" not in answer
    assert memory.directory() == []
    assert p.alarms == []  # the sender is told; the machine is not disturbed


def test_plain_tape_without_command_is_refused_the_same_way(port):
    p, memory = port
    answer = p.talk(b"%\nO0101\nG1 X\xb11\n%\n")
    assert answer.startswith(f"ERR {ALARM_EIGHT_BIT} 8-bit byte 0xB1".encode())
    assert 101 not in memory


def test_seven_bit_program_still_stored(port):
    p, memory = port
    answer = p.talk(b"READ\n" + TAPE.encode() + b"QUIT\n")
    assert answer.startswith(b"OK O0100 ")
    assert memory.get(100) == TAPE


def test_punch_of_a_non_ascii_program_in_memory_answers_err(port):
    """A program that reached memory by another way (a local load) with a character the
    tape cannot carry: PUNCH says so instead of dropping the connection."""
    p, memory = port
    memory.store(102, "%\nO0102\n(caf\u00e9)\nM30\n%\n")
    answer = p.talk(b"PUNCH O0102\n")
    assert answer.startswith(f"ERR {ALARM_EIGHT_BIT} program O0102 holds".encode())
    assert b"line 3" in answer
