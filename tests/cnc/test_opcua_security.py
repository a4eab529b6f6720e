"""The OPC UA face with security on: Basic256Sha256 sign-and-encrypt, a generated server
certificate, trusted client certificates only (unknown and expired ones refused), user name
+ password mapped to the cell's roles (viewer reads, operator may write and call)."""

from __future__ import annotations

import asyncio
import datetime as dt
import time
from pathlib import Path

import pytest
from asyncua import Client, ua
from asyncua.crypto.cert_gen import generate_private_key, generate_self_signed_app_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from cnc.faces.opcua import OpcUaFace, Security
from cnc.status import Alarm, MachineStatus

USERS = {("ops", "operator-password-1234"): 2, ("view", "viewer-password-12345"): 1}
PRESSED: list[str] = []  # the panel buttons the face pressed (Start, Stop)
CLIENT_URI = "urn:fmscell:test-client"


def client_cert(folder: Path, name: str, *, expired: bool = False) -> tuple[Path, Path]:
    key = generate_private_key()
    if expired:
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
        now = dt.datetime.now(dt.UTC)
        cert = (
            x509.CertificateBuilder()
            .subject_name(subject)
            .issuer_name(subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(days=30))
            .not_valid_after(now - dt.timedelta(days=1))
            .add_extension(
                x509.SubjectAlternativeName([x509.UniformResourceIdentifier(CLIENT_URI)]),
                critical=False,
            )
            .sign(key, hashes.SHA256())
        )
    else:
        cert = generate_self_signed_app_certificate(
            key,
            name,
            {"commonName": name},
            [x509.UniformResourceIdentifier(CLIENT_URI)],
            extended=[ExtendedKeyUsageOID.CLIENT_AUTH],
        )
    cert_path, key_path = folder / f"{name}.der", folder / f"{name}.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.TraditionalOpenSSL,
            serialization.NoEncryption(),
        )
    )
    return cert_path, key_path


@pytest.fixture(scope="module")
def secured(tmp_path_factory):
    base = tmp_path_factory.mktemp("opcua")
    trusted = base / "trusted"
    trusted.mkdir()
    mine = client_cert(base, "client")
    (trusted / "client.der").write_bytes(mine[0].read_bytes())
    stale = client_cert(base, "stale", expired=True)
    (trusted / "stale.der").write_bytes(stale[0].read_bytes())
    stranger = client_cert(base, "stranger")
    face = OpcUaFace(
        "mill1",
        ("X", "Y", "Z"),
        security=Security(base / "server", trusted, authenticate=lambda u, p: USERS.get((u, p))),
        press=lambda button: PRESSED.append(button),
    )
    loop = asyncio.new_event_loop()
    loop.run_until_complete(face.start())
    yield loop, face, mine, stale, stranger
    loop.run_until_complete(face.stop())
    loop.close()


async def session(face, cert, user=None, password=None) -> Client:
    client = Client(face.address, timeout=15, watchdog_intervall=30.0)  # loaded box
    client.application_uri = CLIENT_URI
    await client.set_security(
        SecurityPolicyBasic256Sha256,
        str(cert[0]),
        str(cert[1]),
        mode=ua.MessageSecurityMode.SignAndEncrypt,
    )
    if user:
        client.set_user(user)
        client.set_password(password)
    await client.connect()
    return client


class Events:
    def __init__(self) -> None:
        self.events: list = []

    def event_notification(self, event) -> None:
        self.events.append(event)


async def until(predicate, what: str, timeout_s: float = 30.0) -> None:
    end = asyncio.get_running_loop().time() + timeout_s
    while not predicate():
        assert asyncio.get_running_loop().time() < end, f"not seen: {what}"
        await asyncio.sleep(0.02)


def test_a_viewer_reads_but_only_an_operator_acknowledges_an_alarm(secured):
    loop, face, mine, _, _ = secured

    async def run():
        viewer = await session(face, mine, "view", "viewer-password-12345")
        ops = await session(face, mine, "ops", "operator-password-1234")
        try:
            ns = await viewer.get_namespace_index("urn:fmscell:machine:mill1")
            node = viewer.get_node(ua.NodeId("mill1.Monitoring.Channel1.FeedOverride", ns))
            assert await node.read_value() == 100.0
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):  # a viewer never writes
                await node.write_value(ua.Variant(50.0, ua.VariantType.Double))
            seen = Events()
            sub = await ops.create_subscription(100, seen)
            await sub.subscribe_events(ops.nodes.server, ua.ObjectIds.AlarmConditionType)
            face.publish(
                MachineStatus(alarms=(Alarm(1012, "Following error X", axis="X"),)), time.time()
            )
            await until(lambda: seen.events, "the alarm event")
            event = seen.events[-1]
            ack = ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)
            args = (ua.Variant(event.EventId, ua.VariantType.ByteString), ua.LocalizedText("ok"))
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await viewer.get_node(event.NodeId).call_method(ack, *args)
            await ops.get_node(event.NodeId).call_method(ack, *args)
            await until(
                lambda: (
                    getattr(seen.events[-1], "AckedState", None) is not None
                    and seen.events[-1].AckedState.Text == "Acknowledged"
                ),
                "acknowledged",
            )
            with pytest.raises(ua.uaerrors.BadConditionBranchAlreadyAcked):
                await ops.get_node(event.NodeId).call_method(
                    ack,
                    ua.Variant(seen.events[-1].EventId, ua.VariantType.ByteString),
                    ua.LocalizedText("again"),
                )
            # reset clears it: inactive and acknowledged, it is no longer retained and its
            # condition node goes
            face.publish(MachineStatus(), time.time())
            await until(lambda: seen.events[-1].ActiveState.Text == "Inactive", "the cleared event")
            assert seen.events[-1].Retain is False
            with pytest.raises(ua.uaerrors.BadNodeIdUnknown):
                await ops.get_node(event.NodeId).read_browse_name()
        finally:
            await ops.disconnect()
            await viewer.disconnect()

    loop.run_until_complete(run())


def test_only_an_operator_starts_and_stops_and_every_call_is_kept_for_the_audit(secured):
    loop, face, mine, _, _ = secured
    face.take_commands()  # what earlier tests did

    async def run():
        viewer = await session(face, mine, "view", "viewer-password-12345")
        ops = await session(face, mine, "ops", "operator-password-1234")
        try:
            ns = await ops.get_namespace_index("urn:fmscell:machine:mill1")
            start, stop = (
                ua.NodeId(f"mill1.Monitoring.Channel1.{m}", ns) for m in ("Start", "Stop")
            )
            channel = ua.NodeId("mill1.Monitoring.Channel1", ns)
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await viewer.get_node(channel).call_method(start)
            assert PRESSED == []
            await ops.get_node(channel).call_method(start)
            await ops.get_node(channel).call_method(stop)
            assert PRESSED == ["cycle_start", "feed_hold"]
            # malformed calls: an argument Start does not take, an object that is not there
            with pytest.raises(ua.uaerrors.BadTooManyArguments):
                await ops.get_node(channel).call_method(start, ua.Variant(1, ua.VariantType.Int32))
            with pytest.raises((ua.uaerrors.BadNodeIdInvalid, ua.uaerrors.BadNodeIdUnknown)):
                await ops.get_node(ua.NodeId("mill1.Nowhere", ns)).call_method(start)
            assert PRESSED == ["cycle_start", "feed_hold"]
        finally:
            await ops.disconnect()
            await viewer.disconnect()

    PRESSED.clear()
    loop.run_until_complete(run())
    calls = [(c.user, c.command, c.result) for c in face.take_commands()]
    assert calls == [
        ("view", "call", "BadUserAccessDenied"),
        ("ops", "cycle_start", "done"),
        ("ops", "feed_hold", "done"),
        ("ops", "cycle_start", "BadTooManyArguments"),
    ]
    assert face.take_commands() == []  # taken once


@pytest.mark.parametrize(
    ("who", "status"),
    [
        ("wrong password", ua.uaerrors.BadUserAccessDenied),
        ("anonymous", ua.uaerrors.BadIdentityTokenRejected),
        ("stranger", ua.uaerrors.BadCertificateUntrusted),
        ("expired", ua.uaerrors.BadCertificateTimeInvalid),
    ],
)
def test_refused_sessions_say_why(secured, who, status):
    """Each refusal carries the status code that says why (docs/opcua.md), not just any
    error: the client can tell a wrong password from a certificate the server does not
    trust or one out of its validity."""
    loop, face, mine, stale, stranger = secured
    cert, user, password = {
        "wrong password": (mine, "ops", "not-the-password-000"),
        "anonymous": (mine, None, None),
        "stranger": (stranger, "ops", "operator-password-1234"),
        "expired": (stale, "ops", "operator-password-1234"),
    }[who]

    async def run():
        with pytest.raises(status):
            client = await session(face, cert, user, password)
            await client.disconnect()

    loop.run_until_complete(run())


def test_no_unencrypted_endpoint_is_offered_when_security_is_on(secured):
    loop, face, _, _, _ = secured

    async def run():
        client = Client(face.address, timeout=15)
        endpoints = await client.connect_and_get_server_endpoints()
        assert {e.SecurityMode for e in endpoints} == {ua.MessageSecurityMode.SignAndEncrypt}
        assert {e.SecurityPolicyUri for e in endpoints} == {
            "http://opcfoundation.org/UA/SecurityPolicy#Basic256Sha256"
        }

    loop.run_until_complete(run())


def test_with_no_trusted_certificate_the_face_serves_and_refuses_every_session(tmp_path):
    """An empty trust list (a machine just installed): the server starts (asyncua cannot
    load an empty trust store) and refuses each client as unknown."""
    mine = client_cert(tmp_path, "client")
    face = OpcUaFace(
        "mill1",
        ("X",),
        security=Security(
            tmp_path / "server", tmp_path / "trusted", authenticate=lambda u, p: USERS.get((u, p))
        ),
    )
    loop = asyncio.new_event_loop()
    try:
        loop.run_until_complete(face.start())

        async def run():
            with pytest.raises(ua.uaerrors.BadCertificateUntrusted):  # as docs/opcua.md says
                client = await session(face, mine, "ops", "operator-password-1234")
                await client.disconnect()

        loop.run_until_complete(run())
        assert (tmp_path / "trusted").is_dir()  # made, for the integrator to fill
    finally:
        loop.run_until_complete(face.stop())
        loop.close()
