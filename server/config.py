"""The cell file: the machines (each package's sections, composed by cnc.config) and the
host, composed here from the packages that own its keys. docs/configuration.md lists every
key; docs/architecture.md says how to add one.

    machines.<NAME>   cnc/config.py: the machine; its `drives`, `can` sections
                      drives/config.py, its `plc` section plc/config.py
    host              one flat section: database_url, lost_contact_s, dispatch_rule
                      (dnc/config.py); bind, port, auth, tls (web_api/config.py);
                      faults, mqtt (here)

Composition only: each section validates its own keys (its pydantic model and its
`problems()`); this module adds the rules between sections (no two faces on one port,
the REST port among them) and reports every problem with the file, line and key path.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field, StringConstraints

from cnc.config import (
    BUILTIN_MACHINES,
    MACHINE_SECTIONS,
    MachineConfig,
    Name,
    Problem,
    Section,
    machines_problems,
    read_config,
    reference_tables,
    validate_machines,
    within,
)
from cnc.errors import NcError
from cnc.params import MachineParams
from dnc.config import DncConfig
from web_api.config import ApiConfig, AuthConfig, TlsConfig
from web_api.settings import ApiKey

__all__ = [
    "CellConfig",
    "HostConfig",
    "MqttConfig",
    "config_reference_markdown",
    "default_cell_config",
    "load_cell_config",
]

# An MQTT broker as HOST:PORT (a name or an IPv4 address; docs/mqtt.md).
Broker = Annotated[
    str,
    StringConstraints(
        pattern=r"^[A-Za-z0-9_.-]+:([0-9]{1,4}|[1-5][0-9]{4}|6[0-4][0-9]{3}|65[0-4][0-9]{2}|655[0-2][0-9]|6553[0-5])$"
    ),
]
# One MQTT topic level or several (no wildcards, no empty level, no leading/trailing '/').
TopicPrefix = Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*$")]


class MqttConfig(Section):
    """The cell's MQTT face (`host.mqtt`, docs/mqtt.md): live state and events to a broker."""

    broker: Broker = Field(description="The broker, `HOST:PORT` (FMSCELL_MQTT overrides it).")
    prefix: TopicPrefix = Field(
        "fmscell", description="First topic level(s), shared by the cells of one factory."
    )
    cell_id: Name = Field(
        "cell", description="This cell's topic level: `<prefix>/<cell_id>/...`; unique per broker."
    )
    period_s: float = Field(
        0.1, gt=0, le=60, description="How often the live state is read and changes published (s)."
    )
    position_period_s: float = Field(
        1.0, gt=0, le=3600, description="Axis positions are published at most this often (s)."
    )
    keepalive_s: int = Field(
        10,
        ge=2,
        le=3600,
        description="MQTT keepalive: a silent cell is declared dead by its"
        " last will after 1.5 times this (s).",
    )


class HostConfig(ApiConfig, DncConfig):
    """The DNC host and cell server (`host`): one flat section whose keys the packages own
    (the DNC host's in dnc/config.py, the REST API's in web_api/config.py), and the
    cell's own below."""

    faults: bool = Field(
        False,
        description="Fault injection: the `/api/...faults` endpoints and each machine's"
        " simulation face (as `fmscell run --faults` or FMSCELL_FAULTS=1); off = 404.",
    )
    mqtt: MqttConfig | None = Field(
        None, description="The MQTT face (see `host.mqtt`); null = off (unless FMSCELL_MQTT)."
    )
    mtconnect_buffer_size: int = Field(
        131072,
        ge=1024,
        le=1 << 22,
        description="Observations the host's MTConnect agent keeps (the history `sample` serves;"
        " the reference agent's BufferSize 17), about 220 bytes each: the host's memory grows"
        " until the buffer is full, then stays flat: 28 MB at 131072, which the default cell"
        " fills in minutes with every machine cutting, in hours when quiet; 16384: 3.5 MB,"
        " eight times sooner.",
    )

    def problems(self) -> list[Problem]:
        return [*ApiConfig.problems(self), *DncConfig.problems(self)]


class _CellDocument(Section):
    machines: dict[Name, MachineConfig] = Field(min_length=1)
    host: HostConfig = Field(default_factory=HostConfig)


@dataclass(frozen=True, slots=True)
class CellConfig:
    """A validated cell: machines by name (in file order) and the host section."""

    machines: dict[str, MachineConfig]
    host: HostConfig
    source: str = "<config>"

    def machine(self, name: str) -> MachineConfig:
        try:
            return self.machines[name]
        except KeyError:
            known = ", ".join(self.machines)
            raise NcError(f"no machine {name!r} in the cell (machines: {known})") from None

    def params(self, name: str) -> MachineParams:
        return self.machine(name).params


def load_cell_config(path: str | Path | Mapping[str, Any]) -> CellConfig:
    """Load and validate a whole cell file (`machines:` and `host:`); a ConfigError lists
    every problem as `FILE:LINE:COL: key.path: reason`."""
    doc = read_config(path)
    cell = validate_machines(doc, _CellDocument)
    host = cell.host
    # the REST port is one of the cell's ports: no machine face may take it
    used = {(host.bind, host.port): "host.port"}
    doc.check([*within(("host",), host.problems()), *machines_problems(cell.machines, used)])
    return CellConfig(dict(cell.machines), host, doc.file)


def default_cell_config() -> CellConfig:
    """The smallest cell of the shipped machines: one of each of BUILTIN_MACHINES (mill3,
    lathe2). `fmscell run` without --config runs `server.cell.default_cell()` instead."""
    return load_cell_config({"machines": {n: {"base": n} for n in BUILTIN_MACHINES}})


HOST_SECTIONS = (
    ("host", HostConfig),
    ("host.auth", AuthConfig),
    ("host.auth.api_keys[]", ApiKey),
    ("host.tls", TlsConfig),
    ("host.mqtt", MqttConfig),
)


def config_reference_markdown() -> str:
    """One Markdown table per section: key, default, meaning (docs/configuration.md embeds
    this text; a test keeps them equal)."""
    return reference_tables([*MACHINE_SECTIONS, *HOST_SECTIONS])
