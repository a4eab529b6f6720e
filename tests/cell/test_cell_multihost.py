"""A cell that spans hosts (issue 18 item 6): two `fmscell machine` processes, each in a
network namespace of its own (the test's hosts, joined to this one by veth pairs on
private subnets), and a host here that attaches to them over those addresses
(`fmscell run --attach`), publishes to a Mosquitto of the test's own and serves REST,
MTConnect and the machines' OPC UA addresses. One machine's process is killed while it
cuts: the host reports it UNAVAILABLE in REST, MTConnect and MQTT, its OPC UA endpoint
stops answering, and its part is made again on the other machine.

Skipped where network namespaces cannot be made (not root, no iproute2, a container
without CAP_SYS_ADMIN); every namespace and veth is deleted at the end, whatever failed.
"""

from __future__ import annotations

import asyncio
import json
import os
import secrets
import signal
import subprocess
import sys
import uuid
import xml.etree.ElementTree as ET
from datetime import UTC, datetime

import pytest

from server.cell import Cell
from server.config import load_cell_config
from tests.cell.conftest import Api, poll, serve, upload_released
from tests.cell.netns import Namespaces, why_not_permitted
from tests.cell.test_cell_restart import RESTART_PROGRAM
from tests.server.mqtt_support import PrivateBroker, Subscriber

# some 80 s at load 20 (machine processes with OPC UA starting, three parts in real time):
# kept out of `make test` with the soak tests (`make soak`, or `pytest -m soak`)
pytestmark = [
    pytest.mark.soak,
    pytest.mark.skipif(not PrivateBroker.available(), reason="mosquitto is not installed"),
    pytest.mark.timeout(300),
]

# the same faces on every host (each namespace has its own port space)
PORTS = {"dnc": 7001, "modbus": 5021, "shdr": 7878, "opcua": 4841, "simulation": None}
NAMES = ("milla", "millb")
READY_S = 120  # a machine process: interpreter, OPC UA server, power-on, on a box at load 20


@pytest.fixture
def hosts():
    # asked when the test runs, not at collection: a run that deselects it makes none
    why = why_not_permitted()
    if why is not None:
        pytest.skip(f"no network namespaces: {why}")
    ns = Namespaces()
    try:
        yield [ns.add(), ns.add()]
    finally:
        failures = ns.close()
        assert not failures, failures


@pytest.fixture
def machines(hosts, tmp_path):
    """`fmscell machine --bind <its address>` in each namespace, homed, faces up."""
    cell_file = tmp_path / "machines.yaml"
    # each machine's faces on its own host's address (the same ports on two addresses)
    ports = {n: {**PORTS, "host": h.address} for n, h in zip(NAMES, hosts, strict=True)}
    cell_file.write_text(
        json.dumps({"machines": {n: {"base": "mill3", "ports": ports[n]} for n in NAMES}})
    )
    made = {}
    try:
        for name, host in zip(NAMES, hosts, strict=True):
            secret = secrets.token_urlsafe(24)
            ready = tmp_path / f"{name}.ready.json"
            log = open(tmp_path / f"{name}.log", "wb")  # noqa: SIM115 - closed below
            cmd = [sys.executable, "-m", "server.cli", "machine", "--config", str(cell_file)]
            cmd += ["--name", name, "--bind", host.address, "--ideal", "--power-on"]
            cmd += ["--no-simulation", "--ready-file", str(ready)]
            proc = subprocess.Popen(
                host.command(*cmd),
                env={**os.environ, "FMSCELL_MACHINE_SECRET": secret},
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
            )
            log.close()
            made[name] = (proc, host, secret, ready)
        for name, (proc, _, _, ready) in made.items():
            poll(
                lambda proc=proc, ready=ready: ready.exists() or proc.poll() is not None,
                READY_S,
                f"{name} ready",
                0.1,
            )
            assert proc.poll() is None, (tmp_path / f"{name}.log").read_text()[-2000:]
        yield made
    finally:
        for proc, *_ in made.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(10)


def _opcua_namespaces(url: str) -> list[str]:
    from asyncua import Client

    async def read() -> list[str]:
        client = Client(url, timeout=5)
        await client.connect()
        try:
            return await client.get_namespace_array()
        finally:
            await client.disconnect()

    return asyncio.run(asyncio.wait_for(read(), 20))


def _availability(xml: str) -> dict[str, str]:
    """Each device's Availability in an MTConnect current document."""
    out = {}
    for device in ET.fromstring(xml).iter():
        if device.tag.endswith("DeviceStream"):
            for el in device.iter():
                if el.tag.endswith("Availability"):
                    out[device.get("name")] = el.text
    return out


def test_a_host_attached_to_machines_on_two_other_hosts_reroutes_a_lost_machines_part(
    hosts, machines, tmp_path
):
    broker = PrivateBroker(tmp_path)
    broker.start()
    prefix, root = f"test-{uuid.uuid4().hex[:8]}", None
    config = load_cell_config(
        {
            "machines": {
                name: {
                    "base": "mill3",
                    "ports": {**PORTS, "host": host.address, "secret": secret},
                }
                for name, (_, host, secret, _) in machines.items()
            },
            "host": {
                "lost_contact_s": 3.0,
                "mqtt": {"broker": f"127.0.0.1:{broker.port}", "prefix": prefix, "cell_id": "mh"},
            },
        }
    )
    root = f"{prefix}/mh"
    sub = Subscriber("127.0.0.1", broker.port, [f"{root}/#"])
    cell = Cell(
        config, clock="fast", database_url=f"sqlite:///{tmp_path}/host.db", attach=True
    ).start(ready_timeout_s=READY_S)
    server, thread, sock = serve(cell)
    api = Api(f"http://127.0.0.1:{sock.getsockname()[1]}")
    try:
        assert cell.machines == []  # the host started none: they run on the other hosts
        # --- both machines seen over their own addresses, on every face
        for name, (_, host, _, _) in machines.items():
            m = api("viewer").get(f"/api/machines/{name}").json()
            assert m["dnc_address"] == f"{host.address}:7001"
            assert m["opcua_address"] == f"opc.tcp://{host.address}:4841"
            assert m["status"]["availability"] == "AVAILABLE", m["status"]
            assert f"urn:fmscell:machine:{name}" in _opcua_namespaces(m["opcua_address"])
        probe = ET.fromstring(api("viewer").get("/mtconnect/probe").text)
        devices = {d.get("name") for d in probe.iter() if d.tag.endswith("}Device")}
        assert set(NAMES) <= devices, devices
        current = api("viewer").get("/mtconnect/current").text
        assert _availability(current) == dict.fromkeys(NAMES, "AVAILABLE")
        sub.wait_for(
            lambda ms: all(
                (sub.last(f"{root}/{n}/availability") or {}).get("value") == "AVAILABLE"
                for n in NAMES
            ),
            30,
            what="both machines AVAILABLE on the broker",
        )

        # --- a job of three parts: both machines cut, then millb's host loses its machine
        rev = upload_released(api, RESTART_PROGRAM)
        job = api("operator").post("/api/jobs", json={"revision_id": rev, "quantity": 3})
        assert job.status_code == 201, job.text
        job = job.json()["id"]

        def cutting(name):
            return api("viewer").get(f"/api/machines/{name}").json()["status"]["execution"]

        poll(lambda: cutting("millb") == "ACTIVE", 60, "millb cutting", 0.02)
        proc = machines["millb"][0]
        proc.kill()  # the machine's process dies mid-part (its host is still up)
        proc.wait(10)
        killed_at = datetime.now(UTC)

        def unavailable():
            s = api("viewer").get("/api/machines/millb").json()["status"]
            return s["availability"] == "UNAVAILABLE" and s

        poll(unavailable, 30, "millb UNAVAILABLE in REST")
        poll(
            lambda: (
                _availability(api("viewer").get("/mtconnect/current").text).get("millb")
                == "UNAVAILABLE"
            ),
            30,
            "millb UNAVAILABLE in MTConnect",
        )
        assert _availability(api("viewer").get("/mtconnect/current").text)["milla"] == "AVAILABLE"
        sub.wait_for(
            lambda ms: (
                (sub.last(f"{root}/millb/availability") or {}).get("value") == "UNAVAILABLE"
                and (sub.last(f"{root}/millb/state") or {}).get("value") == "offline"
            ),
            30,
            what="millb UNAVAILABLE and offline on the broker",
        )
        assert (sub.last(f"{root}/status") or {}).get("status") == "ONLINE"  # the cell lives
        with pytest.raises((OSError, asyncio.TimeoutError)):  # its endpoint is gone
            _opcua_namespaces(f"opc.tcp://{hosts[1].address}:4841")

        # --- its part is made again on milla; the job completes with each part made once
        def completed():
            j = api("viewer").get(f"/api/jobs/{job}").json()
            return j["status"] == "completed" and j

        done = poll(completed, 120, "the job completed on milla", interval_s=0.2)
        lost = [a for a in done["allocations"] if a["machine"] == "millb"]
        assert [a["status"] for a in lost] == ["rerouted"], done["allocations"]
        rerouted_to = next(a for a in done["allocations"] if a["id"] == lost[0]["rerouted_to"])
        assert (rerouted_to["machine"], rerouted_to["status"]) == ("milla", "completed")
        [lost_at] = [
            datetime.fromisoformat(d["at"])
            for d in done["decisions"]
            if d["action"] == "interrupt" and "contact with millb lost" in d["reason"]
        ]
        # given up no sooner than the contact time-out allows, and not long after it
        assert (
            config.host.lost_contact_s
            <= (lost_at - killed_at).total_seconds()
            <= config.host.lost_contact_s + 30
        )
        milla = api("viewer").get("/api/machines/milla").json()["status"]
        assert milla["counters"]["part_count"] == 3 and done["done"] == 3
    finally:
        api.close()
        server.should_exit = True
        thread.join(20)
        sock.close()
        cell.stop()
        sub.close()
        broker.stop()
