"""The REST API's keys of the cell file's `host` section: where it listens (`bind`, `port`,
`tls`) and who may call it (`auth`: API keys with roles, the failed-authentication limit,
the insecure-open demo mode). docs/configuration.md lists every key; server/config.py
composes them with the DNC host's keys into `host`.

web_api owns these keys: their schema (pydantic sections, strict) and their rules
(`problems()`); `AuthConfig.api_settings()` gives the app's `ApiSettings`.
"""

from __future__ import annotations

from pydantic import Field

from cnc.config import Port, Problem, Section, within
from web_api.settings import ApiKey, ApiSettings

__all__ = ["ApiConfig", "ApiKey", "AuthConfig", "TlsConfig"]

_DEFAULTS = ApiSettings()


class AuthConfig(Section):
    """REST API authentication (`host.auth`)."""

    api_keys: list[ApiKey] = Field(
        default_factory=list,
        description="API keys, each `{user, role, key}` or `{user, role, key_sha256}`.",
    )
    insecure_open: bool = Field(
        False,
        description="Demo only: no key checked, every caller is an admin (as `--insecure-open`).",
    )
    failures_max: int = Field(
        _DEFAULTS.auth_failures_max,
        ge=1,
        description="Failed authentications (unknown keys) one client address may make within"
        " `failures_window_s` before its requests get 429 with Retry-After.",
    )
    failures_window_s: float = Field(
        _DEFAULTS.auth_failures_window_s,
        gt=0,
        le=3600,
        description="The window of `failures_max`, seconds.",
    )

    def problems(self) -> list[Problem]:
        out: list[Problem] = []
        digests: dict[str, int] = {}
        for i, k in enumerate(self.api_keys):
            where = ("api_keys", i)
            if (problem := k.secret_problem()) is not None:
                out.append((where, problem))
                continue
            digest = k.digest()
            if digest in digests:
                out.append((where, f"the same key as api_keys[{digests[digest]}]"))
            digests.setdefault(digest, i)
        return out

    def api_settings(self) -> ApiSettings:
        """The REST app's settings for this section (its limits otherwise the app's own)."""
        return ApiSettings.from_mapping(
            {
                "api_keys": tuple(self.api_keys),  # the same model: taken as they are
                "insecure_open": self.insecure_open,
                "auth_failures_max": self.failures_max,
                "auth_failures_window_s": self.failures_window_s,
            }
        )


class TlsConfig(Section):
    """HTTPS for the REST API and dashboard (`host.tls`)."""

    cert: str = Field(
        min_length=1, description="PEM certificate (chain) file (relative to the cell file)."
    )
    key: str = Field(min_length=1, description="PEM private key file (relative to the cell file).")


class ApiConfig(Section):
    """The REST API and dashboard (`host`: bind, port, auth, tls)."""

    bind: str = Field("127.0.0.1", min_length=1, description="REST/dashboard bind address.")
    port: Port = Field(8000, description="REST/dashboard TCP port.")
    auth: AuthConfig = Field(
        default_factory=AuthConfig, description="REST API keys (see `host.auth` below)."
    )
    tls: TlsConfig | None = Field(
        None, description="HTTPS certificate and key (see `host.tls`); null = plain HTTP."
    )

    def problems(self) -> list[Problem]:
        return within(("auth",), self.auth.problems())
