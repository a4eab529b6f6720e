"""A running machine through its faces over real sockets: DNC port (DncClient and raw
tape), Modbus remote panel (pymodbus client), SHDR stream, simulation face; bad input.

Ideal axes keep these fast; the faces and the PLC are the real ones. The machine is stepped
in lockstep by the test; a face's client runs in a thread while the test steps.
"""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest

from cnc.config import load_machine_config
from cnc.faces.tape import add_parity, encode_program
from cnc.machine import FaultSpecError, Machine
from cnc.machine.contract import CommandRefused
from cnc.program_memory import MemoryFull
from dnc.transfer import DncClient, TransferError

PROG = """%
O0010 (SQUARE)
N10 G21 G90 G17
N20 G1 X-100 Y-100 F6000
N30 X-150
N40 Y-150
N50 M30
%
"""


def config(**over):
    ports = {"dnc": 0, "modbus": 0, "shdr": 0, "simulation": None}
    # programs in machine coordinates: no factory setup (G54 = 0)
    return load_machine_config({"base": "mill3", "ports": ports, "machine_data": None, **over})


def homed(m) -> bool:
    return all(m.controller.referenced.values())


def ready(m: Machine) -> Machine:
    m.step(50)
    m.command("mode", mode="REF")
    m.command("home")
    assert m.run_until(homed, 5.0)
    m.command("mode", mode="AUTO")
    return m


@pytest.fixture
def machine():
    m = Machine(config(), "mill1", ideal=True)
    m.start_faces()
    yield ready(m)
    m.close()


def in_thread(fn):
    """Run a face client in a thread; `.done` tells the stepping loop when to stop."""
    box: dict = {}

    def run():
        try:
            box["value"] = fn()
        except Exception as exc:  # handed to the test
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    box["thread"] = t
    return box


def step_while(m: Machine, box, max_s: float = 60.0) -> object:
    """Step the machine while the client thread works (its I/O needs the machine to run)."""
    m.run_until(lambda mm: not box["thread"].is_alive(), max_s)
    box["thread"].join(5)
    if "error" in box:
        raise box["error"]
    return box.get("value")


def port(m, face):
    return m.faces.ports()[face]


def test_faces_bind_their_ports_and_the_simulation_face_is_off_by_default(machine):
    ports = machine.faces.ports()
    assert all(ports[f] > 0 for f in ("dnc", "modbus", "shdr"))
    assert ports["simulation"] is None


def test_dnc_transfer_into_a_running_machine_then_run_it(machine):
    machine.load_program(PROG.replace("O0010", "O0011"))
    machine.command("select_program", number=11)
    machine.command("cycle_start")
    machine.step(20)
    assert machine.status.execution == "ACTIVE"
    with DncClient("127.0.0.1", port(machine, "dnc"), timeout_s=5) as c:
        sent = c.send_program(PROG)
        directory = c.directory()
    assert sent.number == 10
    assert (10, sent.size, sent.sha256) in directory
    assert machine.status.execution == "ACTIVE"  # the transfer did not disturb the run
    assert machine.run_until(lambda m: m.status.execution == "PROGRAM_COMPLETED", 30.0)
    machine.command("select_program", number=10)
    machine.command("cycle_start")
    machine.step(5)
    assert machine.run_until(lambda m: m.status.execution == "PROGRAM_COMPLETED", 30.0)
    assert machine.axes.feedback().actual == pytest.approx({"X": -150.0, "Y": -150.0, "Z": 0.0})


def test_dnc_parity_error_rejects_the_program_and_raises_a_machine_alarm():
    m = Machine(config(), "mill1", ideal=True)
    m.start_faces(dnc_parity=True)
    try:
        tape = bytearray(add_parity(b"READ\n") + encode_program(PROG, parity=True))
        tape[14] ^= 0x01  # one bit flipped on the line
        with socket.create_connection(("127.0.0.1", port(m, "dnc")), timeout=5) as s:
            s.sendall(bytes(tape))
            answer = bytes(b & 0x7F for b in _read_all(s))
        assert b"ERR 2001 parity error at byte" in answer
        m.step(1)
        assert 10 not in m.memory
        assert [(a.number, a.source) for a in m.alarms] == [(2001, "DNC")]
        assert m.full_status().alarms[-1].number == 2001
        m.command("reset")
        assert m.alarms == ()
    finally:
        m.close()


def test_dnc_transfer_cut_off_is_not_stored_and_leaves_the_machine_fit_to_run(machine):
    with DncClient("127.0.0.1", port(machine, "dnc"), timeout_s=5) as c:
        c.send_program(PROG)
    with socket.create_connection(("127.0.0.1", port(machine, "dnc")), timeout=5) as s:
        s.sendall(b"READ\n" + encode_program(PROG.replace("X-150", "X-120"))[:60])
        s.shutdown(socket.SHUT_WR)
        answer = _read_all(s)
    assert b"ERR 2004" in answer
    machine.step(1)
    assert "X-150" in machine.memory.get(10)  # the program in memory is the old one
    # a WARNING (MTConnect Warning, the host's monitoring records it), no FAULT
    assert [(a.number, a.severity) for a in machine.full_status().alarms] == [(2004, "WARNING")]
    machine.command("select_program", number=10)
    machine.command("cycle_start")  # no reset needed
    machine.step(5)
    assert machine.status.execution == "ACTIVE"
    assert machine.run_until(lambda m: m.status.execution == "PROGRAM_COMPLETED", 30.0)


SLOW = """%
O0010 (ONE SLOW MOVE: 42 S)
N10 G21 G90 G17
N20 G1 X-300 Y-300 F600
N30 M30
%
"""


def big_program(blocks: int) -> str:
    moves = "".join(
        f"N{i * 10 + 100} G1 X{-100 - (i % 50):.3f} Y{-100 - (i % 37):.3f} F30000\n"
        for i in range(blocks)
    )
    return f"%\nO0042 (LARGER THAN MEMORY)\nN10 G21 G90 G17\n{moves}N99990 M30\n%\n"


def test_program_larger_than_memory_is_refused_with_drip_feed_suggested():
    m = Machine(config(program_memory_bytes=1024), "mill1", ideal=True)
    m.start_faces()
    try:
        text = big_program(200)
        with pytest.raises(MemoryFull, match="drip-feed"):
            m.load_program(text)
        client = DncClient("127.0.0.1", port(m, "dnc"), timeout_s=5)
        with client as c, pytest.raises(TransferError) as err:
            c.send_program(text)
        assert "2002" in str(err.value) and "drip-feed" in str(err.value)
        m.step(1)
        assert 2002 in [a.number for a in m.alarms]
        assert 42 not in m.memory
    finally:
        m.close()


def test_drip_feed_of_a_program_larger_than_memory_executes_on_the_machine():
    m = ready(Machine(config(program_memory_bytes=1024), "mill1", ideal=True))
    m.start_faces()
    try:
        text = big_program(400)
        assert len(text) > 8 * 1024  # 8 x the memory, 2 x the drip buffer

        def drip():
            with DncClient("127.0.0.1", port(m, "dnc"), timeout_s=20) as c:
                return c.drip_feed(text.splitlines())

        box = in_thread(drip)
        # the DRIP command arms the controller's drip input; then the operator starts. The
        # client thread connects on the wall clock, so the wait is a wall deadline (machine
        # time runs far faster in lockstep: 60 s of it passed before a loaded box connected)
        deadline = time.monotonic() + 60.0
        while not (m.controller.policy("DRIP", None) is None and m.controller._drip is not None):
            assert time.monotonic() < deadline, "the DRIP command never armed the drip input"
            m.step(m.plc_every)
        m.command("cycle_start")
        result = step_while(m, box, 600.0)
        assert result.blocks == len(text.splitlines()) - 2
        assert result.xoff_count > 0  # the bounded buffer pushed back
        assert m.run_until(lambda mm: mm.status.execution == "PROGRAM_COMPLETED" or mm.alarms, 60.0)
        assert m.alarms == ()
        assert m.axes.feedback().actual["X"] == pytest.approx(-100 - 399 % 50)
        assert m.memory.directory() == []  # nothing was stored
    finally:
        m.close()


def test_shdr_stream_of_a_running_machine(machine):
    with socket.create_connection(("127.0.0.1", port(machine, "shdr")), timeout=5) as s:
        # an agent reads all the time: drain the stream in a thread while the machine runs
        box = in_thread(lambda: _read_until(s, b"|exec|PROGRAM_COMPLETED", 60.0))
        machine.step(10)
        machine.load_program(PROG)
        machine.command("select_program", number=10)
        machine.command("cycle_start")
        machine.run_until(lambda m: m.status.execution == "PROGRAM_COMPLETED", 30.0)
        machine.step(10)
        box["thread"].join(60.0)
        if "error" in box:
            raise AssertionError(f"{box['error']} (face: {machine.shdr.stats})") from box["error"]
        text = box["value"].decode()
    assert text.startswith("* shdrVersion: 2\n")
    assert "|avail|AVAILABLE|" in text
    assert "|exec|ACTIVE" in text and "|exec|PROGRAM_COMPLETED" in text
    assert "|program|O0010" in text
    assert "|Xact|-150.0000" in text or "Xact|-150.0000" in text
    assert "|mode|AUTOMATIC" in text
    # lockstep: the declared epoch (2000-01-01T00:00:00Z) + machine time, a few seconds
    first = text.splitlines()[1].split("|")[0]
    assert first.startswith("2000-01-01T00:00:")


def test_modbus_remote_panel_cycle_start_through_a_pymodbus_client(machine):
    from pymodbus.client import ModbusTcpClient

    from plc.remote_panel import RemotePanel

    machine.load_program(PROG)
    machine.command("select_program", number=10)
    machine.step(10)
    client = ModbusTcpClient("127.0.0.1", port=port(machine, "modbus"), timeout=3)
    assert client.connect()
    try:
        RemotePanel(client).cycle_start()
        assert machine.run_until(lambda m: m.status.execution == "ACTIVE", 0.1)
        # outside the allow-list: refused by the face, the machine untouched
        rr = client.write_coil(16, True)  # SpindleEnable (PLC->field)
        assert rr.isError()
    finally:
        client.close()
    assert machine.run_until(lambda m: m.status.execution == "PROGRAM_COMPLETED", 30.0)


def test_commands_the_state_forbids_are_refused_with_the_reason_and_logged(machine):
    machine.load_program(PROG)
    machine.command("select_program", number=10)
    machine.command("cycle_start")
    machine.step(10)
    with pytest.raises(CommandRefused, match="mode change refused while ACTIVE"):
        machine.command("mode", mode="JOG")
    refused = machine.events.of_kind("refused")
    assert refused and "mode change refused" in refused[-1].text
    assert machine.status.execution == "ACTIVE"


def test_unknown_fault_spec_is_refused_before_anything_runs():
    with pytest.raises(FaultSpecError, match="valid specs"):
        Machine(config(), "mill1", ideal=True, faults=["drive:X:meltdown@1s"])


def test_ideal_axes_refuse_bus_faults_clearly(machine):
    with pytest.raises(ValueError, match="not modelled on ideal axes"):
        machine.inject("bus:bus_off:X")


def ask(m: Machine, sim_port: int, *lines: str) -> list[str]:
    def talk():
        with socket.create_connection(("127.0.0.1", sim_port), timeout=10) as s:
            f = s.makefile("rwb")
            out = []
            for line in lines:
                f.write(line.encode() + b"\n")
                f.flush()
                out.append(f.readline().decode().strip())
            return out

    return step_while(m, in_thread(talk), 60.0)


def test_simulation_face_injects_faults_and_operator_actions():
    m = ready(Machine(config(), "mill1", ideal=True))
    m.start_faces(simulation=True)
    try:
        sim = port(m, "simulation")
        m.load_program(SLOW)
        m.command("select_program", number=10)
        m.command("cycle_start")
        m.step(10)
        answers = ask(
            m,
            sim,
            "DOOR OPEN",
            "STATUS",
            "FAULT drive:X:bogus",
            "HELLO",
            "PAUSE",
            "FAULT plc:air_pressure_loss@1000s",
        )
        assert answers[0] == "OK door open"
        m.step(10)
        assert answers[1].startswith("OK t=") and "execution=" in answers[1]
        assert answers[2].startswith("ERR fault spec 'drive:X:bogus': unknown drive fault")
        assert answers[3].startswith("ERR unknown command")
        assert answers[4].startswith("ERR clock control needs the realtime runner")
        assert answers[5] == "OK scheduled plc:air_pressure_loss@1000s"
        assert m.status.execution == "FEED_HOLD"
        assert [s.kind for s in m.schedule.pending] == ["air_pressure_loss"]
        assert ask(m, sim, "DOOR CLOSE") == ["OK door closed"]
        m.step(10)  # the PLC takes the door switch before the operator's next key
        assert ask(m, sim, "PRESS PanelCycleStart") == ["OK PanelCycleStart pressed"]
        assert m.run_until(lambda mm: mm.status.execution == "ACTIVE", 0.1)
        answers = ask(m, sim, "ESTOP PRESS")
        assert answers == ["OK E-stop pressed"]
        assert m.run_until(lambda mm: mm.status.emergency_stop == "TRIGGERED", 0.1)
        assert not any(m.controller.referenced.values())
    finally:
        m.close()


def test_simulation_face_answers_inject_and_clear_with_the_machine_time():
    """A bench judges detection bounds in machine time: the face says when the machine took
    the fault and the clear (server.cell keeps it in the fault record)."""
    m = ready(Machine(config(), "mill1", ideal=True))
    m.start_faces(simulation=True)
    try:
        sim = port(m, "simulation")
        m.step(50)
        (injected,) = ask(m, sim, "FAULT plc:lube_level_low")
        assert injected.startswith("OK injected plc:lube_level_low t=")
        t_inject = float(injected.rsplit("t=", 1)[1])
        assert 0 < t_inject <= m.t
        m.step(50)
        (cleared,) = ask(m, sim, "CLEAR plc:lube_level_low")
        t_clear = float(cleared.rsplit("t=", 1)[1])
        assert cleared.startswith("OK cleared ") and t_clear >= t_inject + 50 * m.ipo_s - 1e-9
    finally:
        m.close()


def test_simulation_face_clock_control_with_the_realtime_runner():
    from cnc.machine import RealtimeRunner

    m = Machine(config(), "mill1", ideal=True)
    m.start_faces(simulation=True)
    runner = RealtimeRunner(m)
    t = threading.Thread(target=runner.run, kwargs={"duration_s": 30.0}, daemon=True)
    t.start()
    try:
        with socket.create_connection(("127.0.0.1", port(m, "simulation")), timeout=10) as s:
            f = s.makefile("rwb")

            def say(line):
                f.write(line.encode() + b"\n")
                f.flush()
                return f.readline().decode().strip()

            paused = say("PAUSE")
            c0 = int(say("STATUS").split("cycle=")[1].split()[0])
            assert paused == f"OK pause {c0}"
            assert say("STEP 25") == f"OK step {c0 + 25}"
            c1 = int(say("STATUS").split("cycle=")[1].split()[0])
            assert c1 == c0 + 25  # paused: exactly the cycles asked for
            assert say("SPEED 1000") == "ERR SPEED takes a factor 0.01..100"
            assert say("SPEED 2") == "OK speed"
            assert say("RESUME") == "OK resume"
            # resumed: the runner paces cycles again (polled on the face; the deadline only
            # ends a hung run)
            deadline = time.monotonic() + 10.0
            while int(say("STATUS").split("cycle=")[1].split()[0]) <= c1:
                assert time.monotonic() < deadline, "no cycle after RESUME"
    finally:
        runner.stop()
        t.join(5)
        m.close()
    summary = runner.summary()
    assert summary["cycles"] > 0 and runner.speed == 2.0


def test_event_log_is_written_as_jsonl(tmp_path):
    path = tmp_path / "events.jsonl"
    m = Machine(
        config(),
        "mill1",
        ideal=True,
        event_log_path=str(path),
        faults=["plc:air_pressure_loss@0.1s"],
    )
    try:
        m.run_until(lambda mm: mm.alarms, 1.0)
    finally:
        m.close()
    events = [json.loads(line) for line in path.read_text().splitlines()]
    assert events[0]["kind"] == "fault_injected" and events[0]["t"] == pytest.approx(0.1)
    assert any(e["kind"] == "alarm" and e["data"]["source"] == "PLC" for e in events)


def _read_all(s: socket.socket) -> bytes:
    out = b""
    while True:
        try:
            chunk = s.recv(4096)
        except (TimeoutError, ConnectionResetError):
            break
        if not chunk:
            break
        out += chunk
    return out


def _read_until(s: socket.socket, marker: bytes, within_s: float = 5.0) -> bytes:
    """The stream up to `marker`; the server closing first is a failure that says so."""
    out = b""
    s.settimeout(within_s)
    while marker not in out:
        chunk = s.recv(65536)
        if not chunk:
            raise AssertionError(
                f"the face closed the stream after {len(out)} bytes, before {marker!r}:"
                f" {out[-400:]!r}"
            )
        out += chunk
    return out


def test_realtime_runner_stops_with_the_reason_when_the_machine_fails():
    from cnc.controller import Controller
    from cnc.machine import RealtimeRunner

    class Broken(Controller):
        def cycle(self, inputs):
            if inputs.t > 0.05:
                raise RuntimeError("interpolator fell over")
            return super().cycle(inputs)

    m = Machine(config(), "mill1", ideal=True, controller_factory=Broken)
    try:
        summary = RealtimeRunner(m, speed=10.0).run(5.0)
    finally:
        m.close()
    assert summary["error"] == "RuntimeError: interpolator fell over"
    assert m.events.of_kind("stopped")[0].text.endswith("interpolator fell over")
