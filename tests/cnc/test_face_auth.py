"""The shared secret of the DNC port and the simulation face (`ports.secret`): nothing before
`AUTH <secret>`, over real sockets, with the host's own clients (DncClient, MachineLink)."""

from __future__ import annotations

import socket

import pytest

from cnc.faces.dnc_port import ALARM_AUTH, DncPort
from cnc.faces.loop_thread import LoopThread
from cnc.faces.tape import encode_program
from cnc.faces.tcp_face import secret_matches
from cnc.machine import Machine
from cnc.program_memory import ProgramMemory
from dnc.transfer import DncClient, TransferError, canonical_text
from server.supervisor import MachineLink, MachineUnavailable

from .test_machine_faces import ask, config, port, ready

SECRET = "s3cret-of-the-cell-0123"
PROG = "%\nO1234 (PLATE)\nG21 G90\nG0 X10 Y10\nM30\n%\n"
STORED = canonical_text(PROG)


class Port:
    """A DncPort with program O1234 in memory, optionally with a secret."""

    def __init__(self, secret: str | None, *, parity: bool = False) -> None:
        self.memory = ProgramMemory(4096)
        self.memory.store(1234, STORED)
        self.alarms: list[tuple[int, str]] = []
        self.loop = LoopThread("auth-test").start()
        self.port = DncPort(
            self.memory,
            secret=secret,
            parity=parity,
            idle_timeout_s=5,
            on_alarm=lambda n, t: self.alarms.append((n, t)),
        )
        self.loop.run(self.port.start)

    def talk(self, data: bytes) -> str:
        """Send `data`, half-close, and return everything the port answered until it closed."""
        with socket.create_connection(("127.0.0.1", self.port.bound_port), timeout=5) as s:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
            out = b""
            while chunk := s.recv(4096):
                out += chunk
        return out.decode("ascii", "replace")

    def client(self, secret: str | None) -> DncClient:
        return DncClient(
            "127.0.0.1", self.port.bound_port, timeout_s=5, secret=secret, parity=self.port.parity
        )

    def close(self) -> None:
        self.loop.run(self.port.stop)
        self.loop.stop()


@pytest.fixture
def locked():
    p = Port(SECRET)
    yield p
    p.close()


@pytest.fixture
def open_port():
    p = Port(None)
    yield p
    p.close()


TAPE = encode_program(PROG.replace("O1234", "O4321")).decode("ascii")

# first bytes of a connection -> the start of the port's refusal
UNAUTHENTICATED = [
    ("READ\n" + TAPE, "authentication required: the first line must be AUTH <secret> (READ"),
    (TAPE, "authentication required: the first line must be AUTH <secret> (READ"),
    ("DELETE O1234\n", "authentication required: the first line must be AUTH <secret> (DELETE"),
    ("PUNCH O1234\n", "authentication required: the first line must be AUTH <secret> (PUNCH"),
    ("DIR\n", "authentication required: the first line must be AUTH <secret> (DIR"),
    ("DRIP\n" + TAPE, "authentication required: the first line must be AUTH <secret> (DRIP"),
    ("LISTEN\n", "authentication required: the first line must be AUTH <secret> (LISTEN"),
    ("AUTH not-the-secret-at-all\nDELETE O1234\n", "authentication failed: wrong secret"),
    ("AUTH\nDELETE O1234\n", "authentication failed: wrong secret"),
    (f"AUTH {SECRET}x\nDELETE O1234\n", "authentication failed: wrong secret"),
    ("AUTH " + SECRET.upper() + "\nDIR\n", "authentication failed: wrong secret"),
]


@pytest.mark.parametrize(("sent", "refusal"), UNAUTHENTICATED)
def test_the_locked_port_refuses_everything_before_auth(locked, sent, refusal):
    answer = locked.talk(sent.encode("ascii"))
    assert answer.startswith(f"ERR {ALARM_AUTH} {refusal}"), answer
    assert answer.count("\n") == 1, answer  # one refusal, nothing done, then closed
    # nothing stored, nothing deleted, no program text leaked, no machine alarm
    assert [e.number for e in locked.memory.directory()] == [1234]
    assert locked.memory.get(1234) == STORED
    assert "G0 X10" not in answer
    assert locked.alarms == []
    assert locked.port.stats.auth_refused == 1


def test_the_right_secret_opens_every_command(locked):
    answer = locked.talk(f"AUTH {SECRET}\nDIR\nDELETE O1234\nQUIT\n".encode())
    lines = answer.splitlines()
    assert lines[0] == "OK AUTH"
    assert lines[1].startswith("O1234 ")
    assert lines[3] == "OK O1234 deleted"
    assert 1234 not in locked.memory


def test_the_hosts_client_sends_the_secret(locked):
    with locked.client(SECRET) as c:
        sent = c.send_program(PROG.replace("O1234", "O0777"))
        assert c.punch(777) == canonical_text(PROG.replace("O1234", "O0777"))
        assert sent.number == 777
    for secret in (None, "a-wrong-secret-0123456"):
        with pytest.raises(TransferError) as err, locked.client(secret) as c:
            c.directory()
        assert err.value.kind == "refused" and err.value.alarm == ALARM_AUTH
        assert not err.value.retryable  # a wrong secret does not cure itself


def test_the_handshake_carries_parity_on_a_parity_port():
    p = Port(SECRET, parity=True)
    try:
        with p.client(SECRET) as c:
            assert c.send_program(PROG.replace("O1234", "O0042")).number == 42
        with pytest.raises(TransferError) as err, p.client("not-the-secret-0123") as c:
            c.directory()
        assert err.value.alarm == ALARM_AUTH
        assert p.alarms == []
    finally:
        p.close()


def test_a_port_without_secret_still_takes_plain_tape_and_answers_auth(open_port):
    answer = open_port.talk(TAPE.encode("ascii"))
    assert answer.startswith("OK O4321 ")
    with open_port.client(SECRET) as c:  # a host that always authenticates
        assert [n for n, _, _ in c.directory()] == [1234, 4321]


def test_secret_comparison():
    assert secret_matches(SECRET, SECRET)
    assert not secret_matches(SECRET[:-1], SECRET)
    assert not secret_matches("", SECRET)
    assert not secret_matches(SECRET + "\x00", SECRET)


# --- the simulation face -----------------------------------------------------------------


@pytest.fixture
def sim_machine():
    m = ready(
        Machine(
            config(ports={"dnc": 0, "modbus": 0, "shdr": 0, "secret": SECRET}), "mill1", ideal=True
        )
    )
    m.start_faces(simulation=True)
    yield m
    m.close()


def raw_lines(sim_port: int, *lines: str) -> list[str]:
    """Send lines, read answers until the face closes (no machine stepping needed: every
    line here is refused before it reaches the machine)."""
    with socket.create_connection(("127.0.0.1", sim_port), timeout=5) as s:
        s.sendall("".join(f"{ln}\n" for ln in lines).encode())
        out = b""
        while chunk := s.recv(4096):
            out += chunk
    return out.decode().splitlines()


@pytest.mark.parametrize(
    ("lines", "answer"),
    [
        (["ESTOP PRESS"], "ERR authentication required: the first line must be AUTH <secret>"),
        (["FAULT drive:X:encoder"], "ERR authentication required"),
        (["DOOR OPEN"], "ERR authentication required"),
        (["SPEED 50"], "ERR authentication required"),
        (["AUTH guess-guess-guess-1", "ESTOP PRESS"], "ERR authentication failed: wrong secret"),
    ],
)
def test_the_simulation_face_refuses_commands_before_auth(sim_machine, lines, answer):
    got = raw_lines(port(sim_machine, "simulation"), *lines)
    assert len(got) == 1 and got[0].startswith(answer), got
    sim_machine.step(20)
    assert sim_machine.status.emergency_stop != "TRIGGERED"
    assert not sim_machine.schedule.pending and not sim_machine.full_status().alarms
    assert sim_machine.faces.simulation.auth_refused == 1


def test_the_simulation_face_takes_commands_after_auth(sim_machine):
    answers = ask(sim_machine, port(sim_machine, "simulation"), f"AUTH {SECRET}", "ESTOP PRESS")
    assert answers == ["OK AUTH", "OK E-stop pressed"]
    assert sim_machine.run_until(lambda mm: mm.status.emergency_stop == "TRIGGERED", 0.1)


def test_the_hosts_machine_link_authenticates_on_the_simulation_face(sim_machine):
    from .test_machine_faces import in_thread, step_while

    ports = sim_machine.faces.ports()
    link = MachineLink("mill1", "mill", "127.0.0.1", ports, ("X", "Y", "Z"), 0, secret=SECRET)
    assert step_while(sim_machine, in_thread(lambda: link.simulation("STATUS"))).startswith("t=")
    wrong = MachineLink("mill1", "mill", "127.0.0.1", ports, ("X", "Y", "Z"), 0, secret="x" * 20)
    with pytest.raises(MachineUnavailable, match="authentication failed"):
        wrong.simulation("ESTOP PRESS")
    none = MachineLink("mill1", "mill", "127.0.0.1", ports, ("X", "Y", "Z"), 0)
    with pytest.raises(MachineUnavailable, match="authentication required"):
        none.simulation("ESTOP PRESS")


def test_the_dnc_command_line_sends_and_receives_with_the_secret(tmp_path, locked):
    from typer.testing import CliRunner

    from dnc.db import make_engine, session_factory
    from dnc.library import Library
    from server.cli import app

    db = f"sqlite:///{tmp_path / 'cli.db'}"
    args = ["--database-url", db]
    (tmp_path / "p.nc").write_text(PROG.replace("O1234", "O0555"))
    runner = CliRunner()
    assert runner.invoke(app, ["dnc", "import", str(tmp_path / "p.nc"), *args]).exit_code == 0
    address = f"127.0.0.1:{locked.port.bound_port}"
    added = runner.invoke(app, ["dnc", "machine", "m1", "--kind", "mill", "--dnc", address, *args])
    assert added.exit_code == 0, added.output
    lib = Library(session_factory(make_engine(db)))
    lib.release(lib.search(number=555).items[0].latest_revision_id, approver="a", comment="ok")
    refused = runner.invoke(app, ["dnc", "send", "555", "-m", "m1", *args])
    assert refused.exit_code == 1 and "machine alarm 2011" in refused.output, refused.output
    env = {"FMSCELL_DNC_SECRET": SECRET}
    sent = runner.invoke(app, ["dnc", "send", "555", "-m", "m1", *args], env=env)
    assert sent.exit_code == 0 and "verified" in sent.output, sent.output
    back = runner.invoke(app, ["dnc", "receive", "O0555", "-m", "m1", *args], env=env)
    assert back.exit_code == 0, back.output
    assert 555 in locked.memory
