"""Machine configuration: YAML -> validated, typed sections -> MachineParams; and the
reading of configuration files that every package's sections share.

A machine section holds what the NC kernel needs (kind, axes with soft limits,
velocity/accel/jerk limits, IPO cycle, look-ahead, tolerance, number format, spindle, tool
changer, faces' ports, machine data) and the sections other packages own, each declared and
checked by its owner: `drives` and `can` (drives/config.py), `plc` (plc/config.py). A
machine may start from a shipped machine or another file with `base:` and override keys.
The cell file (`machines:` and `host:`) is composed by server/config.py, which adds the
host's sections (dnc/config.py, web_api/config.py, its own). docs/configuration.md lists
every key; docs/architecture.md says how to add one.

A section is a pydantic model (strict, unknown keys refused) whose rules across keys are a
`problems()` method returning (key path below the section, reason) pairs; the loader places
them (`within`) and reports every problem, one line each, as `FILE:LINE:COL: key.path:
reason`, e.g. `cell.yaml:12:18: machines.mill1.axes.X.max_accel: must be > 0, got -5`.
Unknown keys are errors (with a did-you-mean), and so are duplicate keys.
"""

from __future__ import annotations

import difflib
import math
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, StringConstraints, ValidationError
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from cnc.errors import NcError
from cnc.kinematics import kinematics_for
from cnc.machine_data.core import MachineData, MachineDataError
from cnc.params import AxisParams, DecimalStyle, MachineParams
from cnc.probe import ToolSetter
from drives.config import CanConfig, DriveAxisConfig, DrivesConfig
from plc.config import MCodeConfig, PlcConfig

__all__ = [
    "BUILTIN_MACHINES",
    "MACHINES_DIR",
    "MACHINE_SECTIONS",
    "SHIPPED_MACHINES",
    "AxisConfig",
    "ConfigDocument",
    "ConfigError",
    "ConfigProblem",
    "MachineConfig",
    "MachineDataConfig",
    "Name",
    "Port",
    "PortsConfig",
    "Problem",
    "Section",
    "SpindleConfig",
    "ToolChangerConfig",
    "ToolConfig",
    "builtin_machine",
    "load_machine_config",
    "load_machine_params",
    "machines_problems",
    "read_config",
    "reference_tables",
    "validate_machines",
    "within",
]

MACHINES_DIR = Path(__file__).resolve().parent / "machines"
BUILTIN_MACHINES = ("mill3", "lathe2")  # the default cell: one of each
# every machine file shipped in cnc/machines (a `base:` or `--machine` may name any)
SHIPPED_MACHINES = (*BUILTIN_MACHINES, "mill4", "mill5")
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


class Section(BaseModel):
    """The base of a configuration section. Strict: YAML "5" is not 5 and 1 is not true;
    unknown keys are refused; frozen: a loaded configuration is a value. (drives and plc,
    which import nothing of ours, declare the same settings.)"""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


#: One problem a section's rules found: the key path (below the section) and the reason.
Problem = tuple[tuple[Any, ...], str]


Port = Annotated[int, Field(ge=0, le=65535)]
Name = Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_-]{0,31}$")]
AxisName = Annotated[str, StringConstraints(pattern=r"^[XYZABCUVW]$")]
# A shared secret: printable ASCII without blanks (it travels on a command line), long
# enough not to be guessed.
Secret = Annotated[str, StringConstraints(pattern=r"^[!-~]{16,128}$")]


class AxisConfig(Section):
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


class KinematicsConfig(Section):
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


class SpindleConfig(Section):
    """The main spindle (`spindle`)."""

    max_rpm: float = Field(8000.0, gt=0, description="Highest speed, rpm.")
    min_rpm: float = Field(0.0, ge=0, description="Lowest programmable speed, rpm.")
    ramp_s: float = Field(1.0, ge=0, description="Time from 0 to max_rpm, s.")


class ToolChangerConfig(Section):
    """Tool changer (`tool_changer`): a mill's ATC magazine or a lathe's turret."""

    kind: Literal["atc", "turret", "manual"] = Field(
        "atc", description="`atc` (magazine + arm), `turret` or `manual` (operator)."
    )
    pockets: int = Field(20, ge=1, le=999, description="Magazine pockets / turret stations.")
    change_time_s: float = Field(2.5, gt=0, description="Time of one M6 change, s.")


class ToolSetterConfig(Section):
    """A tool-length sensor (`probe.tool_setter`): where a G31 skip move finds its skip
    signal (docs/gcode.md, "G31 skip and the tool setter")."""

    x: float = Field(description="Centre of the sensor's contact disc, machine X, mm.")
    y: float = Field(description="Centre of the sensor's contact disc, machine Y, mm.")
    z_trigger: float = Field(
        description="Machine Z of the tool tip (the gauge line minus the tool length) at which"
        " the sensor switches, mm."
    )
    radius: float = Field(5.0, gt=0, description="Radius of the contact disc, mm.")


class ProbeConfig(Section):
    """The machine's measuring sensors (`probe`)."""

    tool_setter: ToolSetterConfig | None = Field(
        None, description="The tool-length sensor; null = none fitted (a G31 never trips)."
    )


class PortsConfig(Section):
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


class ToolConfig(Section):
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


class MachineDataConfig(Section):
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
    macro_variables: dict[int, float] = Field(
        default_factory=dict,
        description="Kept Macro B variables a setter presets (#500-#999, Fanuc 30i-B"
        " #500000-#999999, Haas #10000-#10999): number -> value; the others are vacant.",
    )

    def initial(self):
        """The cnc.machine_data.MachineData this section describes."""
        doc: dict[str, Any] = {
            "tools": {str(n): t.model_dump() for n, t in self.tools.items()},
            "work_offsets": {k: list(v) for k, v in self.work_offsets.items()},
            "parameters": {"power_on_units": self.power_on_units},
            "macro_variables": {str(n): v for n, v in self.macro_variables.items()},
        }
        if self.g92 is not None:
            doc["g92"] = list(self.g92)
        return MachineData.from_dict(doc)


class MachineConfig(Section):
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
    macro_variable_map: Literal["haas_ngc", "kitamura"] = Field(
        "haas_ngc",
        description="Whose Macro B system variables the control has where builders differ:"
        " `haas_ngc` (#10000-#10999 are common variables kept across power cycles, as on a"
        " Haas NGC; #4012 is the G66/G67 modal group, as on a Fanuc) or `kitamura` (a Kitamura"
        " HMC: #10001-#10999 are the tool length offsets H1.. and #11001-#11999 their wear,"
        " #4012 is the current work coordinate system, 54..59 or 54.1); docs/gcode.md.",
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
    probe: ProbeConfig = Field(
        default_factory=ProbeConfig, description="The measuring sensors section (G31 skip)."
    )
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
            macro_variable_map=self.macro_variable_map,
            plc_m_codes=self.plc.nc_m_codes,
            tool_setter=(
                ToolSetter(ts.x, ts.y, ts.z_trigger, ts.radius)
                if (ts := self.probe.tool_setter) is not None
                else None
            ),
            kinematics=(
                (self.kinematics.d_mm, self.kinematics.tool_length_mm, self.kinematics.z_offset_mm)
                if self.kinematics is not None
                else None
            ),
        )


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


class ConfigDocument:
    """A configuration file read for validation: its plain data (YAML merged, machine
    `base:` files resolved) and the position of every key, so that a problem found at a key
    path is reported at the file, line and column that wrote it. The packages above cnc
    that compose a cell (server) validate their sections through it."""

    def __init__(self, src: _Source, data: Mapping[str, Any], marks: _Marks) -> None:
        self.src = src
        self.data = data
        self.marks = marks

    @property
    def file(self) -> str:
        return self.src.file

    def problem(self, path: tuple[Any, ...], reason: str) -> ConfigProblem:
        """The problem `reason` at key path `path`, placed in its file."""
        probe = path
        while probe and probe not in self.marks:
            probe = probe[:-1]
        node = self.marks.get(probe)
        if node is None or node.start_mark.name == "<config>":
            return ConfigProblem(_dotted(path), reason, self.src.file)  # no lines to point at
        m = node.start_mark  # may lie in a `base:` file: its name is in the mark
        return ConfigProblem(_dotted(path), reason, m.name, m.line + 1, m.column + 1)

    def validate(self, model: type[BaseModel], data: Any = None) -> Any:
        """`data` (default: the whole document) as a `model`, or ConfigError."""
        data = self.data if data is None else data
        try:
            return model.model_validate(data)
        except ValidationError as exc:
            raise ConfigError(self.pydantic_problems(exc, model)) from None

    def pydantic_problems(
        self, exc: ValidationError, model: type[BaseModel]
    ) -> list[ConfigProblem]:
        """Pydantic's errors of `model` in the one-line `key.path: reason` form."""
        return [self.problem(_loc(e), _reason(e, model)) for e in exc.errors()]

    def check(self, problems: list[Problem]) -> None:
        """Raise ConfigError when a section's rules found problems (key paths from the root)."""
        if problems:
            raise ConfigError([self.problem(p, r) for p, r in problems])


def read_config(path_or_dict: str | Path | Mapping[str, Any]) -> ConfigDocument:
    """A cell or machine file (or the same data as a mapping), read and prepared for
    validation: duplicate keys and YAML errors are refused here."""
    src = _source_from(path_or_dict)
    data, marks = _prepare(src)
    return ConfigDocument(src, data, marks)


def within(path: tuple[Any, ...], problems: list[Problem]) -> list[Problem]:
    """A section's problems (paths relative to it) placed at `path`."""
    return [((*path, *p), reason) for p, reason in problems]


def _check_machine(name: tuple[Any, ...], m: MachineConfig) -> list[Problem]:
    """Cross-field rules pydantic's per-field constraints cannot express."""
    out: list[Problem] = []
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
    # the sections other packages own check themselves (drives/config.py, plc/config.py)
    out.extend(within((*name, "can"), m.can.problems()))
    out.extend(within((*name, "plc"), m.plc.problems()))
    out.extend(within((*name, "drives"), m.drives.problems(tuple(m.axes))))
    out.extend(_check_machine_data(name, m))
    return out


def _check_machine_data(name: tuple[Any, ...], m: MachineConfig) -> list[Problem]:

    out: list[Problem] = []
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
    for n, value in md.macro_variables.items():
        try:
            MachineData.from_dict({"macro_variables": {str(n): value}})
        except MachineDataError as e:
            out.append(((*base, "macro_variables", n), e.message))
            continue
        if m.macro_variable_map == "kitamura" and 10000 <= n <= 10999:
            reason = (
                "on a `macro_variable_map: kitamura` machine #10001-#10999 are tool length"
                " offsets (machine_data.tools), not kept common variables"
            )
            out.append(((*base, "macro_variables", n), reason))
    return out


def machines_problems(
    machines: Mapping[str, MachineConfig], used: dict[tuple[str, int], str] | None = None
) -> list[Problem]:
    """The rules of every machine of a cell (`machines.<NAME>`) and that no two faces share
    an address and port; `used`: ports taken already, (host, port) -> by whom (a key path)."""
    out: list[Problem] = []
    used = dict(used or {})
    for name, m in machines.items():
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


def validate_machines(doc: ConfigDocument, model: type[BaseModel]) -> Any:
    """The document as `model`, a cell document whose `machines` maps names to
    MachineConfig. When it fails, machines that are valid on their own still get their
    rules checked, so that one run reports as much as possible."""
    try:
        return model.model_validate(doc.data)
    except ValidationError as exc:
        problems = doc.pydantic_problems(exc, model)
        failed = {tuple(e["loc"][:2]) for e in exc.errors()}
        machines = doc.data.get("machines")
        for name, section in machines.items() if isinstance(machines, Mapping) else ():
            if ("machines", name) in failed:
                continue
            try:
                machine = MachineConfig.model_validate(section)
            except ValidationError:
                continue
            problems += [doc.problem(p, r) for p, r in _check_machine(("machines", name), machine)]
        raise ConfigError(problems) from None


class _MachinesOfACell(Section):
    """A cell file as a machine reads it: its `machines`; the `host` section is the host's,
    validated by the cell that composes it (server.config)."""

    machines: dict[Name, MachineConfig] = Field(min_length=1)
    host: dict[str, Any] = Field(default_factory=dict)


def load_machine_config(
    path_or_dict: str | Path | Mapping[str, Any], name: str | None = None
) -> MachineConfig:
    """Load one machine: from a cell file (`machines:`; `name` picks one and may be left
    out when there is only one) or from a machine file (the machine section itself, as the
    shipped cnc/machines/*.yaml; `name` is then ignored). Every machine of a cell file is
    checked, and the ports of all; its `host` section is left to the cell
    (`server.config.load_cell_config`)."""
    doc = read_config(path_or_dict)
    if "machines" not in doc.data:
        machine = doc.validate(MachineConfig)
        doc.check(_check_machine((), machine))
        return machine
    cell = validate_machines(doc, _MachinesOfACell)
    doc.check(machines_problems(cell.machines))
    if name is None and len(cell.machines) == 1:
        name = next(iter(cell.machines))
    if name is None or name not in cell.machines:
        names = ", ".join(cell.machines)
        reason = (
            f"several machines ({names}): name one"
            if name is None
            else f"no machine {name!r} (machines: {names})"
        )
        raise ConfigError([doc.problem(("machines",), reason)])
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


# --- documentation -------------------------------------------------------------------------

#: The machine's sections for the key reference, (title, model); each package's own
#: sections among them (drives, can: drives/config.py; plc: plc/config.py).
MACHINE_SECTIONS: tuple[tuple[str, type[BaseModel]], ...] = (
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
    ("machines.<NAME>.probe", ProbeConfig),
    ("machines.<NAME>.probe.tool_setter", ToolSetterConfig),
    ("machines.<NAME>.machine_data", MachineDataConfig),
    ("machines.<NAME>.machine_data.tools.<N>", ToolConfig),
)


def reference_tables(sections: Sequence[tuple[str, type[BaseModel]]]) -> str:
    """One Markdown table per section: key, default, meaning (server.config composes the
    cell's reference that docs/configuration.md embeds)."""
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
