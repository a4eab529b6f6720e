"""Machine and cell configuration: YAML -> validated, typed sections -> MachineParams.

One YAML file describes the cell: `machines` by name and the `host`. A machine section holds
what the NC kernel needs (kind, axes with soft limits, velocity/accel/jerk limits, IPO cycle,
look-ahead, tolerance, number format) and the sections later layers consume (drives, plc,
can, ports, spindle, tool changer). A machine may start from a shipped machine or another
file with `base:` and override keys. docs/configuration.md lists every key.

Every problem is reported, one line each, as `FILE:LINE:COL: key.path: reason`, e.g.
`cell.yaml:12:18: machines.mill1.axes.X.max_accel: must be > 0, got -5`. Unknown keys are
errors (with a did-you-mean), and so are duplicate keys.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import math
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, StringConstraints, ValidationError
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from cnc.errors import NcError
from cnc.params import AxisParams, DecimalStyle, MachineParams

__all__ = [
    "BUILTIN_MACHINES",
    "SHIPPED_MACHINES",
    "MACHINES_DIR",
    "ApiKeyConfig",
    "AuthConfig",
    "AxisConfig",
    "CanConfig",
    "CellConfig",
    "ConfigError",
    "ConfigProblem",
    "DriveAxisConfig",
    "DrivesConfig",
    "HostConfig",
    "MqttConfig",
    "MachineConfig",
    "MachineDataConfig",
    "PlcConfig",
    "PortsConfig",
    "SpindleConfig",
    "TlsConfig",
    "ToolChangerConfig",
    "ToolConfig",
    "builtin_machine",
    "config_reference_markdown",
    "default_cell_config",
    "load_cell_config",
    "load_machine_config",
    "load_machine_params",
]

MACHINES_DIR = Path(__file__).resolve().parent / "machines"
BUILTIN_MACHINES = ("mill3", "lathe2")  # the default cell: one of each
# every machine file shipped in cnc/machines (a `base:` or `--machine` may name any)
SHIPPED_MACHINES = (*BUILTIN_MACHINES, "mill4", "mill5")
CAN_BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
IPO_CYCLE_MIN_MS = 0.5
IPO_CYCLE_MAX_MS = 8.0


# --- errors ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ConfigProblem:
    """One configuration problem: where (file, line, column, key path) and why."""

    path: str
    reason: str
    file: str = "<config>"
    line: int = 0
    col: int = 0

    def __str__(self) -> str:
        where = f"{self.path}: " if self.path else ""
        return f"{self.file}:{self.line}:{self.col}: {where}{self.reason}"


class ConfigError(NcError):
    """Invalid configuration. `problems` lists every problem found; str() prints one line
    per problem in the `FILE:LINE:COL: key.path: reason` form."""

    def __init__(self, problems: list[ConfigProblem]) -> None:
        first = problems[0]
        where = f"{first.path}: " if first.path else ""
        super().__init__(f"{where}{first.reason}", first.line, first.col, first.file)
        self.problems = tuple(problems)

    def __str__(self) -> str:
        return "\n".join(str(p) for p in self.problems)


# --- the schema --------------------------------------------------------------------------


class _Section(BaseModel):
    # strict: YAML "5" is not 5 and 1 is not true; frozen: a loaded config is a value.
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


Port = Annotated[int, Field(ge=0, le=65535)]
Name = Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_-]{0,31}$")]
AxisName = Annotated[str, StringConstraints(pattern=r"^[XYZABCUVW]$")]
# A shared secret: printable ASCII without blanks (it travels on a command line), long
# enough not to be guessed.
Secret = Annotated[str, StringConstraints(pattern=r"^[!-~]{16,128}$")]
PlantOverrides = dict[str, dict[str, Any]]  # values are checked against PlantParams


class AxisConfig(_Section):
    """One axis (`axes.<NAME>`): soft limits and dynamic limits in machine coordinates."""

    min_mm: float = Field(description="Negative soft limit, machine coordinates, mm.")
    max_mm: float = Field(description="Positive soft limit, machine coordinates, mm.")
    max_velocity: float = Field(gt=0, description="Rapid (G0) velocity, mm/min.")
    max_accel: float = Field(gt=0, description="Acceleration limit, mm/s².")
    max_jerk: float = Field(gt=0, description="Jerk limit, mm/s³.")
    home_mm: float = Field(
        0.0, description="Reference point (G28, homing), machine coordinates, mm."
    )
    continuous: bool = Field(
        False,
        description="Rotary axis (A, B, C) only: endless (no soft limits; positions shown"
        " modulo 360). A rotary axis reads every figure of its section in degrees: deg,"
        " deg/min, deg/s², deg/s³.",
    )


class KinematicsConfig(_Section):
    """Machine kinematics constants (`kinematics`): the `mill5` B45/C table-table machine
    (002_postprocessor.md §4; the post-processor's cam/machines/mill5.yaml gives the same)."""

    type: Literal["table_table_bc45"] = Field(
        "table_table_bc45", description="`table_table_bc45`: B inclined 45° carrying C."
    )
    d_mm: float = Field(
        0.0, description="C-table surface to the point where the B axis meets the C axis, mm."
    )
    tool_length_mm: float = Field(0.0, description="Z_T of eq. 9, mm.")
    z_offset_mm: float = Field(0.0, description="z_OwOt of eq. 9, mm.")


class SpindleConfig(_Section):
    """The main spindle (`spindle`)."""

    max_rpm: float = Field(8000.0, gt=0, description="Highest speed, rpm.")
    min_rpm: float = Field(0.0, ge=0, description="Lowest programmable speed, rpm.")
    ramp_s: float = Field(1.0, ge=0, description="Time from 0 to max_rpm, s.")


class ToolChangerConfig(_Section):
    """Tool changer (`tool_changer`): a mill's ATC magazine or a lathe's turret."""

    kind: Literal["atc", "turret", "manual"] = Field(
        "atc", description="`atc` (magazine + arm), `turret` or `manual` (operator)."
    )
    pockets: int = Field(20, ge=1, le=999, description="Magazine pockets / turret stations.")
    change_time_s: float = Field(2.5, gt=0, description="Time of one M6 change, s.")


class DriveAxisConfig(_Section):
    """One axis' drive (`drives.axes.<NAME>`)."""

    node_id: int = Field(ge=1, le=127, description="CANopen node-ID, 1..127.")
    line: int = Field(
        0,
        ge=0,
        le=3,
        description="CAN line of the drive (0 = `can.channel`, k = that channel + `.k`):"
        " a second line doubles the room for cyclic PDOs (5 axes at a 1 ms IPO cycle).",
    )
    plant: PlantOverrides = Field(
        default_factory=dict,
        description="Plant overrides for this axis, on top of `drives.plant`.",
    )


class DrivesConfig(_Section):
    """Virtual CiA 402 drives (`drives`). Plant overrides are `group: {field: value}` over
    the drives package's PlantParams groups (motor, screw, loops, encoder, dc_link,
    thermal, switches, monitor), SI units as PlantParams documents them."""

    plant: PlantOverrides = Field(
        default_factory=dict, description="Plant overrides applied to every axis."
    )
    axes: dict[str, DriveAxisConfig] = Field(
        default_factory=dict,
        description="Per-axis drive settings; node-IDs default to 1, 2, 3... in axis order.",
    )

    def node_id(self, axis: str, index: int) -> int:
        """The node-ID of `axis` (the `index`-th configured axis)."""
        entry = self.axes.get(axis)
        return entry.node_id if entry is not None else index + 1

    def line(self, axis: str) -> int:
        """The CAN line of `axis` (0 unless configured)."""
        entry = self.axes.get(axis)
        return entry.line if entry is not None else 0

    def plant_overrides(self, axis: str) -> dict[str, dict[str, Any]]:
        """Merged overrides for one axis: `PlantParams().with_(**overrides)`."""
        merged = {group: dict(values) for group, values in self.plant.items()}
        entry = self.axes.get(axis)
        if entry is not None:
            for group, values in entry.plant.items():
                merged.setdefault(group, {}).update(values)
        return merged


class MCodeConfig(_Section):
    """One M function of the PLC's M-code table (`plc.m_codes.<M>`)."""

    ms: int = Field(
        0,
        ge=0,
        le=29_000,
        description="How long the function takes: the PLC gives the finish"
        " this long after the strobe (at least its 50 ms check delay), ms.",
    )
    text: str = Field("", description="What it does, for displays and the docs.")
    sets: str | None = Field(
        None,
        description="PLC bit the function switches on (a device: conveyor, air blast).",
    )
    clears: str | None = Field(None, description="PLC bit the function switches off.")


class PlcConfig(_Section):
    """The soft-PLC (`plc`)."""

    program: str | None = Field(
        None,
        description="Ladder program file (relative to the config file); null = the standard"
        " machine-tool program.",
    )
    period_ms: int = Field(
        10, ge=1, le=1000, description="Scan period, ms; an integer multiple of the IPO cycle."
    )
    watchdog_ms: float | None = Field(
        None, gt=0, description="Scan execution-time limit, ms; null = 10 × period."
    )
    debounce_samples: int = Field(
        0, ge=0, le=64, description="Input filter: a change counts after N equal samples (0 off)."
    )
    m_codes: dict[int, MCodeConfig] | None = Field(
        None,
        description="The M-code table: M functions the PLC handles besides the standard"
        " program's (docs/machine_plc.md), by code; the NC refuses an M code that is neither"
        " its own nor in this table at its block. null = no table: every M code the NC does"
        " not know is handed to the PLC.",
    )
    modbus_write_allow: str = Field(
        "",
        description="Modbus write allow-list (`coil:0-15,hr:1024-1100,%MW0-99`); empty ="
        " read-only.",
    )

    @property
    def m_functions(self) -> tuple:
        """The M-code table as `plc.m_functions.MFunction`s (raises MTableError)."""
        from plc.m_functions import table_from

        entries = {c: e.model_dump() for c, e in (self.m_codes or {}).items()}
        return table_from(entries)

    @property
    def nc_m_codes(self) -> frozenset[int] | None:
        """The M codes the NC hands to this PLC (None: no table, any code)."""
        if self.m_codes is None:
            return None
        from plc.m_functions import STANDARD_EXTRA

        return STANDARD_EXTRA | frozenset(self.m_codes)  # the entries: checked by the loader


class CanConfig(_Section):
    """The machine's CAN bus (`can`)."""

    interface: Literal["sim", "socketcan", "virtual"] = Field(
        "sim", description="`sim` (simulated bus), `socketcan` (real), `virtual` (python-can)."
    )
    channel: str | None = Field(
        None, description="Bus channel (`can0` for socketcan); null = the machine's name."
    )
    bitrate: int = Field(
        1_000_000, description="Bit rate, bit/s: one of the CiA 301 rates 10k … 1M."
    )

    def bus_config(self, machine: str) -> dict[str, Any]:
        """The mapping `drives.bus.open_bus` takes."""
        return {
            "interface": self.interface,
            "channel": self.channel or machine,
            "bitrate": self.bitrate,
        }


class PortsConfig(_Section):
    """The machine's faces (`ports`): TCP ports; 0 = any free port, null = face off."""

    host: str = Field("127.0.0.1", min_length=1, description="Address the faces bind to.")
    dnc: Port | None = Field(0, description="DNC port (ISO 6983 tape transfer, drip-feed).")
    modbus: Port | None = Field(0, description="Modbus/TCP face of the PLC.")
    shdr: Port | None = Field(0, description="MTConnect SHDR status stream.")
    simulation: Port | None = Field(
        None, description="Simulation/fault-injection face; null = off (the default)."
    )
    opcua: Port | None = Field(
        None,
        description="OPC UA server (OPC 40501 MachineTool, docs/opcua.md); null = off (the"
        " default for a machine file; the built-in cell serves mill1 on 4841, lathe1 4842,"
        " mill2 4843).",
    )
    opcua_security: Literal["none", "Basic256Sha256"] = Field(
        "none",
        description="OPC UA endpoint security: none (anonymous, read-only) or Basic256Sha256"
        " sign-and-encrypt with a generated self-signed certificate, trusted client"
        " certificates only, user name + password mapped to the cell's roles.",
    )
    secret: Secret | None = Field(
        None,
        description="Shared secret of the DNC port and the simulation face: a client's first"
        " line must be `AUTH <secret>` (docs/dnc_port.md); null = no handshake (a cell"
        " started by `fmscell run` then generates one for the machines it starts).",
    )


class ToolConfig(_Section):
    """One tool offset (`machine_data.tools.<N>`, N = 1..999), mm; see docs/machine_data.md."""

    length: float = Field(0.0, description="Length geometry (G43/G44 H), mm.")
    length_wear: float = Field(0.0, description="Length wear, mm.")
    radius: float = Field(0.0, description="Radius geometry (G41/G42 D; lathe: nose), mm.")
    radius_wear: float = Field(0.0, description="Radius wear, mm.")
    x: float = Field(0.0, description="Lathe: X tip offset (radius value), mm.")
    x_wear: float = Field(0.0, description="Lathe: X wear (radius value), mm.")
    z: float = Field(0.0, description="Lathe: Z tip offset, mm.")
    z_wear: float = Field(0.0, description="Lathe: Z wear, mm.")
    tip: int = Field(0, ge=0, le=9, description="Lathe: imaginary tip number 0..9.")
    life_uses: int = Field(0, ge=0, description="Tool life: tool changes allowed (0 = none).")
    life_time_s: float = Field(
        0.0, ge=0, description="Tool life: cutting time allowed, s (0 = none)."
    )
    comment: str = Field("", max_length=80, description="Free text (tool description).")


class MachineDataConfig(_Section):
    """The machine data a new machine starts with (`machine_data`); once the machine has
    a state directory its saved data wins (docs/machine_data.md)."""

    power_on_units: Literal["mm", "inch"] = Field(
        "mm", description="Unit in force at power-on and reset until G20/G21: `mm` or `inch`."
    )
    work_offsets: dict[str, list[float]] = Field(
        default_factory=dict,
        description="Work offsets by name (EXT, G54..G59, G54.1P1..G54.1P48): [X, Y, Z],"
        " machine coordinates, mm; names left out are 0.",
    )
    g92: list[float] | None = Field(None, description="G92 shift [X, Y, Z], mm; null = 0.")
    tools: dict[int, ToolConfig] = Field(
        default_factory=dict, description="Tool offsets by number 1..999; see the keys below."
    )

    def initial(self):
        """The cnc.machine_data.MachineData this section describes."""
        from cnc.machine_data import MachineData

        doc: dict[str, Any] = {
            "tools": {str(n): t.model_dump() for n, t in self.tools.items()},
            "work_offsets": {k: list(v) for k, v in self.work_offsets.items()},
            "parameters": {"power_on_units": self.power_on_units},
        }
        if self.g92 is not None:
            doc["g92"] = list(self.g92)
        return MachineData.from_dict(doc)


class MachineConfig(_Section):
    """One machine (`machines.<NAME>`, or a whole machine file)."""

    kind: str = Field(
        description="Kinematics: `mill` (axes X Y Z, optionally followed by rotary axes A, B,"
        " C: mill4 is X Y Z A), `lathe` (axes X Z) or `mill5` (X Y Z B C: a 45° nutating B"
        " table carrying the C table)."
    )
    description: str = Field("", description="Free text for displays.")
    axes: dict[AxisName, AxisConfig] = Field(
        description="Axes by name, in drive order; see the axis keys below."
    )
    ipo_cycle_ms: float = Field(
        2.0,
        ge=IPO_CYCLE_MIN_MS,
        le=IPO_CYCLE_MAX_MS,
        description="Interpolation (IPO) cycle, ms, 0.5 … 8.",
    )
    lookahead: int = Field(200, ge=1, le=100_000, description="Planner look-ahead, blocks.")
    default_path_tolerance: float = Field(
        0.01, ge=0, description="G64 path tolerance without P, mm (0 = as fast as limits allow)."
    )
    max_feed: float = Field(15000.0, gt=0, description="Highest programmable feed F, mm/min.")
    decimal_style: Literal["calculator", "least_increment"] = Field(
        "calculator",
        description="Numbers without a decimal point: `calculator` (X10 = 10 mm) or"
        " `least_increment` (Fanuc, X10 = 0.010 mm).",
    )
    least_increment_mm: float = Field(0.001, gt=0, description="Least input increment, mm.")
    least_increment_inch: float = Field(
        0.0001, gt=0, description="Least input increment under G20, inch."
    )
    lathe_diameter_mode: bool = Field(True, description="Lathe: X words are diameters.")
    lathe_gcode_system: Literal["A", "B", "C"] = Field(
        "A",
        description="Lathe: Fanuc G-code system A (G90/G92/G94 cycles, G50 coordinate set,"
        " G98/G99 feed), B (G77/G78/G79 cycles, G90/G91 absolute/incremental, G92, G94/G95)"
        " or C (B with G70/G71 inch/metric and G72..G78 cycles); docs/gcode.md.",
    )
    second_reference_mm: dict[str, float] | None = Field(
        None,
        description="G30 point per axis, machine coordinates, mm; missing axes use home_mm;"
        " null = the home position.",
    )
    program_memory_bytes: int = Field(
        262_144, ge=1024, description="Part-program memory capacity, bytes."
    )
    call_nesting: int = Field(
        10,
        ge=1,
        le=10,
        description="Program levels a program may call down (M98, G65, G66 together; deeper"
        " is alarm PS0077): 10 on a Fanuc 0i-D/F, 4 on a 0i-C, 16i/18i/21i.",
    )
    macro_nesting: int = Field(
        5,
        ge=1,
        le=5,
        description="Of those, G65/G66 macro levels (deeper is alarm PS0122): 5 on a Fanuc"
        " 0i-D/F, 4 on a 0i-C, 16i/18i/21i.",
    )
    home_sequence: list[list[AxisName]] | None = Field(
        None,
        description="Homing sequence: groups of axes homed together, one group after the"
        " other, each axis exactly once (e.g. [[Z], [X, Y]]); null = the kind's default"
        " (mill: Z first, then the others together; lathe: X, then Z).",
    )
    kinematics: KinematicsConfig | None = Field(
        None,
        description="Kinematics constants of a `mill5` (null: the kind's defaults).",
    )
    spindle: SpindleConfig = Field(
        default_factory=SpindleConfig, description="The spindle section."
    )
    tool_changer: ToolChangerConfig = Field(
        default_factory=ToolChangerConfig, description="The tool changer section."
    )
    drives: DrivesConfig = Field(default_factory=DrivesConfig, description="The drives section.")
    plc: PlcConfig = Field(default_factory=PlcConfig, description="The PLC section.")
    can: CanConfig = Field(default_factory=CanConfig, description="The CAN bus section.")
    ports: PortsConfig = Field(default_factory=PortsConfig, description="The faces' ports section.")
    machine_data: MachineDataConfig | None = Field(
        default_factory=MachineDataConfig,
        description="The machine data section: tools, work offsets, power-on unit; null ="
        " every offset 0 and no tools (programs in machine coordinates).",
    )

    @property
    def params(self) -> MachineParams:
        """The NC kernel's view of this machine."""
        axes = tuple(
            AxisParams(
                name=n,
                min_mm=a.min_mm,
                max_mm=a.max_mm,
                max_velocity=a.max_velocity,
                max_accel=a.max_accel,
                max_jerk=a.max_jerk,
                home_mm=a.home_mm,
                continuous=a.continuous,
            )
            for n, a in self.axes.items()
        )
        second = None
        if self.second_reference_mm is not None:
            second = tuple(float(self.second_reference_mm.get(a.name, a.home_mm)) for a in axes)
        return MachineParams(
            kind=self.kind,
            axes=axes,
            decimal_style=DecimalStyle(self.decimal_style),
            least_increment_mm=self.least_increment_mm,
            least_increment_inch=self.least_increment_inch,
            lathe_diameter_mode=self.lathe_diameter_mode,
            lathe_gcode_system=self.lathe_gcode_system,
            max_feed=self.max_feed,
            default_path_tolerance=self.default_path_tolerance,
            lookahead=self.lookahead,
            ipo_cycle_s=self.ipo_cycle_ms / 1000.0,
            second_reference_mm=second,
            max_spindle_rpm=self.spindle.max_rpm,
            call_nesting=self.call_nesting,
            macro_nesting=self.macro_nesting,
            plc_m_codes=self.plc.nc_m_codes,
            kinematics=(
                (self.kinematics.d_mm, self.kinematics.tool_length_mm, self.kinematics.z_offset_mm)
                if self.kinematics is not None
                else None
            ),
        )


class ApiKeyConfig(_Section):
    """One REST API key (`host.auth.api_keys[]`): who uses it, with which role."""

    user: str = Field(min_length=1, max_length=64, description="Who uses the key (audit).")
    role: Literal["viewer", "operator", "programmer", "admin"] = Field(
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


class AuthConfig(_Section):
    """REST API authentication (`host.auth`)."""

    api_keys: list[ApiKeyConfig] = Field(
        default_factory=list,
        description="API keys, each `{user, role, key}` or `{user, role, key_sha256}`.",
    )
    insecure_open: bool = Field(
        False,
        description="Demo only: no key checked, every caller is an admin (as `--insecure-open`).",
    )


class TlsConfig(_Section):
    """HTTPS for the REST API and dashboard (`host.tls`)."""

    cert: str = Field(min_length=1, description="PEM certificate (chain) file.")
    key: str = Field(min_length=1, description="PEM private key file.")


# An MQTT broker as HOST:PORT (a name or an IPv4 address; docs/mqtt.md).
Broker = Annotated[
    str,
    StringConstraints(
        pattern=r"^[A-Za-z0-9_.-]+:([0-9]{1,4}|[1-5][0-9]{4}|6[0-4][0-9]{3}|65[0-4][0-9]{2}|655[0-2][0-9]|6553[0-5])$"
    ),
]
# One MQTT topic level or several (no wildcards, no empty level, no leading/trailing '/').
TopicPrefix = Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*$")]


class MqttConfig(_Section):
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


class HostConfig(_Section):
    """The DNC host and cell server (`host`)."""

    database_url: str | None = Field(
        None, description="SQLAlchemy URL; null = the embedded SQLite file."
    )
    bind: str = Field("127.0.0.1", min_length=1, description="REST/dashboard bind address.")
    port: Port = Field(8000, description="REST/dashboard TCP port.")
    auth: AuthConfig = Field(
        default_factory=AuthConfig, description="REST API keys (see `host.auth` below)."
    )
    tls: TlsConfig | None = Field(
        None, description="HTTPS certificate and key (see `host.tls`); null = plain HTTP."
    )
    lost_contact_s: float = Field(
        30.0,
        gt=0,
        description="A machine out of contact this long is taken as lost: its allocation is"
        " interrupted and the part rerouted (seconds).",
    )
    dispatch_rule: str = Field(
        "fifo",
        min_length=1,
        description="Which waiting job a free machine takes next: `fifo`, `spt`, `edd`, `cr`"
        " or `same_program_first` (the job whose program the machine already holds, then"
        " FIFO; `same_program_first then edd` falls back to EDD instead); docs/dnc.md.",
    )
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
        " until the buffer is full: 28 MB at 131072, which the default cell's 13-30 a second"
        " (jobs looping) take one to three hours to fill; 16384: 3.5 MB, some 10 minutes.",
    )


class _CellDocument(_Section):
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


# --- YAML with positions ---------------------------------------------------------------

_Marks = dict[tuple[Any, ...], Node]


def _compose(text: str, file: str) -> Node:
    loader = None
    try:
        loader = yaml.SafeLoader(text)
        loader.name = file
        node = loader.get_single_node()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (0, 0)
        reason = f"YAML syntax: {exc.problem or exc}"
        raise ConfigError([ConfigProblem("", reason, file, line, col)]) from None
    except yaml.YAMLError as exc:
        raise ConfigError([ConfigProblem("", f"YAML: {exc}", file)]) from None
    except RecursionError:
        raise ConfigError([ConfigProblem("", "YAML nested too deeply", file)]) from None
    finally:
        if loader is not None:
            loader.dispose()
    if node is None:
        raise ConfigError([ConfigProblem("", "the configuration is empty", file, 1, 1)])
    return node


def _key(node: Node) -> Any:
    return node.value if isinstance(node, ScalarNode) else repr(node)


def _dotted(path: tuple[Any, ...]) -> str:
    # A key with control characters is shown escaped so that a problem stays on one line.
    return ".".join(str(p) if str(p).isprintable() else repr(p) for p in path)


def _check_keys(
    node: Node, path: tuple[Any, ...], problems: list[ConfigProblem], visited: set[int]
) -> None:
    """Duplicate keys are errors (PyYAML keeps the last one silently); expand `<<` merges.
    Aliased nodes are walked once, so an alias bomb or a recursive alias cannot hang."""
    if id(node) in visited:
        return
    visited.add(id(node))
    if isinstance(node, MappingNode):
        seen: dict[Any, Node] = {}
        for k, _v in node.value:
            if k.tag == "tag:yaml.org,2002:merge":
                continue
            kv = _key(k)
            if kv in seen:
                m = k.start_mark
                first = seen[kv].start_mark.line + 1
                problems.append(
                    ConfigProblem(
                        _dotted((*path, kv)),
                        f"duplicate key (first at line {first})",
                        m.name,
                        m.line + 1,
                        m.column + 1,
                    )
                )
            seen[kv] = k
        yaml.SafeLoader("").flatten_mapping(node)
        for k, v in node.value:
            _check_keys(v, (*path, _key(k)), problems, visited)
    elif isinstance(node, SequenceNode):
        for i, v in enumerate(node.value):
            _check_keys(v, (*path, i), problems, visited)


def _index(node: Node, path: tuple[Any, ...], marks: _Marks, visited: set[int]) -> None:
    """Key path -> the node to point at: a scalar's value, or a block's key."""
    marks[path] = node
    if id(node) in visited:
        return  # an alias: its positions are those of the anchor
    visited.add(id(node))
    if isinstance(node, MappingNode):
        for k, v in node.value:
            kv = _key(k)
            _index(v, (*path, kv), marks, visited)
            if isinstance(v, MappingNode | SequenceNode):
                marks[(*path, kv)] = k
    elif isinstance(node, SequenceNode):
        for i, v in enumerate(node.value):
            _index(v, (*path, i), marks, visited)


def _merge_nodes(base: Node, over: Node) -> Node:
    """Deep merge of two mapping nodes: `over` wins; nested mappings merge."""
    if not (isinstance(base, MappingNode) and isinstance(over, MappingNode)):
        return over
    merged: list[tuple[Node, Node]] = []
    over_by_key = {_key(k): (k, v) for k, v in over.value}
    for k, v in base.value:
        kv = _key(k)
        if kv in over_by_key:
            ok, ov = over_by_key.pop(kv)
            merged.append((ok, _merge_nodes(v, ov)))
        else:
            merged.append((k, v))
    merged.extend(over_by_key.values())
    return MappingNode(over.tag, merged, over.start_mark, over.end_mark, over.flow_style)


# --- loading -----------------------------------------------------------------------------


@dataclass(slots=True)
class _Source:
    """A composed document and how to report positions in it."""

    file: str
    directory: Path
    node: Node


def _read(path: str | Path) -> _Source:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError([ConfigProblem("", "configuration file not found", str(p))]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([ConfigProblem("", f"cannot read: {exc}", str(p))]) from None
    return _Source(str(p), p.resolve().parent, _compose(text, str(p)))


def _source_from(path_or_dict: str | Path | Mapping[str, Any]) -> _Source:
    if not isinstance(path_or_dict, Mapping):
        return _read(path_or_dict)
    try:
        text = yaml.safe_dump(dict(path_or_dict), sort_keys=False)
    except yaml.YAMLError as exc:
        problem = ConfigProblem("", f"not plain configuration data: {exc}")
        raise ConfigError([problem]) from None
    return _Source("<config>", Path.cwd(), _compose(text, "<config>"))


def _resolve_bases(node: Node, src_dir: Path, path: tuple[Any, ...], depth: int = 0) -> Node:
    """Replace a machine section's `base:` by the base machine merged under it."""
    if not isinstance(node, MappingNode):
        return node
    entry = next(((k, v) for k, v in node.value if _key(k) == "base"), None)
    if entry is None:
        return node
    k, v = entry
    m = v.start_mark

    def fail(reason: str) -> ConfigError:
        dotted = _dotted((*path, "base"))
        return ConfigError([ConfigProblem(dotted, reason, m.name, m.line + 1, m.column + 1)])

    if depth >= 8:
        raise fail("`base` chain deeper than 8 files")
    if not isinstance(v, ScalarNode) or not v.value:
        raise fail("must name a shipped machine or a file")
    ref = v.value
    if ref in SHIPPED_MACHINES:
        target = MACHINES_DIR / f"{ref}.yaml"
    else:
        target = (src_dir / ref).resolve()
        if not target.is_file():
            raise fail(
                f"no shipped machine or file {ref!r} (shipped: {', '.join(SHIPPED_MACHINES)})"
            )
    base = _read(target)
    problems: list[ConfigProblem] = []
    _check_keys(base.node, (), problems, set())
    if problems:
        raise ConfigError(problems)
    base_node = _resolve_bases(base.node, target.parent, path, depth + 1)
    rest = MappingNode(node.tag, [(a, b) for a, b in node.value if a is not k], node.start_mark)
    return _merge_nodes(base_node, rest)


def _prepare(src: _Source) -> tuple[Any, _Marks]:
    """Check keys, resolve `base:`, construct plain data and index key positions."""
    try:
        return _prepare_nodes(src)
    except RecursionError:
        raise ConfigError([ConfigProblem("", "YAML nested too deeply", src.file)]) from None


def _prepare_nodes(src: _Source) -> tuple[Any, _Marks]:
    problems: list[ConfigProblem] = []
    _check_keys(src.node, (), problems, set())
    if problems:
        raise ConfigError(problems)
    node = src.node
    if isinstance(node, MappingNode):
        machines = next((v for k, v in node.value if _key(k) == "machines"), None)
        if isinstance(machines, MappingNode):
            machines.value = [
                (k, _resolve_bases(v, src.directory, ("machines", _key(k))))
                for k, v in machines.value
            ]
        elif machines is None:
            node = _resolve_bases(node, src.directory, ())
    marks: _Marks = {}
    _index(node, (), marks, set())
    try:
        data = yaml.SafeLoader("").construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mk = exc.problem_mark
        where = (mk.name, mk.line + 1, mk.column + 1) if mk else (src.file, 0, 0)
        raise ConfigError([ConfigProblem("", f"YAML: {exc.problem}", *where)]) from None
    if not isinstance(data, Mapping):
        reason = f"must be a mapping, got {_fmt(data)}"
        raise ConfigError([ConfigProblem("", reason, src.file, 1, 1)])
    return data, marks


def _did_you_mean(model: type[BaseModel] | None, key: Any) -> str:
    if model is None:
        return ""
    return _hint(str(key), list(model.model_fields))


def _hint(key: str, names: Any) -> str:
    names = list(names)
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
    hint = f"did you mean '{close[0]}'? " if close else ""
    return f" ({hint}known: {', '.join(names)})"


def _model_at(root: type[BaseModel], loc: tuple[Any, ...]) -> type[BaseModel] | None:
    """The section model that holds the key at `loc` (for unknown-key hints)."""
    current: Any = root
    for part in loc[:-1]:
        if isinstance(current, type) and issubclass(current, BaseModel):
            field = current.model_fields.get(str(part))
            if field is None:
                return None
            current = field.annotation
        elif typing.get_origin(current) is dict:
            current = typing.get_args(current)[1]
        else:
            return None
        while typing.get_origin(current) in (typing.Union, types.UnionType, Annotated):
            current = next(a for a in typing.get_args(current) if a is not type(None))
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


def _fmt(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        return str(int(value))
    if isinstance(value, int | float):
        return f"{value:g}"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list | tuple):
        return "a list"
    if value is None:
        return "null"
    return repr(value)


_TYPE_WORDS = {
    "float_type": "a number",
    "int_type": "an integer",
    "bool_type": "true or false",
    "string_type": "a string",
    "dict_type": "a mapping",
    "list_type": "a list",
    "model_type": "a mapping",
}
_BOUNDS = {
    "greater_than": (">", "gt"),
    "greater_than_equal": (">=", "ge"),
    "less_than": ("<", "lt"),
    "less_than_equal": ("<=", "le"),
}


def _reason(err: Mapping[str, Any], root: type[BaseModel]) -> str:
    """Pydantic's error in the trade's one-line form."""
    kind = err["type"]
    ctx = err.get("ctx") or {}
    got = _fmt(err.get("input"))
    if kind in _BOUNDS:
        op, key = _BOUNDS[kind]
        return f"must be {op} {_fmt(ctx[key])}, got {got}"
    if kind == "missing":
        return "required key missing"
    if kind == "extra_forbidden":
        return "unknown key" + _did_you_mean(_model_at(root, tuple(err["loc"])), err["loc"][-1])
    if kind in _TYPE_WORDS:
        return f"must be {_TYPE_WORDS[kind]}, got {got}"
    if kind == "literal_error":
        return f"must be one of {ctx.get('expected')}, got {got}"
    if kind == "finite_number":
        return f"must be a finite number, got {got}"
    if kind == "string_pattern_mismatch":
        rule = _PATTERN_WORDS.get(ctx.get("pattern"), f"must match {ctx.get('pattern')}")
        return f"bad name {got}: {rule}"
    if kind in ("too_short", "string_too_short"):
        return "must not be empty"
    msg = str(err["msg"])
    return f"{msg[:1].lower()}{msg[1:]}, got {got}"


def _loc(err: Mapping[str, Any]) -> tuple[Any, ...]:
    """Pydantic's location as a key path (a bad mapping key is reported at the key)."""
    loc = tuple(err["loc"])
    return loc[:-1] if loc and loc[-1] == "[key]" else loc


_PATTERN_WORDS = {
    Name.__metadata__[0].pattern: "a machine name starts with a letter and has up to 32"
    " letters, digits, '_' or '-'",
    AxisName.__metadata__[0].pattern: "an axis is one of X Y Z A B C U V W",
}


class _Reporter:
    """Turns key paths into ConfigProblems that point at the right file, line and column."""

    def __init__(self, src: _Source, marks: _Marks) -> None:
        self.src = src
        self.marks = marks

    def __call__(self, path: tuple[Any, ...], reason: str) -> ConfigProblem:
        probe = path
        while probe and probe not in self.marks:
            probe = probe[:-1]
        node = self.marks.get(probe)
        if node is None or node.start_mark.name == "<config>":
            return ConfigProblem(_dotted(path), reason, self.src.file)  # no lines to point at
        m = node.start_mark  # may lie in a `base:` file: its name is in the mark
        return ConfigProblem(_dotted(path), reason, m.name, m.line + 1, m.column + 1)

    def validate(self, model: type[_Section], data: Any) -> Any:
        try:
            return model.model_validate(data)
        except ValidationError as exc:
            raise ConfigError([self(_loc(e), _reason(e, model)) for e in exc.errors()]) from None

    def check(self, problems: list[tuple[tuple[Any, ...], str]]) -> None:
        if problems:
            raise ConfigError([self(p, r) for p, r in problems])


def _check_machine(name: tuple[Any, ...], m: MachineConfig) -> list[tuple[tuple, str]]:
    """Cross-field rules pydantic's per-field constraints cannot express."""
    out: list[tuple[tuple, str]] = []
    for axis, a in m.axes.items():
        if a.continuous and axis not in "ABC":
            out.append(
                ((*name, "axes", axis, "continuous"), "only a rotary axis (A, B, C) is endless")
            )
        if a.min_mm >= a.max_mm:
            out.append(
                (
                    (*name, "axes", axis, "max_mm"),
                    f"must be > min_mm ({_fmt(a.min_mm)}), got {_fmt(a.max_mm)}",
                )
            )
        elif not a.min_mm <= a.home_mm <= a.max_mm:
            out.append(
                (
                    (*name, "axes", axis, "home_mm"),
                    f"must lie within the soft limits {_fmt(a.min_mm)} .. {_fmt(a.max_mm)},"
                    f" got {_fmt(a.home_mm)}",
                )
            )
    from cnc.kinematics import kinematics_for  # late: kinematics is not needed to parse

    try:
        kinematics_for(m.params)
    except NcError as exc:
        key = "kind" if "no kinematics" in exc.message else "axes"
        out.append(((*name, key), exc.message))
    for axis, value in (m.second_reference_mm or {}).items():
        a = m.axes.get(axis)
        if a is None:
            reason = f"no such axis (axes: {' '.join(m.axes)})"
            out.append(((*name, "second_reference_mm", axis), reason))
        elif a.min_mm < a.max_mm and not a.min_mm <= value <= a.max_mm:
            reason = (
                f"must lie within the soft limits {_fmt(a.min_mm)} .. {_fmt(a.max_mm)},"
                f" got {_fmt(value)}"
            )
            out.append(((*name, "second_reference_mm", axis), reason))
    if m.home_sequence is not None:
        flat = [a for group in m.home_sequence for a in group]
        if any(not g for g in m.home_sequence) or sorted(flat) != sorted(m.axes):
            reason = (
                f"must name each axis of {' '.join(m.axes)} exactly once, in non-empty groups,"
                f" got {[list(g) for g in m.home_sequence]}"
            )
            out.append(((*name, "home_sequence"), reason))
    ratio = m.plc.period_ms / m.ipo_cycle_ms
    if abs(ratio - round(ratio)) > 1e-9:
        reason = (
            f"must be an integer multiple of the IPO cycle ({_fmt(m.ipo_cycle_ms)} ms),"
            f" got {m.plc.period_ms}"
        )
        out.append(((*name, "plc", "period_ms"), reason))
    if m.spindle.min_rpm > m.spindle.max_rpm:
        reason = f"must be <= max_rpm ({_fmt(m.spindle.max_rpm)}), got {_fmt(m.spindle.min_rpm)}"
        out.append(((*name, "spindle", "min_rpm"), reason))
    if m.can.bitrate not in CAN_BITRATES:
        rates = ", ".join(str(r) for r in CAN_BITRATES)
        out.append(((*name, "can", "bitrate"), f"must be one of {rates}, got {m.can.bitrate}"))
    if m.plc.m_codes:
        from plc.m_functions import MTableError

        try:
            _ = m.plc.m_functions  # compiles the table: its errors name the entry
        except MTableError as exc:
            out.append(((*name, "plc", *exc.where.split(".")), exc.message))
    if m.plc.modbus_write_allow:
        from plc.modbus.allowlist import AllowList, AllowListError

        try:
            AllowList.parse(m.plc.modbus_write_allow)
        except AllowListError as exc:
            out.append(((*name, "plc", "modbus_write_allow"), str(exc)))
    out.extend(_check_drives(name, m))
    out.extend(_check_machine_data(name, m))
    return out


def _check_machine_data(name: tuple[Any, ...], m: MachineConfig) -> list[tuple[tuple, str]]:
    from cnc.machine_data import MachineData, MachineDataError

    out: list[tuple[tuple, str]] = []
    md = m.machine_data
    if md is None:
        return out
    base = (*name, "machine_data")
    for key, vec in md.work_offsets.items():
        try:
            MachineData.from_dict({"work_offsets": {key: vec}})
        except MachineDataError as e:
            out.append(((*base, "work_offsets", key), e.message))
    if md.g92 is not None and len(md.g92) != 3:
        out.append(((*base, "g92"), f"must be [X, Y, Z], got {len(md.g92)} values"))
    for n, tool in md.tools.items():
        try:
            MachineData.from_dict({"tools": {str(n): tool.model_dump()}})
        except MachineDataError as e:
            sub = e.pointer.split("/")[3:]
            out.append(((*base, "tools", n, *sub), e.message))
    return out


def _check_drives(name: tuple[Any, ...], m: MachineConfig) -> list[tuple[tuple, str]]:
    out: list[tuple[tuple, str]] = []
    for axis in m.drives.axes:
        if axis not in m.axes:
            reason = f"no such axis (axes: {' '.join(m.axes)})"
            out.append(((*name, "drives", "axes", axis), reason))
    ids: dict[int, str] = {}
    for i, axis in enumerate(m.axes):
        nid = m.drives.node_id(axis, i)
        if nid in ids:
            reason = f"node-ID {nid} already used by axis {ids[nid]}"
            out.append(((*name, "drives", "axes", axis, "node_id"), reason))
        ids[nid] = axis
    out.extend(_check_plant((*name, "drives", "plant"), m.drives.plant))
    for axis, entry in m.drives.axes.items():
        out.extend(_check_plant((*name, "drives", "axes", axis, "plant"), entry.plant))
    return out


def _check_plant(path: tuple[Any, ...], plant: PlantOverrides) -> list[tuple[tuple, str]]:
    """Override groups and fields must exist in the drives package's PlantParams."""
    if not plant:
        return []
    from drives.plant.params import PlantParams  # late: only configs with overrides need it

    out: list[tuple[tuple, str]] = []
    defaults = PlantParams()
    groups = [f.name for f in dataclasses.fields(PlantParams)]
    for group, values in plant.items():
        if group not in groups:
            out.append(((*path, group), "unknown plant group" + _hint(group, groups)))
            continue
        current = getattr(defaults, group)
        names = [f.name for f in dataclasses.fields(current)]
        for key, value in values.items():
            if key not in names:
                out.append(((*path, group, key), "unknown plant parameter" + _hint(key, names)))
                continue
            default = getattr(current, key)
            if not isinstance(value, int | float) or (
                isinstance(value, float) and not math.isfinite(value)
            ):
                want = "true or false" if isinstance(default, bool) else "a finite number"
                out.append(((*path, group, key), f"must be {want}, got {_fmt(value)}"))
            elif isinstance(default, bool) != isinstance(value, bool):
                want = "true or false" if isinstance(default, bool) else "a number"
                out.append(((*path, group, key), f"must be {want}, got {_fmt(value)}"))
            elif isinstance(default, int) and not isinstance(value, int):
                out.append(((*path, group, key), f"must be an integer, got {_fmt(value)}"))
    return out


def _check_cell(cell: _CellDocument) -> list[tuple[tuple, str]]:
    out: list[tuple[tuple, str]] = []
    used: dict[tuple[str, int], str] = {(cell.host.bind, cell.host.port): "host.port"}
    digests: dict[str, int] = {}
    for i, k in enumerate(cell.host.auth.api_keys):
        where = ("host", "auth", "api_keys", i)
        if (k.key is None) == (k.key_sha256 is None):
            out.append((where, f"api key of {k.user!r}: give exactly one of key, key_sha256"))
            continue
        digest = k.key_sha256 or hashlib.sha256(k.key.encode()).hexdigest()  # type: ignore[union-attr]
        if digest in digests:
            out.append((where, f"the same key as api_keys[{digests[digest]}]"))
        digests.setdefault(digest, i)
    # the host's own keys are checked by the host layer, which registers its checks here
    # (dnc.rules: dispatch_rule): cnc never imports dnc (docs/architecture.md)
    for key, check in HOST_CHECKS.items():
        try:
            check(getattr(cell.host, key))
        except ValueError as exc:
            out.append((("host", key), str(exc)))
    for name, m in cell.machines.items():
        out.extend(_check_machine(("machines", name), m))
        for face in ("dnc", "modbus", "shdr", "simulation", "opcua"):
            port = getattr(m.ports, face)
            if not port:
                continue  # 0 = any free port, None = face off
            key = (m.ports.host, port)
            if key in used:
                reason = f"port {port} already used by {used[key]}"
                out.append((("machines", name, "ports", face), reason))
            else:
                used[key] = f"machines.{name}.ports.{face}"
    return out


#: host key -> a check that raises ValueError with the reason; filled by the packages above
#: cnc that own those keys (dnc.rules registers `dispatch_rule` when it is imported).
HOST_CHECKS: dict[str, Callable[[Any], object]] = {}


def _load_cell(src: _Source, data: Mapping[str, Any], report: _Reporter) -> CellConfig:
    try:
        doc = _CellDocument.model_validate(data)
    except ValidationError as exc:
        problems = [report(_loc(e), _reason(e, _CellDocument)) for e in exc.errors()]
        # Machines that are valid on their own still get their cross-field checks, so one
        # run reports as much as possible.
        failed = {tuple(e["loc"][:2]) for e in exc.errors()}
        machines = data.get("machines")
        for name, section in machines.items() if isinstance(machines, Mapping) else ():
            if ("machines", name) in failed:
                continue
            try:
                machine = MachineConfig.model_validate(section)
            except ValidationError:
                continue
            problems += [report(p, r) for p, r in _check_machine(("machines", name), machine)]
        raise ConfigError(problems) from None
    report.check(_check_cell(doc))
    return CellConfig(dict(doc.machines), doc.host, src.file)


def load_cell_config(path: str | Path | Mapping[str, Any]) -> CellConfig:
    """Load and validate a whole cell file (`machines:` and `host:`)."""
    src = _source_from(path)
    data, marks = _prepare(src)
    return _load_cell(src, data, _Reporter(src, marks))


def load_machine_config(
    path_or_dict: str | Path | Mapping[str, Any], name: str | None = None
) -> MachineConfig:
    """Load one machine: from a cell file (`machines:`; `name` picks one and may be left
    out when there is only one) or from a machine file (the machine section itself, as the
    shipped cnc/machines/*.yaml; `name` is then ignored)."""
    src = _source_from(path_or_dict)
    data, marks = _prepare(src)
    report = _Reporter(src, marks)
    if "machines" not in data:
        machine = report.validate(MachineConfig, data)
        report.check(_check_machine((), machine))
        return machine
    cell = _load_cell(src, data, report)
    if name is None and len(cell.machines) == 1:
        name = next(iter(cell.machines))
    if name is None or name not in cell.machines:
        names = ", ".join(cell.machines)
        reason = (
            f"several machines ({names}): name one"
            if name is None
            else f"no machine {name!r} (machines: {names})"
        )
        raise ConfigError([report(("machines",), reason)])
    return cell.machines[name]


def load_machine_params(
    path_or_dict: str | Path | Mapping[str, Any], name: str | None = None
) -> MachineParams:
    """MachineParams of one machine; see `load_machine_config` for the accepted inputs."""
    return load_machine_config(path_or_dict, name).params


def builtin_machine(name: str) -> MachineConfig:
    """A shipped machine: `mill3` (3-axis vertical mill, ATC), `lathe2` (X Z turret
    lathe), `mill4` (mill3 with a rotary table A) or `mill5` (X Y Z B45 C table-table)."""
    if name not in SHIPPED_MACHINES:
        raise NcError(f"no shipped machine {name!r} (shipped: {', '.join(SHIPPED_MACHINES)})")
    return load_machine_config(MACHINES_DIR / f"{name}.yaml")


def default_cell_config() -> CellConfig:
    """The built-in cell `fmscell run` uses without --config: one of each shipped machine."""
    return load_cell_config({"machines": {n: {"base": n} for n in BUILTIN_MACHINES}})


# --- documentation -------------------------------------------------------------------------


def config_reference_markdown() -> str:
    """One Markdown table per section: key, type, default, meaning (docs/configuration.md
    embeds this text; a test keeps them equal)."""
    sections: list[tuple[str, type[BaseModel]]] = [
        ("machines.<NAME>", MachineConfig),
        ("machines.<NAME>.axes.<AXIS>", AxisConfig),
        ("machines.<NAME>.kinematics", KinematicsConfig),
        ("machines.<NAME>.spindle", SpindleConfig),
        ("machines.<NAME>.tool_changer", ToolChangerConfig),
        ("machines.<NAME>.drives", DrivesConfig),
        ("machines.<NAME>.drives.axes.<AXIS>", DriveAxisConfig),
        ("machines.<NAME>.plc", PlcConfig),
        ("machines.<NAME>.plc.m_codes.<M>", MCodeConfig),
        ("machines.<NAME>.can", CanConfig),
        ("machines.<NAME>.ports", PortsConfig),
        ("machines.<NAME>.machine_data", MachineDataConfig),
        ("machines.<NAME>.machine_data.tools.<N>", ToolConfig),
        ("host", HostConfig),
        ("host.auth", AuthConfig),
        ("host.auth.api_keys[]", ApiKeyConfig),
        ("host.tls", TlsConfig),
        ("host.mqtt", MqttConfig),
    ]
    out: list[str] = []
    for title, model in sections:
        out.append(f"### `{title}`\n")
        out.append("| key | default | meaning |")
        out.append("|---|---|---|")
        for key, field in model.model_fields.items():
            if field.is_required():
                default = "required"
            elif field.default_factory is not None:
                made = field.default_factory()  # type: ignore[call-arg]
                default = "section" if isinstance(made, BaseModel) else f"`{_doc_value(made)}`"
            else:
                default = f"`{_doc_value(field.default)}`"
            out.append(f"| `{key}` | {default} | {field.description or ''} |")
        out.append("")
    return "\n".join(out)


def _doc_value(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "{}"
    if isinstance(value, str):
        return f'"{value}"'
    return f"{value:g}" if isinstance(value, float) else str(value)
