"""The machine's DNC port over real sockets, driven by the host's DncClient and raw sockets."""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time

import pytest

from cnc.faces.tape import XOFF, add_parity, encode_program
from dnc.transfer import DncClient, TransferError, canonical_text, iter_blocks, sha256_text

from .dnc_helpers import Machine

PROG = "%\nO1234 (PLATE)\nG21 G90\nG0 X10 Y10\nG1 X50 F300\nM30\n%\n"


@pytest.fixture
def machine():
    m = Machine()
    yield m
    m.close()


@pytest.fixture
def parity_machine():
    m = Machine(parity=True)
    yield m
    m.close()


def read_all(sock: socket.socket) -> bytes:
    out = b""
    while True:
        try:
            data = sock.recv(4096)
        except TimeoutError:
            return out
        if not data:
            return out
        out += data


def test_send_stores_the_program_and_verifies_by_sha(machine):
    with machine.client() as c:
        result = c.send_program(PROG)
    assert result.number == 1234
    assert result.sha256 == sha256_text(canonical_text(PROG))
    assert machine.memory.get(1234) == canonical_text(PROG)


def test_punch_round_trip_and_directory(machine):
    with machine.client() as c:
        sent = c.send_program(PROG)
        punched = c.punch(1234)
        listing = c.directory()
    assert sha256_text(punched) == sent.sha256
    assert listing == [(1234, sent.size, sent.sha256)]


def test_parity_tape_round_trip(parity_machine):
    with parity_machine.client() as c:
        sent = c.send_program(PROG)
        assert sha256_text(c.punch(1234)) == sent.sha256


def test_parity_error_rejects_the_program_and_raises_an_alarm(parity_machine):
    tape = bytearray(add_parity(b"READ\n") + encode_program(PROG, parity=True))
    tape[12] ^= 0x01  # one bit flipped on the line
    with parity_machine.raw() as s:
        s.sendall(bytes(tape))
        answer = read_all(s)
    assert b"ERR 2001 parity error at byte" in bytes(b & 0x7F for b in answer)
    assert 1234 not in parity_machine.memory
    assert parity_machine.alarms[0][0] == 2001


def test_transfer_cut_off_stores_nothing_and_raises_no_alarm(machine):
    with machine.raw() as s:
        s.sendall(b"READ\n" + encode_program(PROG)[:30])
        s.shutdown(socket.SHUT_WR)
        answer = read_all(s)
    assert b"ERR 2004 transfer cut off before the closing %" in answer
    assert machine.memory.directory() == []
    text = answer.decode().split(" ", 2)[2].strip()
    assert text.endswith("; program discarded, memory unchanged")
    # a message for the operator, not an alarm that takes the machine out of the cell
    assert machine.alarms == [] and machine.warnings == [(2004, text)]


NEW = PROG.replace("(PLATE)", "(PLATE REV B)").replace("X50", "X60")


@pytest.mark.parametrize(
    "cut",
    [
        pytest.param(lambda tape: b"READ\n", id="READ then hang up before the tape"),
        pytest.param(lambda tape: b"READ\n" + tape[:25], id="hang up mid-tape"),
        pytest.param(lambda tape: b"READ O1234\n" + tape[:-2], id="hang up before the closing %"),
        pytest.param(lambda tape: tape[:-2], id="plain tape without its closing %"),
    ],
)
def test_a_cut_off_load_keeps_the_program_in_memory_and_the_port_usable(machine, cut):
    with machine.client() as c:
        old = c.send_program(PROG)
    with machine.raw() as s:  # a client (or a host killed mid-transfer) that goes away
        s.sendall(cut(encode_program(NEW)))
        s.close()
    deadline = time.monotonic() + 5.0
    while not machine.warnings and time.monotonic() < deadline:
        time.sleep(0.01)  # the port notices the hang-up on its own thread
    assert [n for n, _ in machine.warnings] == [2004] and machine.alarms == []
    assert machine.memory.get(1234) == canonical_text(PROG)
    with machine.client() as c:  # the port and the machine carry on
        assert sha256_text(c.punch(1234)) == old.sha256
        new = c.send_program(NEW)
    assert new.sha256 == sha256_text(canonical_text(NEW))


@pytest.mark.parametrize("reset", [False, True], ids=["FIN", "RST"])
def test_a_host_killed_mid_transfer_leaves_memory_as_it_was(machine, reset):
    """The host's connection ends half way through a load: closed by the kernel of a killed
    host (FIN), or reset (RST, as from a host whose machine went down)."""
    with machine.client() as c:
        old = c.send_program(PROG)
    big = "%\nO1234\n" + "G1 X1 Y1 F100\n" * 150 + "M30\n%\n"
    s = machine.raw()
    s.sendall(b"READ\n" + encode_program(big)[:1000])
    if reset:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    s.close()
    deadline = time.monotonic() + 5.0
    while not machine.warnings and time.monotonic() < deadline:
        time.sleep(0.01)
    assert machine.alarms == [] and [n for n, _ in machine.warnings] == [2004]
    assert "program discarded, memory unchanged" in machine.warnings[0][1]
    with machine.client() as c:
        assert sha256_text(c.punch(1234)) == old.sha256


def test_program_larger_than_memory_is_refused_with_drip_feed_suggested(machine):
    big = "O7\n" + "G1 X1 Y1 F100\n" * 400
    with machine.client() as c, pytest.raises(TransferError) as err:
        c.send_program(big)
    assert err.value.alarm == 2002 and "use drip-feed" in err.value.message
    assert machine.memory.directory() == []


def test_plain_tape_without_command_is_a_read(machine):
    with machine.raw() as s:
        s.sendall(b"\0\0\0" + encode_program(PROG))
        s.shutdown(socket.SHUT_WR)
        answer = read_all(s)
    assert answer.startswith(b"OK O1234 ")
    assert 1234 in machine.memory


@pytest.mark.parametrize(
    "command, answer",
    [
        (b"FORMAT\n", b"ERR 2006 unknown command 'FORMAT'"),
        (b"PUNCH O99\n", b"ERR 2003 program O0099 not in memory"),
        (b"PUNCH\n", b"ERR 2005 this command needs a program number"),
        (b"DELETE X1\n", b"ERR 2005 not a program number: 'X1'"),
        (b"READ\n%\nG0 X1\n%\n", b"ERR 2005 no program number"),
        (b"DIR\n", b"OK 0 programs, 4096 bytes free"),
        (b"PUNCH O123456789\n", b"ERR 2005 program number O123456789 outside O1..O99999999"),
        (b"READ O0\n%\nG0 X1\n%\n", b"ERR 2005 program number O0 outside O1..O99999999"),
        (b"READ\n%\nO123456789\nG0 X1\n%\n", b"ERR 2005 program number O123456789 outside"),
    ],
)
def test_command_answers(machine, command, answer):
    with machine.raw() as s:
        s.sendall(command)
        s.shutdown(socket.SHUT_WR)
        assert read_all(s).startswith(answer)


def test_machine_policy_refuses_with_its_reason():
    m = Machine(policy=lambda op, n: "program is running" if n == 1234 else None)
    try:
        with (
            m.client() as c,
            pytest.raises(TransferError, match="alarm 2009: READ refused: program is running"),
        ):
            c.send_program(PROG)
    finally:
        m.close()


def test_delete_frees_memory(machine):
    with machine.client() as c:
        c.send_program(PROG)
        c.delete(1234)
        assert c.directory() == []


def _drain(buffer_list, out, done, stop):
    """The NC's side: take blocks as it executes them, more slowly than the wire brings them."""
    while not stop.is_set():
        if not buffer_list:
            time.sleep(0.001)
            continue
        block = buffer_list[0].take()
        if block is None:
            done.set()
            return
        if block is False:
            time.sleep(0.001)
            continue
        out.append(block)
        if len(out) % 20 == 0:
            time.sleep(0.002)


def test_drip_feed_of_a_program_larger_than_memory_with_xon_xoff(machine):
    blocks = [f"N{n} G1 X{n % 100} Y{n % 37} F500" for n in range(1, 3001)]  # ~75 KB
    assert sum(len(b) + 1 for b in blocks) > 10 * machine.memory.capacity
    taken, done, stop = [], threading.Event(), threading.Event()
    nc = threading.Thread(target=_drain, args=(machine.drip_buffers, taken, done, stop))
    nc.start()
    try:
        with machine.client(chunk=128) as c:
            result = c.drip_feed(iter_blocks(["O55\n", "\n".join(blocks)]))
        assert done.wait(10)
    finally:
        stop.set()
        nc.join()
    assert taken == ["O55", *blocks]
    assert result.blocks == len(blocks) + 1 and result.xoff_count > 0
    buf = machine.drip_buffers[0]
    assert buf.max_fill <= buf.capacity
    assert machine.memory.directory() == []  # nothing went to program memory


def test_sender_ignoring_xoff_gets_an_overrun_alarm(machine):
    flood = b"DRIP\n%\n" + b"G1 X1 Y1 F100\n" * 20000  # 280 KB, and no NC takes anything
    with machine.raw() as s:
        s.settimeout(5)
        with contextlib.suppress(OSError):  # the machine closing on us is the point
            s.sendall(flood)
        answer = read_all(s)
    assert bytes([XOFF]) in answer and b"ERR 2010 overrun" in answer
    assert machine.alarms[-1][0] == 2010
    assert machine.drip_buffers[0].aborted


def test_eight_digit_o_numbers_round_trip_through_the_port(machine):
    """READ, DIR, PUNCH and DELETE with 6- and 8-digit O numbers (Fanuc 8-digit option)."""
    main = PROG.replace("O1234 (PLATE)", "O80000001 (MAIN)")
    sub = PROG.replace("O1234 (PLATE)", "O410000 (SUB)")
    with machine.client() as c:
        assert c.send_program(main).number == 80000001
        assert c.send_program(sub, number=410000).number == 410000
        assert [n for n, _size, _sha in c.directory()] == [410000, 80000001]
        assert c.punch(80000001) == canonical_text(main)
        c.delete(410000)
    assert 410000 not in machine.memory and 80000001 in machine.memory


@pytest.mark.parametrize(
    ("name", "number"), [("moji-o80000001-main.nc", 80000001), ("moji-o410000-sub.nc", 410000)]
)
def test_corpus_programs_with_long_o_numbers_are_stored_by_their_own_number(name, number):
    """Real Fanuc production programs (8- and 6-digit O numbers) go in by their tape header."""
    from dnc.tape import read_header
    from tests.reference import GCODE_CORPUS, MISSING

    path = GCODE_CORPUS / name
    if not path.is_file():
        pytest.skip(MISSING)
    text = path.read_text(encoding="latin-1")
    assert read_header(text).number == number
    m = Machine(capacity=256 * 1024)
    try:
        with m.client() as c:
            assert c.send_program(text).number == number
            assert [n for n, _size, _sha in c.directory()] == [number]
    finally:
        m.close()


@pytest.mark.parametrize("number", [1234, 80000001])
def test_remote_request_is_answered_with_the_program(machine, number):
    served, stop = [], threading.Event()
    prog = PROG.replace("O1234", f"O{number}")

    def host():
        with machine.client() as c:
            served.append(c.listen(lambda n: prog if n == number else None, until=stop.is_set))

    t = threading.Thread(target=host)
    t.start()
    deadline = time.monotonic() + 5
    while machine.port.remote_request(number) == 0 and time.monotonic() < deadline:
        time.sleep(0.01)  # until the host's LISTEN is registered
    while number not in machine.memory and time.monotonic() < deadline:
        time.sleep(0.01)
    stop.set()
    t.join(5)
    assert machine.memory.get(number) == canonical_text(prog)
    assert served[0] >= 1


def test_garbage_does_not_hurt_the_port_or_other_clients(machine):
    with machine.raw() as s:
        s.sendall(bytes(range(256)) * 4)
        s.shutdown(socket.SHUT_WR)
        read_all(s)
    with machine.client() as c:
        assert c.send_program(PROG).number == 1234


def test_unreachable_port_is_a_connect_error():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(TransferError) as err, DncClient("127.0.0.1", port, timeout_s=1):
        pass
    assert err.value.kind == "connect" and err.value.retryable
