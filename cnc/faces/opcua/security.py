"""Who may do what on the OPC UA face, and its secured endpoint.

Anonymous sessions and viewers read, browse and subscribe; writes and method calls need an
operator or above (BadUserAccessDenied otherwise), the roles being the cell's
(web_api.settings.Role). With security on, the endpoint is Basic256Sha256 sign-and-encrypt
with a self-signed certificate made at first start, and only trusted, unexpired client
certificates are accepted.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

from asyncua import Server, ua
from asyncua.crypto.permission_rules import PermissionRuleset, User, UserRole

log = logging.getLogger(__name__)

# roles of the cell (web_api.settings.Role): viewer < operator < programmer < admin
VIEWER, OPERATOR = 1, 2

_READ_SERVICES = frozenset(
    ua.NodeId(i)
    for i in (
        ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary,
        ua.ObjectIds.CloseSessionRequest_Encoding_DefaultBinary,
        ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary,
        ua.ObjectIds.ReadRequest_Encoding_DefaultBinary,
        ua.ObjectIds.BrowseRequest_Encoding_DefaultBinary,
        ua.ObjectIds.BrowseNextRequest_Encoding_DefaultBinary,
        ua.ObjectIds.GetEndpointsRequest_Encoding_DefaultBinary,
        ua.ObjectIds.FindServersRequest_Encoding_DefaultBinary,
        ua.ObjectIds.TranslateBrowsePathsToNodeIdsRequest_Encoding_DefaultBinary,
        ua.ObjectIds.CreateSubscriptionRequest_Encoding_DefaultBinary,
        ua.ObjectIds.ModifySubscriptionRequest_Encoding_DefaultBinary,
        ua.ObjectIds.DeleteSubscriptionsRequest_Encoding_DefaultBinary,
        ua.ObjectIds.CreateMonitoredItemsRequest_Encoding_DefaultBinary,
        ua.ObjectIds.ModifyMonitoredItemsRequest_Encoding_DefaultBinary,
        ua.ObjectIds.DeleteMonitoredItemsRequest_Encoding_DefaultBinary,
        ua.ObjectIds.PublishRequest_Encoding_DefaultBinary,
        ua.ObjectIds.RepublishRequest_Encoding_DefaultBinary,
        ua.ObjectIds.CloseSecureChannelRequest_Encoding_DefaultBinary,
        ua.ObjectIds.SetMonitoringModeRequest_Encoding_DefaultBinary,
        ua.ObjectIds.SetPublishingModeRequest_Encoding_DefaultBinary,
        ua.ObjectIds.RegisterNodesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.UnregisterNodesRequest_Encoding_DefaultBinary,
    )
)
_WRITE = ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
_CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
_OPERATOR_SERVICES = _READ_SERVICES | {_WRITE, _CALL}

#: the user of the request being served: the permission check sets it and the method
#: callbacks that follow in the same task read it (asyncua does not pass the session)
_CALLER: ContextVar[str] = ContextVar("opcua_caller", default="anonymous")


def caller() -> str:
    """The user name of the session whose request is being served."""
    return _CALLER.get()


@dataclass
class CellUser(User):
    """An OPC UA session's user with the cell role (1 viewer .. 4 admin) it maps to."""

    cell_role: int = VIEWER


class CellRoles(PermissionRuleset):
    """Anonymous and viewers read, browse and subscribe; writes and method calls
    (Start, Stop, Acknowledge) need an operator or above: BadUserAccessDenied otherwise.
    `on_denied(user, "write" | "call")` hears each refused write or call (the audit)."""

    def __init__(self, on_denied: Callable[[str, str], None] | None = None) -> None:
        self.on_denied = on_denied

    def check_validity(self, user, action_type_id, body) -> bool:
        role = getattr(user, "cell_role", VIEWER)
        name = getattr(user, "name", None) or "anonymous"
        _CALLER.set(name)
        allowed = _OPERATOR_SERVICES if role >= OPERATOR else _READ_SERVICES
        ok = action_type_id in allowed
        if not ok and self.on_denied is not None and action_type_id in (_WRITE, _CALL):
            self.on_denied(name, "write" if action_type_id == _WRITE else "call")
        return ok


class CellUsers:
    """asyncua user manager: anonymous -> viewer; user name + password -> the role
    `authenticate` gives (the cell's API keys: user name = the key's user, password = the
    key); unknown -> refused (BadUserAccessDenied)."""

    def __init__(
        self, authenticate: Callable[[str, str], int | None] | None, anonymous: bool
    ) -> None:
        self.authenticate = authenticate
        self.anonymous = anonymous

    def get_user(self, iserver, username=None, password=None, certificate=None):
        if username is None:
            if not self.anonymous:
                return None
            return CellUser(role=UserRole.Anonymous, name="anonymous", cell_role=VIEWER)
        role = self.authenticate(username, password or "") if self.authenticate else None
        if role is None:
            return None
        return CellUser(role=UserRole.User, name=username, cell_role=int(role))


@dataclass(frozen=True)
class Security:
    """Sign-and-encrypt (Basic256Sha256) with a self-signed certificate made in `cert_dir`
    at first start; client certificates must be in `trusted_dir` (unknown or expired ones
    are refused); anonymous sessions refused unless `anonymous`."""

    cert_dir: Path
    trusted_dir: Path
    authenticate: Callable[[str, str], int | None] | None = None
    anonymous: bool = False


async def secure_endpoint(
    server: Server, sec: Security, machine: str, roles: CellRoles | None = None
) -> None:
    from asyncua.crypto.cert_gen import generate_private_key, generate_self_signed_app_certificate
    from asyncua.crypto.truststore import TrustStore
    from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    sec.cert_dir.mkdir(parents=True, exist_ok=True)
    cert_path = sec.cert_dir / f"{machine}-opcua.der"
    key_path = sec.cert_dir / f"{machine}-opcua-key.pem"
    uri = f"urn:fmscell:{machine}"
    if not cert_path.exists() or not key_path.exists():
        key = generate_private_key()
        cert = generate_self_signed_app_certificate(
            key,
            f"fmscell {machine}",
            {"commonName": f"fmscell {machine}"},
            _san(uri),
            extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
        )
        key_path.write_bytes(
            key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.TraditionalOpenSSL,
                serialization.NoEncryption(),
            )
        )
        key_path.chmod(0o600)
        cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    await server.load_certificate(str(cert_path))
    await server.load_private_key(str(key_path))
    server.set_security_policy(
        [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt], roles or CellRoles()
    )
    tokens = [ua.UserNameIdentityToken]
    if sec.anonymous:
        tokens.append(ua.AnonymousIdentityToken)
    server.set_identity_tokens(tokens)
    sec.trusted_dir.mkdir(parents=True, exist_ok=True)
    if not any(p.is_file() for p in sec.trusted_dir.iterdir()):
        # asyncua cannot build an empty trust store; no trusted certificate means every
        # client is unknown, so the face serves and refuses each secured session
        log.warning(
            "OPC UA %s: no trusted client certificates in %s: every session is refused"
            " until one is copied there and the machine restarted",
            machine,
            sec.trusted_dir,
        )
        server.set_certificate_validator(_refuse_all)
        return
    store = TrustStore([sec.trusted_dir], [])
    await store.load()
    validator = CertificateValidator(
        CertificateValidatorOptions.TIME_RANGE
        | CertificateValidatorOptions.TRUSTED
        | CertificateValidatorOptions.PEER_CLIENT,
        store,
    )
    server.set_certificate_validator(validator)


async def _refuse_all(certificate, app_description) -> None:
    from asyncua.common.utils import ServiceError

    raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)


def _san(uri: str):
    from cryptography import x509

    return [x509.UniformResourceIdentifier(uri), x509.DNSName("localhost")]
