"""The socketcand-compatible server: the protocol table, python-can's own `socketcand` client
on a simulated bus, and an unchanged stock `canopen.BaseNode402` master in this process
driving drives that `fmscell drives serve` runs in another process.

Realtime on purpose (python-can's client and BaseNode402 wait on the wall clock); every wait
is bounded by a deadline with margin, never a sleep standing in for the simulation.
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import canopen
import pytest

from drives import EDS_PATH
from drives.bus import CanHub
from drives.bus.socketcand import (
    ProtocolError,
    SocketcandServer,
    format_frame,
    parse_address,
    parse_send,
)

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "msg, line",
    [
        (
            can.Message(
                arbitration_id=0x185, is_extended_id=False, data=b"\x21\x02", timestamp=12.000345
            ),
            "< frame 185 12.000345 2102 >",
        ),
        (
            can.Message(arbitration_id=0x80, is_extended_id=False, data=b"", timestamp=0.0),
            "< frame 080 0.000000  >",
        ),
        (
            can.Message(
                arbitration_id=0x1ABCDEF0, is_extended_id=True, data=b"\xff", timestamp=1.9999999
            ),
            "< frame 1ABCDEF0 2.000000 FF >",
        ),
    ],
)
def test_frames_are_formatted_as_socketcand_does(msg, line):
    assert format_frame(msg) == line


@pytest.mark.parametrize(
    "words, can_id, extended, data",
    [
        ("send 605 8 40 0 10 0 0 0 0 0", 0x605, False, bytes([0x40, 0, 0x10, 0, 0, 0, 0, 0])),
        ("send 000 2 81 5", 0x000, False, b"\x81\x05"),
        ("send 080 0", 0x080, False, b""),
        ("send 00000123 1 ff", 0x123, True, b"\xff"),
    ],
)
def test_send_commands_parse(words, can_id, extended, data):
    msg = parse_send(words.split())
    assert (msg.arbitration_id, msg.is_extended_id, bytes(msg.data)) == (can_id, extended, data)


@pytest.mark.parametrize(
    "words, reason",
    [
        ("send", "needs an identifier"),
        ("send 80G 1 00", "not hexadecimal"),
        ("send 800 0", "out of range"),
        ("send 205 2 0f", "does not match"),
        ("send 205 9 1 2 3 4 5 6 7 8 9", "does not match"),
        ("send 205 1 100", "above ff"),
    ],
)
def test_malformed_send_is_refused_with_the_reason(words, reason):
    with pytest.raises(ProtocolError, match=reason):
        parse_send(words.split())


@pytest.mark.parametrize(
    "text, address",
    [
        ("29536", ("127.0.0.1", 29536)),
        (":0", ("127.0.0.1", 0)),
        ("0.0.0.0:29600", ("0.0.0.0", 29600)),
    ],
)
def test_addresses(text, address):
    assert parse_address(text) == address


def test_bad_address():
    with pytest.raises(ValueError, match="port"):
        parse_address("host:http")


@pytest.fixture
def served_hub():
    hub = CanHub(channel="sockcand-test", mode="realtime")
    hub.start()
    server = SocketcandServer(hub.endpoint, "can0", port=0, max_clients=2).start()
    yield hub, server
    server.close()
    hub.close()


def _converse(address, *lines: bytes, expect: int) -> list[bytes]:
    """Send raw protocol lines, return what the server answered (until `expect` answers)."""
    with socket.create_connection(address, timeout=5.0) as s:
        got = [s.recv(256)]
        for line in lines:
            s.sendall(line)
        buf = b""
        deadline = time.monotonic() + 5.0
        while buf.count(b">") < expect and time.monotonic() < deadline:
            chunk = s.recv(256)
            if not chunk:
                break
            buf += chunk
        got += [m + b">" for m in buf.split(b">") if m.strip()]
        return got


@pytest.mark.parametrize(
    "lines, answers",
    [
        ([b"< open can0 >"], [b"< hi >", b"< ok >"]),
        ([b"< echo >"], [b"< hi >", b"< echo >"]),
        ([b"< rawmode >"], [b"< hi >", b"< error rawmode before open >"]),
        ([b"< open can9 >"], [b"< hi >", b"< error could not open bus 'can9' >"]),
        (
            [b"< open can0 >", b"< frob >"],
            [b"< hi >", b"< ok >", b"< error unknown command 'frob' >"],
        ),
        (
            [b"< open can0 >< send 205 9 0 >"],
            [b"< hi >", b"< ok >", b"< error send: length 9 does not match 1 data bytes >"],
        ),
    ],
)
def test_protocol_table(served_hub, lines, answers):
    _, server = served_hub
    assert _converse(server.address, *lines, expect=len(answers) - 1) == answers


def test_client_limit_is_refused_not_queued(served_hub):
    _, server = served_hub
    held = [socket.create_connection(server.address, timeout=5.0) for _ in range(2)]
    try:
        for s in held:
            assert s.recv(64) == b"< hi >"
        with socket.create_connection(server.address, timeout=5.0) as third:
            assert third.recv(64) == b"< error too many clients >"
    finally:
        for s in held:
            s.close()


def test_python_can_socketcand_client_exchanges_frames_with_the_hub(served_hub):
    hub, server = served_hub
    local = hub.endpoint("local")
    host, port = server.address
    client = can.Bus(interface="socketcand", host=host, port=port, channel="can0")
    try:
        client.send(
            can.Message(
                arbitration_id=0x605, is_extended_id=False, data=b"\x40\x00\x10\x00\x00\x00\x00\x00"
            )
        )
        got = local.recv(timeout=5.0)
        assert got is not None and got.arbitration_id == 0x605 and got.data[0] == 0x40
        deadline = time.monotonic() + 5.0
        seen = None
        while seen is None and time.monotonic() < deadline:
            # the first frames go out only after the rawmode grace period
            local.send(
                can.Message(
                    arbitration_id=0x585,
                    is_extended_id=False,
                    data=b"\x43\x00\x10\x00\x92\x01\x02\x00",
                )
            )
            seen = client.recv(timeout=0.3)
        assert seen is not None and seen.arbitration_id == 0x585
        assert bytes(seen.data) == b"\x43\x00\x10\x00\x92\x01\x02\x00"
        assert server.clients == 1
    finally:
        client.shutdown()
    deadline = time.monotonic() + 5.0
    while server.clients and time.monotonic() < deadline:
        time.sleep(0.01)  # the server notices the closed socket on its own thread
    assert server.clients == 0


@pytest.fixture
def drives_process():
    """`fmscell drives serve` in its own process, serving node 2 over socketcand."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "server.cli",
            "drives",
            "serve",
            "--interface",
            "sim",
            "--channel",
            "xproc",
            "--node",
            "2",
            "--seconds",
            "120",
            "--socketcand",
            "127.0.0.1:0",
        ],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60.0  # an import on a loaded box
        line = ""
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if "socketcand" in line or not line:
                break
        match = re.search(r"socketcand ([\d.]+):(\d+)", line)
        assert match, f"drives serve did not start: {line!r} rc={proc.poll()}"
        yield match.group(1), int(match.group(2))
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_stock_master_in_another_process_runs_the_basenode402_recipe(drives_process):
    host, port = drives_process
    network = canopen.Network()
    node = canopen.BaseNode402(2, EDS_PATH)
    network.add_node(node)
    network.connect(interface="socketcand", host=host, port=port, channel="xproc")
    try:
        node.nmt.send_command(0x81)  # reset node
        node.nmt.wait_for_bootup(timeout=5.0)
        # the segmented SDO upload of the axis name crosses the process boundary intact
        assert node.sdo[0x2100].raw == "axis"
        node.pdo.read()
        for n in (1, 2):
            node.tpdo[n].event_timer = 50
        node.tpdo.save()
        node.setup_402_state_machine()
        node.nmt.state = "OPERATIONAL"
        node.tpdo[1].wait_for_reception(timeout=2.0)
        node.state = "SWITCH ON DISABLED"
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        # the documented recipe, unchanged: op_mode goes out in RPDO2 (mode of operation
        # alone) and leaves the drive in OPERATION ENABLED
        node.op_mode = "PROFILED VELOCITY"
        assert node.op_mode == "PROFILED VELOCITY"
        node.op_mode = "PROFILED POSITION"
        assert node.op_mode == "PROFILED POSITION"
        assert node.state == "OPERATION ENABLED"
        # a profile-position move of 2 mm: target by SDO, set-point by the controlword
        node.sdo[0x6081].raw = 50_000
        node.sdo[0x607A].raw = 2_000
        node.controlword = 0x0F
        node.controlword = 0x1F
        deadline = time.monotonic() + 10.0
        while not node.statusword & 0x1000:
            assert time.monotonic() < deadline, f"no set-point acknowledge: 0x{node.statusword:04X}"
            node.check_statusword(timeout=0.5)
        node.controlword = 0x0F
        while not (node.statusword & 0x0400 and abs(node.sdo[0x6064].raw - 2_000) < 10):
            assert time.monotonic() < deadline, f"PP move not done: 0x{node.statusword:04X}"
            node.check_statusword(timeout=0.5)
        assert node.state == "OPERATION ENABLED"
    finally:
        network.disconnect()
