"""The OPC UA face of a machine in its own process (`fmscell machine`), with a host that
started it: what only the host knows (the dispatched revision and its sha256, the cell's
jobs on the machine) reaches the face through the machine's DNC port (`HOST PUT`,
authenticated with the port's secret), and what the face's clients did comes back into the
host's audit log. A real asyncua client reads it over opc.tcp."""

from __future__ import annotations

import contextlib

import pytest
from asyncua import Client, ua
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

from cnc.faces.loop_thread import LoopThread
from server.cell import Cell, opcua_users
from server.config import load_cell_config
from tests.cell.conftest import Api, poll, serve, upload_released
from tests.cell.test_cell_restart import RESTART_PROGRAM
from tests.cnc.test_opcua_security import client_cert
from web_api.settings import ApiKey, ApiSettings

# a machine process, an asyncua server start and a part on a box at load 30
pytestmark = pytest.mark.timeout(300)


# in-process is what `fmscell run` (the README's default cell) does; machine processes are
# `fmscell run --processes` and a host attached to `fmscell machine`s
@pytest.mark.parametrize("processes", [True, False], ids=["machine-process", "in-process"])
def test_a_machine_serves_the_hosts_revision_and_jobs_and_the_host_audits_it(tmp_path, processes):
    ports = {"host": "127.0.0.1", "dnc": 0, "modbus": 0, "shdr": 0, "opcua": 0}
    config = load_cell_config({"machines": {"mill1": {"base": "mill3", "ports": ports}}})
    cell = Cell(
        config,
        clock="fast",
        database_url=f"sqlite:///{tmp_path}/cell.db",
        processes=processes,
        ideal_axes=True,
        state_dir=tmp_path,
    ).start()
    server, thread, sock = serve(cell)
    api = Api(f"http://127.0.0.1:{sock.getsockname()[1]}")
    loop = LoopThread("opcua-cell-client").start()
    client = None
    try:
        link = cell.links["mill1"]
        if processes:
            assert link.local is None and link.ports["opcua"]  # a process of its own
        else:
            assert link.local is not None  # the machine runs in the host's process
        # port 0 asked for any free port: the API names the one bound
        url = api("viewer").get("/api/machines/mill1").json()["opcua_address"]
        assert url == cell.opcua_addresses()["mill1"]
        assert url.startswith("opc.tcp://127.0.0.1:") and not url.endswith(":0")
        # asyncua's default probe calls a session lost after one answer slower than 1 s
        client = Client(url, timeout=30, watchdog_intervall=30.0)
        loop.run(client.connect, timeout=60)
        ns = loop.run(lambda: client.get_namespace_index("urn:fmscell:machine:mill1"))

        def read(key: str):
            async def go():
                return await client.get_node(ua.NodeId(f"mill1.{key}", ns)).read_value()

            return loop.run(go)

        rev = upload_released(api, RESTART_PROGRAM)
        sha = cell.library.get_revision(rev).sha256
        # many parts: with the fast clock and ideal axes a short job can end between two of
        # the host's once-a-second feeds, and its node with it
        job = api("operator").post("/api/jobs", json={"revision_id": rev, "quantity": 50})
        assert job.status_code == 201, job.text
        job_id = job.json()["id"]

        plan = f"Production.ProductionPlan.job{job_id}"

        def running_with_the_hosts_data():
            if read("Production.ActiveProgram.Name") != "O1001":
                return False
            if read("Production.ActiveProgram.Revision") != str(rev):
                return False
            try:  # the job's node comes with the same host data, built a moment later
                read(f"{plan}.RunsPlanned")
            except ua.uaerrors.BadNodeIdUnknown:
                return False
            return True

        poll(running_with_the_hosts_data, 120, "the dispatched revision and job on the face", 0.1)
        assert read("Production.ActiveProgram.Sha256") == sha
        assert read(f"{plan}.RunsPlanned") == 50
        assert read(f"{plan}.Identifier") == f"job{job_id}"
        assert read(f"{plan}.ProductionPrograms.O1001.Name") == "O1001"
        assert read(f"{plan}.State.CurrentState").Text in ("Initializing", "Running")
        assert read("Production.ActiveProgram.JobIdentifier") == f"job{job_id}"
        assert read("Production.ActiveProgram.JobNodeId") == ua.NodeId(f"mill1.{plan}", ns)

        # an anonymous client tries Start: refused on the face, audited by the host with
        # who asked (the call travelled back over the DNC port's HOST exchange)
        async def start():
            channel = client.get_node(ua.NodeId("mill1.Monitoring.Channel1", ns))
            fms = await client.get_namespace_index("urn:fmscell:opcua")
            await channel.call_method(ua.QualifiedName("Start", fms))

        with pytest.raises(ua.uaerrors.BadUserAccessDenied):
            loop.run(start)

        def audited():
            return [
                e
                for e in cell.library.audit(entity="machine")
                if e["action"] == "machine.command_refused" and e["detail"].get("face") == "opcua"
            ]

        entry = poll(audited, 30, "the refused call in the host's audit log")[-1]
        assert entry["actor"] == "anonymous"
        assert entry["detail"]["command"] == "call"
        assert entry["detail"]["reason"] == "BadUserAccessDenied"
    finally:
        if client is not None:
            loop.run(client.disconnect)
        loop.stop()
        api.close()
        server.should_exit = True
        thread.join(20)
        sock.close()
        cell.stop()


OPS_KEY, VIEW_KEY = "ann-operator-key-0123456789", "vic-viewer-key-0123456789"


def test_a_machine_process_with_security_takes_the_hosts_users_and_roles(tmp_path):
    """A secured face in its own process has no user source of its own: the host sends
    the cell's API keys (user, role, sha256 of the key, never the key) with its data over
    the DNC port, so the cell's operator starts and stops the machine over OPC UA, a viewer
    only reads, and a key the host drops stops working at the next exchange."""
    trusted = tmp_path / "opcua" / "trusted"  # the machine process's state dir is tmp_path
    trusted.mkdir(parents=True)
    mine = client_cert(tmp_path, "client")
    (trusted / "client.der").write_bytes(mine[0].read_bytes())
    ports = {"host": "127.0.0.1", "dnc": 0, "modbus": 0, "shdr": 0, "opcua": 0}
    ports["opcua_security"] = "Basic256Sha256"
    config = load_cell_config({"machines": {"mill1": {"base": "mill3", "ports": ports}}})
    users = opcua_users(
        ApiSettings(
            api_keys=(
                ApiKey(user="ann", role="operator", key=OPS_KEY),
                ApiKey(user="vic", role="viewer", key=VIEW_KEY),
            )
        )
    )
    cell = Cell(
        config,
        clock="fast",
        database_url=f"sqlite:///{tmp_path}/cell.db",
        processes=True,
        ideal_axes=True,
        state_dir=tmp_path,
        opcua_users=users,
    ).start()
    loop = LoopThread("opcua-cell-client").start()
    sessions: list = []
    try:
        link = cell.links["mill1"]
        assert link.local is None  # a process of its own: its users come over the DNC port
        url = f"opc.tcp://127.0.0.1:{link.ports['opcua']}"
        assert "ann" not in (tmp_path / "fmscell-cell.yaml").read_text()  # not in its file

        def session(user: str, password: str) -> Client:
            client = Client(url, timeout=30, watchdog_intervall=30.0)
            client.application_uri = "urn:fmscell:test-client"

            async def go():
                await client.set_security(
                    SecurityPolicyBasic256Sha256,
                    str(mine[0]),
                    str(mine[1]),
                    mode=ua.MessageSecurityMode.SignAndEncrypt,
                )
                client.set_user(user)
                client.set_password(password)
                await client.connect()

            loop.run(go, timeout=60)
            sessions.append(client)
            return client

        def refused(user: str, password: str) -> str:
            """The status code (or error) the session was refused with; "" if opened."""
            try:
                session(user, password)
            except (ua.UaError, ConnectionError, TimeoutError, OSError) as exc:
                return type(exc).__name__
            return ""

        # the users arrive with the host's first exchange (within a second of start)
        ops = poll(lambda: not refused("ann", OPS_KEY) and sessions[-1], 60, "ann's session")
        viewer = session("vic", VIEW_KEY)
        # another user's key is not ann's password
        assert refused("ann", VIEW_KEY) == "BadUserAccessDenied"

        async def call(client: Client, method: str) -> None:
            ns = await client.get_namespace_index("urn:fmscell:machine:mill1")
            await client.get_node(ua.NodeId("mill1.Monitoring.Channel1", ns)).call_method(
                ua.NodeId(f"mill1.Monitoring.Channel1.{method}", ns)
            )

        async def feed_override(client: Client):
            ns = await client.get_namespace_index("urn:fmscell:machine:mill1")
            node = ua.NodeId("mill1.Monitoring.Channel1.FeedOverride", ns)
            return await client.get_node(node).read_value()

        assert loop.run(lambda: feed_override(viewer)) == 100.0
        with pytest.raises(ua.uaerrors.BadUserAccessDenied):
            loop.run(lambda: call(viewer, "Start"))
        loop.run(lambda: call(ops, "Stop"))  # feed hold: pressed at the machine's next cycle

        def audited():
            entries = [
                e
                for e in cell.library.audit(entity="machine")
                if e["detail"].get("face") == "opcua"
            ]
            done = [e for e in entries if e["action"] == "machine.command"]
            refused_calls = [e for e in entries if e["action"] == "machine.command_refused"]
            return (done, refused_calls) if done and refused_calls else None

        done, refused_calls = poll(audited, 30, "the calls in the host's audit log")
        assert (done[-1]["actor"], done[-1]["detail"]["command"]) == ("ann", "feed_hold")
        assert refused_calls[-1]["actor"] == "vic"
        assert refused_calls[-1]["detail"]["reason"] == "BadUserAccessDenied"

        # the host drops ann's key: her next session is refused, vic's still opens
        users.settings = ApiSettings(api_keys=(ApiKey(user="vic", role="viewer", key=VIEW_KEY),))
        poll(lambda: refused("ann", OPS_KEY), 60, "ann's key dropped on the machine")
        session("vic", VIEW_KEY)
    finally:
        for client in sessions:
            with contextlib.suppress(Exception):
                loop.run(client.disconnect)
        loop.stop()
        cell.stop()
