"""The host's data for a machine's OPC UA face (server/opcua_feed.py): the revision and
sha256 of each program dispatched to it (the newest done dispatch wins), and the open jobs
with an allocation on it."""

from __future__ import annotations

import hashlib
from types import SimpleNamespace as NS

from server.opcua_feed import host_data


class Library:
    revisions = {
        7: NS(id=7, program_id=1, sha256="a" * 64),
        9: NS(id=9, program_id=1, sha256="b" * 64),
        11: NS(id=11, program_id=2, sha256="c" * 64),
    }
    programs = {1: NS(number=100), 2: NS(number=2001)}

    def get_revision(self, rid):
        return self.revisions[rid]

    def get_program(self, pid):
        return self.programs[pid]


class Dispatches:
    rows = [  # newest first, as Dispatches.list returns them
        NS(machine="mill1", revision_id=9, state="failed"),
        NS(machine="mill1", revision_id=7, state="done"),
        NS(machine="mill1", revision_id=9, state="done"),
    ]

    def list(self, machine=None, limit=100):
        return [d for d in self.rows if d.machine == machine][:limit]


class Jobs:
    jobs = {
        "running": [NS(id=3, revision_id=11, quantity=5, done=2, status="running")],
        "queued": [NS(id=4, revision_id=7, quantity=1, done=0, status="queued")],
    }
    allocs = {
        3: [  # job 3's five parts: two done on mill1, one on lathe1, one running on mill1
            {"machine": "mill1", "status": "completed"},
            {"machine": "lathe1", "status": "completed"},
            {"machine": "mill1", "status": "completed"},
            {"machine": "lathe1", "status": "rerouted"},
            {"machine": "mill1", "status": "running"},
        ],
        4: [{"machine": "mill2", "status": "dispatched"}],
    }

    def list(self, status=None, limit=100):
        return self.jobs.get(status, [])

    def allocations(self, job_id):
        return self.allocs[job_id]


def test_the_newest_done_dispatch_names_the_revision_of_each_program():
    data = host_data(Library(), Dispatches(), Jobs(), "mill1")
    assert data.revision_by_program == {"O0100": "7"}  # 9 failed after; 7 is newer than 9
    assert data.sha256_by_program == {"O0100": "a" * 64}


def test_open_jobs_allocated_to_the_machine_become_production_jobs():
    data = host_data(Library(), Dispatches(), Jobs(), "mill1")
    assert [
        (j.identifier, j.program, j.runs_planned, j.runs_completed, j.state) for j in data.jobs
    ] == [("job3", "O2001", 5, 2, "Running")]
    assert host_data(Library(), Dispatches(), Jobs(), "mill2").jobs[0].state == "Initializing"


def test_each_machine_counts_its_own_runs_of_a_job_and_shows_the_plans_quantity():
    """A job spread over machines: each machine's ProductionJob counts the runs (parts) it
    completed, not the job's total (3 here); RunsPlanned is the job's quantity on both."""
    Jobs.jobs["running"][0].done = 3  # the cell's count: 2 on mill1 + 1 on lathe1
    try:
        by_machine = {
            name: host_data(Library(), Dispatches(), Jobs(), name).jobs[0]
            for name in ("mill1", "lathe1")
        }
    finally:
        Jobs.jobs["running"][0].done = 2
    assert {
        n: (j.runs_planned, j.runs_completed, j.parts_completed) for n, j in by_machine.items()
    } == {
        "mill1": (5, 2, 2),
        "lathe1": (5, 1, 1),
    }


def test_opcua_users_are_the_api_keys_with_their_roles():
    from server.cell import opcua_users
    from web_api.settings import ApiKey, ApiSettings

    check = opcua_users(
        ApiSettings(
            api_keys=(
                ApiKey(user="ann", role="operator", key="ann-key-0123456789"),
                ApiKey(user="vic", role="viewer", key="vic-key-0123456789"),
            )
        )
    )
    assert check("ann", "ann-key-0123456789") == 2  # operator
    assert check("vic", "vic-key-0123456789") == 1  # viewer
    assert check("vic", "ann-key-0123456789") is None  # another user's key
    assert check("ann", "wrong-key-000000000") is None
    # what a machine in its own process gets over the DNC port: digests, never the keys
    records = check.records()
    assert [(u.user, u.role, u.role_level) for u in records] == [
        ("ann", "operator", 2),
        ("vic", "viewer", 1),
    ]
    assert records[0].key_sha256 == hashlib.sha256(b"ann-key-0123456789").hexdigest()
    assert "ann-key-0123456789" not in repr(records)


class AuditingLibrary(Library):
    def __init__(self) -> None:
        self.notes: list[tuple] = []

    def note_transfer(self, machine, action, *, actor="dnc", **detail):
        self.notes.append((machine, action, actor, detail))


class HostPort:
    """A machine's DNC port as the feed's client sees it (HOST PUT), or one that is down."""

    def __init__(self, commands=None, down: str = "") -> None:
        self.commands, self.down, self.docs = commands or [], down, []

    def __enter__(self):
        if self.down:
            raise ConnectionRefusedError(self.down)
        return self

    def __exit__(self, *exc):
        return False

    def host_data(self, doc):
        self.docs.append(doc)
        commands, self.commands = self.commands, []
        return {"commands": commands}


def test_the_feed_sends_each_machine_its_data_and_audits_what_its_clients_did():
    from server.opcua_feed import OpcUaFeed

    calls = [
        {"user": "ann", "command": "cycle_start", "result": "done", "detail": "Start"},
        {"user": "vic", "command": "call", "result": "BadUserAccessDenied", "detail": "vic"},
    ]
    ports = {"mill1": HostPort(calls), "mill2": HostPort(down="connection refused")}
    links = {name: NS(ports={"opcua": 4841 + i}, local=None) for i, name in enumerate(ports)} | {
        "lathe1": NS(ports={"opcua": None}, local=None)
    }  # no OPC UA face: nothing sent
    library = AuditingLibrary()
    from cnc.faces.opcua import FaceUser

    users = (FaceUser("ann", "operator", "d" * 64),)
    feed = OpcUaFeed(
        library, Dispatches(), Jobs(), links, client=lambda name: ports[name], users=lambda: users
    )
    feed.tick()
    sent = ports["mill1"].docs[0]
    assert sent["programs"] == {"O0100": {"revision": "7", "sha256": "a" * 64}}
    assert [j["identifier"] for j in sent["jobs"]] == ["job3"]
    assert sent["users"] == [{"user": "ann", "role": "operator", "key_sha256": "d" * 64}]
    assert library.notes == [
        (
            "mill1",
            "machine.command",
            "ann",
            {"command": "cycle_start", "face": "opcua", "detail": "Start"},
        ),
        (
            "mill1",
            "machine.command_refused",
            "vic",
            {"command": "call", "face": "opcua", "detail": "vic", "reason": "BadUserAccessDenied"},
        ),
    ]
    assert feed.unreachable == {"mill2": "connection refused"}  # tried again next tick
    feed.tick()
    assert len(ports["mill1"].docs) == 2 and len(library.notes) == 2


def test_a_machine_in_this_process_gets_its_data_by_a_direct_call():
    from cnc.faces.opcua import FaceCommand
    from server.opcua_feed import OpcUaFeed

    class Face:
        data = None

        def set_host_data(self, data):
            self.data = data

        def take_commands(self):
            return [FaceCommand("ann", "acknowledge", "done", "alarm 3040 (DRIVE)", 1.0)]

    face = Face()
    links = {"mill1": NS(ports={"opcua": 4841}, local=NS(opcua=face))}
    library = AuditingLibrary()

    def no_client(name):
        raise AssertionError("no DNC exchange for a machine in this process")

    OpcUaFeed(library, Dispatches(), Jobs(), links, client=no_client).tick()
    assert face.data.revision_by_program == {"O0100": "7"}
    assert library.notes == [
        (
            "mill1",
            "machine.command",
            "ann",
            {"command": "acknowledge", "face": "opcua", "detail": "alarm 3040 (DRIVE)"},
        )
    ]


def test_the_run_banner_names_each_machines_opcua_endpoint():
    """`fmscell run` prints where each machine's OPC UA server is (server/cell.py)."""
    from server.cell import banner  # deferred: server.cell pulls in the whole host

    lines = banner(
        ("mill1", "lathe1", "mill2"),
        "realtime",
        "http://127.0.0.1:8000",
        {"mill1": "opc.tcp://127.0.0.1:4841", "mill2": "opc.tcp://127.0.0.1:4843"},
    )
    assert lines[0] == "fmscell cell: mill1, lathe1, mill2 (realtime clock)"
    assert "MTConnect:      http://127.0.0.1:8000/mtconnect/probe" in lines
    assert lines[-2:] == [
        "OPC UA mill1:   opc.tcp://127.0.0.1:4841",
        "OPC UA mill2:   opc.tcp://127.0.0.1:4843",
    ]  # lathe1's OPC UA face is off: no line
