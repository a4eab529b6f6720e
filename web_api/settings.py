"""The REST API's settings: API keys with roles, the insecure-open demo mode, limits.

Roles are ordered: viewer < operator < programmer < admin. Viewers read; dispatches, jobs
and machine commands need an operator; uploads and releases need a programmer; fault
injection needs an admin. A key is configured either in clear (`key`) or as its sha256
(`key_sha256`), so a configuration file need not hold usable secrets.

`ApiKey` is declared once, here: the cell file's `host.auth.api_keys[]` entries
(web_api/config.py, with the file, line and column of each problem) and the app's
`ApiSettings.api_keys` are the same model.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Mapping
from enum import IntEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator
from pydantic_core import PydanticCustomError

from cnc.config import Section


class Role(IntEnum):
    viewer = 1
    operator = 2
    programmer = 3
    admin = 4


class ApiKey(Section):
    """One REST API key (`host.auth.api_keys[]`): who uses it, with which role.

    Exactly one of `key` and `key_sha256` is given; the section's owner checks that
    (`secret_problem()`): the cell file reports it at the entry with the others found,
    `ApiSettings` refuses it."""

    user: str = Field(min_length=1, max_length=64, description="Who uses the key (audit).")
    role: Role = Field(
        description="`viewer` reads; `operator` dispatches, runs jobs, commands machines;"
        " `programmer` uploads and releases; `admin` injects faults."
    )
    key: str | None = Field(None, min_length=16, description="The key in clear (>= 16 chars).")
    key_sha256: str | None = Field(
        None,
        pattern=r"^[0-9a-f]{64}$",
        description="Or the key's sha256 in hex (`sha256sum` of the key without a newline):"
        " no usable secret in the file.",
    )

    @field_validator("role", mode="before")
    @classmethod
    def _role_by_name(cls, value: Any) -> Any:
        """A role is written by its name (a Role is taken as it is); any other is refused
        in the words of a Literal (the cell file says "must be one of ...")."""
        if isinstance(value, Role):
            return value
        if not isinstance(value, str) or value not in Role.__members__:
            expected = "'viewer', 'operator', 'programmer' or 'admin'"
            raise PydanticCustomError(
                "literal_error", "Input should be {expected}", {"expected": expected}
            )
        return Role[value]

    def secret_problem(self) -> str | None:
        """Why the key's secret is not usable (None: exactly one of key, key_sha256)."""
        if (self.key is None) == (self.key_sha256 is None):
            return f"api key of {self.user!r}: give exactly one of key, key_sha256"
        return None

    def digest(self) -> str:
        return self.key_sha256 or hashlib.sha256((self.key or "").encode()).hexdigest()


class Principal(BaseModel):
    """Who is calling: the key's user and role (or the anonymous admin of insecure-open)."""

    user: str
    role: Role


class ApiSettings(BaseModel):
    """Settings of the REST API (the cell file's `host.auth` section, web_api/config.py,
    gives `api_keys`, `insecure_open` and the failed-authentication limit; the other limits
    are the app's own)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    api_keys: tuple[ApiKey, ...] = ()
    insecure_open: bool = Field(
        default=False,
        description="demo mode: no key needed, every caller is an admin named 'anonymous'",
    )
    auth_failures_max: int = Field(
        default=10,
        ge=1,
        description="failed authentications (unknown keys) per client address within "
        "auth_failures_window_s before its requests get 429 with Retry-After",
    )
    auth_failures_window_s: float = Field(default=10.0, gt=0, le=3600)
    upload_limit_bytes: int = Field(default=16 * 1024 * 1024, ge=1)
    events_poll_s: float = Field(default=0.25, gt=0, le=10)
    events_keepalive_s: float = Field(default=15.0, ge=0, le=300)
    events_ring_size: int = Field(
        default=4096,
        ge=500,
        le=1_000_000,
        description="newest events the event hub keeps in memory; clients further behind "
        "read the gap from the database",
    )
    events_ring_age_s: float = Field(
        default=300.0,
        gt=0,
        le=86_400,
        description="the event hub keeps no event in memory longer than this (seconds): a "
        "quiet cell's ring is full, and the memory flat, after this long instead of hours; "
        "a client reconnecting later reads the gap from the database",
    )
    events_fanout: Literal["hub", "poll"] = Field(
        default="hub",
        description="hub: one outbox reader per process feeds every stream client; poll: "
        "each client polls the outbox itself (the old way, kept as the benchmark's peer)",
    )
    page_limit_max: int = Field(default=500, ge=1, le=10_000)
    problem_base: str = "https://fmscell.dev/problems/"

    @model_validator(mode="after")
    def _usable_keys(self) -> ApiSettings:
        for k in self.api_keys:
            if (problem := k.secret_problem()) is not None:
                raise ValueError(problem)
        digests = [k.digest() for k in self.api_keys]
        if len(set(digests)) != len(digests):
            raise ValueError("two api_keys entries have the same key")
        return self

    @property
    def request_body_limit(self) -> int:
        """Largest request body read at all: JSON escaping and multipart framing need room."""
        return 2 * self.upload_limit_bytes + 64 * 1024

    def authenticate(self, presented: str) -> Principal | None:
        """The principal owning `presented`, compared in constant time; None if unknown."""
        digest = hashlib.sha256(presented.encode("utf-8", "surrogatepass")).hexdigest()
        found = None
        for k in self.api_keys:
            if hmac.compare_digest(digest, k.digest()):
                found = Principal(user=k.user, role=k.role)
        return found

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any] | None) -> ApiSettings:
        """Settings from a mapping of these fields, or from the cell file's typed `host.auth`
        (web_api.config.AuthConfig); a ValidationError names the key."""
        if hasattr(data, "api_settings"):
            return data.api_settings()
        return cls.model_validate(dict(data or {}))
