"""The host's links to its machines (server/supervisor.py) where a real cell rarely goes:
refusals and failures of the remote panel and the simulation face, mode and home requests
the NC does not take, and machine processes adopted from an earlier host or dying at start.

The panel's decisions are driven through a scripted remote panel (the NC's mode, cycle and
homing state as the PLC shows them); the faces' failures through real loopback sockets.
Nothing waits on a simulation: a time-out here is the supervisor's own (set short), against
a panel whose state never changes.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import socketserver
import subprocess
import sys
import threading
import time

import pytest

from plc.remote_panel import PanelRefused
from server.supervisor import (
    MODE_NUMBERS,
    MachineLink,
    MachineUnavailable,
    SubprocessMachine,
    wait_for,
)

AUTO, MDI, REF = MODE_NUMBERS["AUTO"], MODE_NUMBERS["MDI"], MODE_NUMBERS["REF"]


class ScriptedPanel:
    """A remote panel whose NC and PLC state the test sets: the NC's mode, a program in
    cycle, the PLC's ModeSelect and ModeRefused, whether the NC takes a mode request, and
    what a home all ends with."""

    def __init__(self, *, mode=AUTO, in_cycle=False, mode_select=0, takes_mode=True,
                 mode_refused=False, homing="done", axes=("X", "Y", "Z")):  # fmt: skip
        self.mode, self.in_cycle = mode, in_cycle
        self.mode_select, self.takes_mode, self.mode_refused = mode_select, takes_mode, mode_refused
        self.homing = homing  # done | partial | stuck
        self.homing_active = False
        self.refs = dict.fromkeys(axes, False)
        self.requests: list[tuple] = []

    def nc_state(self) -> dict:
        return {
            "NcMode": self.mode,
            "NcInCycle": self.in_cycle,
            "HomingActive": self.homing_active,
            "AllReferenced": all(self.refs.values()),
        }

    def status(self) -> dict:
        return {"ModeSelect": self.mode_select, "ModeRefused": self.mode_refused, "PlcReady": True}

    def request_mode(self, mode: int) -> None:
        self.requests.append(("mode", mode))
        self.mode_select = mode
        if self.takes_mode and not self.in_cycle:
            self.mode = mode

    def home_all(self, timeout_s: float = 5.0) -> None:
        self.requests.append(("home_all",))
        first = next(iter(self.refs))
        if self.homing == "done":
            self.refs = dict.fromkeys(self.refs, True)
        elif self.homing == "partial":  # a drive fault stops the sequence after the first axis
            self.refs[first] = True
        else:
            self.homing_active = True

    def referenced(self) -> dict:
        return dict(self.refs)

    def select_program(self, number: int, timeout_s: float = 5.0) -> None:
        self.requests.append(("select", number))

    def cycle_start(self) -> None:
        self.requests.append(("cycle_start",))

    def set_feed_override(self, percent: int) -> None:
        self.requests.append(("feed_override", percent))


def link(**ports) -> MachineLink:
    return MachineLink("m1", "mill", "127.0.0.1", ports, ("X", "Y", "Z"), 1 << 16)


@pytest.fixture
def panel(monkeypatch):
    """panel(**state) -> the ScriptedPanel every MachineLink's remote_panel() yields."""

    def make(**state) -> ScriptedPanel:
        p = ScriptedPanel(**state)
        monkeypatch.setattr(
            MachineLink, "remote_panel", lambda self, timeout_s=3.0: contextlib.nullcontext(p)
        )
        return p

    return make


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ------------------------------------------------------------------ panel decisions
def test_panel_actions_with_and_without_a_value(panel):
    p = panel()
    lk = link(modbus=1)
    lk.panel("cycle_start")
    lk.panel("set_feed_override", 80)
    assert p.requests == [("cycle_start",), ("feed_override", 80)]
    assert lk.panel_status()["PlcReady"] is True


def test_program_select_is_refused_while_a_program_is_active(panel):
    p = panel(in_cycle=True)
    with pytest.raises(MachineUnavailable, match=r"m1: program select O0042 refused: a program"):
        link(modbus=1).select_program(42)
    assert p.requests == []
    p.in_cycle = False
    link(modbus=1).select_program(42)
    assert p.requests == [("select", 42)]


def test_a_mode_that_does_not_exist_is_refused_before_asking(panel):
    p = panel()
    with pytest.raises(MachineUnavailable, match=r"mode 'EDIT': one of AUTO, MDI, JOG, REF"):
        link(modbus=1).mode("EDIT")
    assert p.requests == []


def test_the_present_mode_is_not_requested_again(panel):
    p = panel(mode=MDI)
    link(modbus=1).mode("MDI")
    assert p.requests == []


def test_a_mode_change_is_refused_while_a_program_is_active(panel):
    p = panel(in_cycle=True)
    with pytest.raises(MachineUnavailable, match=r"m1: mode MDI refused: a program is active"):
        link(modbus=1).mode("MDI")
    assert p.requests == []


def test_a_stale_mode_select_is_set_back_first_so_the_nc_sees_a_change(panel):
    # the PLC still holds REF from an earlier request, the NC went back to AUTO since: the NC
    # takes ModeSelect on a change only, so the present mode is requested first
    p = panel(mode=AUTO, mode_select=REF)
    link(modbus=1).mode("REF")
    assert p.requests == [("mode", AUTO), ("mode", REF)]
    assert p.mode == REF


@pytest.mark.parametrize(
    ("refused", "why"),
    [
        (True, "refused by the PLC (a program is active)"),
        (False, "not taken by the NC (homing in progress or a program active)"),
    ],
)
def test_a_mode_the_nc_does_not_take_says_why_and_where_it_is(panel, refused, why):
    panel(mode=AUTO, takes_mode=False, mode_refused=refused)
    with pytest.raises(MachineUnavailable) as err:
        link(modbus=1).mode("MDI", timeout_s=0.05)
    assert str(err.value) == f"m1: mode MDI {why}; the NC is in mode {AUTO}"


def test_home_goes_through_ref_and_back_to_auto(panel):
    p = panel(mode=AUTO)
    link(modbus=1).home(timeout_s=5.0)
    assert p.requests == [("mode", REF), ("home_all",), ("mode", AUTO)]
    assert all(p.refs.values()) and p.mode == AUTO


def test_home_is_refused_while_a_program_is_active(panel):
    p = panel(in_cycle=True)
    with pytest.raises(MachineUnavailable, match=r"m1: home refused: a program is active"):
        link(modbus=1).home()
    assert p.requests == []


def test_a_homing_that_ends_short_names_the_axes_referenced(panel):
    p = panel(homing="partial")
    with pytest.raises(MachineUnavailable) as err:
        link(modbus=1).home(timeout_s=5.0)
    assert str(err.value) == ("m1: homing ended with only X referenced (see the machine's alarms)")
    assert p.mode == REF  # left in REF: the operator sees where it stopped


def test_a_homing_that_never_ends_times_out(panel):
    panel(homing="stuck")
    with pytest.raises(MachineUnavailable, match=r"m1: homing not done in 0.05 s"):
        link(modbus=1).home(timeout_s=0.05)


# ------------------------------------------------------------------ Modbus face failures
def test_no_modbus_face(monkeypatch):
    with pytest.raises(MachineUnavailable, match=r"^m1 has no Modbus face$"):
        link(modbus=None).panel("reset")
    assert link(modbus=None).ping() is False


def test_a_modbus_face_that_does_not_answer():
    port = free_port()  # nothing listens there
    with pytest.raises(MachineUnavailable) as err:
        link(modbus=port).panel("reset")
    assert str(err.value) == f"m1: Modbus face 127.0.0.1:{port} not reachable"
    assert link(modbus=port).ping() is False


def test_a_refusal_inside_a_panel_session_names_the_machine():
    with socket.socket() as server:  # a TCP peer is enough to open the session
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        lk = link(modbus=server.getsockname()[1])
        with pytest.raises(MachineUnavailable) as err, lk.remote_panel():
            raise PanelRefused("program select O0042", 3)
    assert str(err.value).startswith("m1: program select O0042 refused: ")


# ------------------------------------------------------------------ simulation face
class SimFace(socketserver.ThreadingTCPServer):
    """A simulation face: `AUTH <secret>` first when it has one, then one command line;
    answers from `answers` (a command missing there: no answer, the line is cut)."""

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, secret: str | None, answers: dict[str, str]) -> None:
        self.secret, self.answers, self.seen = secret, answers, []
        outer = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                if outer.secret is not None:
                    line = self.rfile.readline().decode().strip()
                    outer.seen.append(line)
                    if line != f"AUTH {outer.secret}":
                        self.wfile.write(b"ERR 2011 authentication failed\n")
                        return
                    self.wfile.write(b"OK\n")
                line = self.rfile.readline().decode().strip()
                outer.seen.append(line)
                if line in outer.answers:
                    self.wfile.write(outer.answers[line].encode() + b"\n")

        super().__init__(("127.0.0.1", 0), Handler)
        self.thread = threading.Thread(target=self.serve_forever, daemon=True)
        self.thread.start()

    @property
    def port(self) -> int:
        return self.server_address[1]

    def close(self) -> None:
        self.shutdown()
        self.server_close()
        self.thread.join(10)


@pytest.fixture
def sim_face():
    made: list[SimFace] = []

    def make(secret=None, **answers) -> SimFace:
        face = SimFace(secret, {k.replace("_", " "): v for k, v in answers.items()})
        made.append(face)
        return face

    yield make
    for face in made:
        face.close()


def test_simulation_face_off():
    with pytest.raises(MachineUnavailable, match=r"m1: the simulation face is off \(start"):
        link(simulation=None).simulation("ESTOP PRESS")


def test_simulation_command_with_the_shared_secret(sim_face):
    face = sim_face("s3cret-0123456789", ESTOP_PRESS="OK pressed")
    lk = link(simulation=face.port)
    lk.secret = "s3cret-0123456789"
    assert lk.simulation("ESTOP PRESS") == "pressed"
    assert face.seen == ["AUTH s3cret-0123456789", "ESTOP PRESS"]


def test_simulation_wrong_secret(sim_face):
    face = sim_face("s3cret-0123456789")
    lk = link(simulation=face.port)
    lk.secret = "wrong-secret-000000"
    with pytest.raises(MachineUnavailable) as err:
        lk.simulation("ESTOP PRESS")
    assert str(err.value) == "m1: simulation face: ERR 2011 authentication failed"
    assert face.seen == ["AUTH wrong-secret-000000"]  # the command never went out


def test_simulation_refusal_and_silence(sim_face):
    face = sim_face(FAULT_drive_Q="ERR no axis Q")
    lk = link(simulation=face.port)
    with pytest.raises(MachineUnavailable, match=r"^m1: no axis Q$"):
        lk.simulation("FAULT drive Q")
    with pytest.raises(MachineUnavailable, match=r"^m1: no answer$"):
        lk.simulation("CLEAR all")  # the face closes without a word


def test_simulation_face_not_listening():
    with pytest.raises(MachineUnavailable, match=r"^m1: simulation face: .*refused"):
        link(simulation=free_port()).simulation("ESTOP PRESS", timeout_s=5.0)


def test_wait_for_says_what_it_waited_for():
    assert wait_for(lambda: 7, 1.0, "seven") == 7
    with pytest.raises(MachineUnavailable, match=r"^the PLC taking it not seen within 0.05 s$"):
        wait_for(lambda: None, 0.05, "the PLC taking it", poll_s=0.01)


# ------------------------------------------------------------------ machine processes
@pytest.fixture
def mill_config():
    from server.cell import default_cell

    return default_cell(free_ports=True).machines["mill1"]


@pytest.fixture
def orphan():
    """A process that is not ours (re-parented, as a machine left by a killed host is)."""
    out = subprocess.run(
        [
            "sh",
            "-c",
            f"'{sys.executable}' -c 'import time; time.sleep(120)' >/dev/null 2>&1 & echo $!",
        ],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    pid = int(out.stdout.strip())
    try:
        yield pid
    finally:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


def _state(tmp_path, **state) -> None:
    (tmp_path / "mill1.machine.json").write_text(json.dumps(state))


def test_a_running_machine_process_is_adopted_and_stopped(tmp_path, mill_config, orphan,
                                                          monkeypatch):  # fmt: skip
    ports = {"dnc": 7101, "modbus": 5121, "shdr": 7978, "simulation": None}
    _state(tmp_path, machine="mill1", pid=orphan, ports=ports)
    pinged = []
    monkeypatch.setattr(MachineLink, "ping", lambda self: pinged.append(self.ports) or True)
    proc = SubprocessMachine(
        "mill1", tmp_path / "cell.yaml", fast=True, simulation=False, config=mill_config,
        state_dir=tmp_path, secret="kept-secret-0123456789",
    )  # fmt: skip
    assert (proc.adopted, proc.pid, proc.proc) == (True, orphan, None)
    assert pinged == [ports]
    lk = proc.wait_ready()
    assert (lk.ports, lk.secret, lk.kind) == (ports, "kept-secret-0123456789", "mill")
    proc.stop(timeout_s=30.0)
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        try:
            os.kill(orphan, 0)
        except OSError:
            break
        time.sleep(0.05)
    else:
        pytest.fail("the adopted machine process was not stopped")
    assert not (tmp_path / "mill1.machine.json").exists()


@pytest.mark.parametrize(
    "case", ["no state", "other machine", "no pid", "process gone", "plc silent", "garbage"]
)
def test_a_machine_process_that_cannot_be_adopted(tmp_path, monkeypatch, case):
    ports = {"dnc": 7101, "modbus": 5121, "shdr": 7978}
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait(60)
    state = {
        "no state": None,
        "other machine": {"machine": "mill2", "pid": os.getpid(), "ports": ports},
        "no pid": {"machine": "mill1", "pid": 0, "ports": ports},
        "process gone": {"machine": "mill1", "pid": gone.pid, "ports": ports},
        "plc silent": {"machine": "mill1", "pid": os.getpid(), "ports": ports},
        "garbage": None,
    }[case]
    if state is not None:
        _state(tmp_path, **state)
    if case == "garbage":
        (tmp_path / "mill1.machine.json").write_text("{not json")
    monkeypatch.setattr(MachineLink, "ping", lambda self: case != "plc silent")
    probe = SubprocessMachine.__new__(SubprocessMachine)
    probe.name, probe.state_file = "mill1", tmp_path / "mill1.machine.json"
    probe.adopted, probe.pid = False, None
    assert probe._adopt("127.0.0.1") is None
    assert (probe.adopted, probe.pid) == (False, None)


def test_a_machine_process_that_dies_at_start_says_why(tmp_path, mill_config):
    bad = tmp_path / "cell.yaml"
    bad.write_text("machines: [this is not a mapping\n")
    proc = SubprocessMachine(
        "mill1", bad, fast=True, simulation=False, config=mill_config, state_dir=tmp_path,
        timeout_s=120.0,
    )  # fmt: skip
    try:
        assert proc.adopted is False and proc.proc is not None
        with pytest.raises(MachineUnavailable) as err:
            proc.wait_ready()
        text = str(err.value)
        assert text.startswith(f"mill1: machine process ended (exit {proc.proc.returncode}): ")
        assert proc.proc.returncode != 0
        assert text.endswith(f"see {tmp_path / 'mill1.machine.log'}")
    finally:
        proc.stop(timeout_s=10.0)
    assert proc.proc.poll() is not None
