"""The controller's machine data: tool offset memory, work offsets and kept parameters.

A pure core: plain values in memory, no I/O (cnc.machine_data.store writes it to a file,
cnc.machine_data.files reads tool-table and offset files). One `MachineData` belongs to one
controller; G10 and the operator's faces (REST, DNC port) change it through the methods here,
which validate every number before anything is changed, so a refused change leaves the data
as it was.

Work offsets are indexed as the interpreter keeps them (`_wofs`): 0 = common / EXT,
1..6 = G54..G59, 7..54 = G54.1 P1..P48 (index 6 + P).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, MutableMapping
from dataclasses import dataclass
from typing import Any

from cnc.errors import CncError
from cnc.interp.state import ToolOffset

MAX_TOOL_OFFSET = 999  # H/D/lathe offset numbers 1..999 (Fanuc 0i: up to 999 pairs)
EXTENDED_OFFSETS = 48  # G54.1 P1..P48
WORK_OFFSET_COUNT = 7 + EXTENDED_OFFSETS  # EXT, G54..G59, G54.1 P1..P48
UNITS = ("mm", "inch")
DECIMAL_STYLES = ("calculator", "least_increment")
# A tool offset of a metre or more is a typing error, not a tool (LinuxCNC and Fanuc both
# cap offset input; Fanuc 0i: 999.999 mm geometry).
MAX_OFFSET_MM = 1000.0
MAX_WORK_OFFSET_MM = 10_000.0


class MachineDataError(CncError, ValueError):
    """A refused change: `pointer` is the JSON pointer of the bad value ("" = the whole)."""

    def __init__(self, message: str, pointer: str = "") -> None:
        super().__init__(message)
        self.message = message
        self.pointer = pointer

    def __str__(self) -> str:
        return f"{self.pointer}: {self.message}" if self.pointer else self.message


@dataclass(frozen=True, slots=True)
class ToolData:
    """One entry of the tool offset memory (Fanuc memory C: geometry and wear kept apart).

    Mills: `length` (+ `length_wear`) is applied by G43/G44 H<n>, `radius` (+ `radius_wear`)
    by G41/G42 D<n>. Lathes: `x` (radius value) and `z` (+ their wear) shift the tool tip for
    T<tt><nn>; `radius` is the nose radius and `tip` the imaginary tip number 0..9.
    Tool life: `uses` (tool changes to it) and `cut_time_s` (feed time with it) count up;
    `life_uses` / `life_time_s` are the limits (0 = no limit).
    """

    length: float = 0.0
    length_wear: float = 0.0
    radius: float = 0.0
    radius_wear: float = 0.0
    x: float = 0.0
    x_wear: float = 0.0
    z: float = 0.0
    z_wear: float = 0.0
    tip: int = 0
    uses: int = 0
    cut_time_s: float = 0.0
    life_uses: int = 0
    life_time_s: float = 0.0
    comment: str = ""

    def offset(self) -> ToolOffset:
        """The effective offset the interpreter applies: geometry + wear."""
        return ToolOffset(
            self.length + self.length_wear,
            self.radius + self.radius_wear,
            self.x + self.x_wear,
            self.z + self.z_wear,
        )

    @property
    def expired(self) -> bool:
        """Tool life reached (uses or cutting time at or over a set limit)."""
        return (self.life_uses > 0 and self.uses >= self.life_uses) or (
            self.life_time_s > 0 and self.cut_time_s >= self.life_time_s
        )


TOOL_FIELDS = tuple(f.name for f in dataclasses.fields(ToolData))
_FLOAT_FIELDS = frozenset(
    ("length", "length_wear", "radius", "radius_wear", "x", "x_wear", "z", "z_wear")
)
_INT_FIELDS = frozenset(("tip", "uses", "life_uses"))


def work_offset_name(index: int) -> str:
    """`EXT`, `G54`..`G59`, `G54.1P1`..`G54.1P48` for an index of the work offset list."""
    if index == 0:
        return "EXT"
    if 1 <= index <= 6:
        return f"G{53 + index}"
    if 7 <= index < WORK_OFFSET_COUNT:
        return f"G54.1P{index - 6}"
    raise MachineDataError(f"work offset index {index} is not 0..{WORK_OFFSET_COUNT - 1}")


def work_offset_index(name: str) -> int:
    """The inverse of `work_offset_name`; accepts `G54.1 P7`, `P7`, `EXT`, `COMMON`, `G54`."""
    n = name.strip().upper().replace(" ", "")
    if n in ("EXT", "COMMON", "G54.1P0"):
        return 0
    if n.startswith("G54.1P"):
        n = "P" + n[6:]
    if n.startswith("P") and n[1:].isdigit():
        p = int(n[1:])
        if 1 <= p <= EXTENDED_OFFSETS:
            return 6 + p
        raise MachineDataError(f"{name}: extended work offset P{p} is not P1..P{EXTENDED_OFFSETS}")
    if n.startswith("G") and n[1:].isdigit() and 54 <= int(n[1:]) <= 59:
        return int(n[1:]) - 53
    raise MachineDataError(f"{name!r} is not a work offset (EXT, G54..G59, G54.1P1..P48)")


def _number(value: Any, pointer: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MachineDataError(f"must be a number, got {value!r}", pointer)
    v = float(value)
    if not math.isfinite(v) or not lo <= v <= hi:
        raise MachineDataError(f"must be within {lo:g} .. {hi:g}, got {value!r}", pointer)
    return v


def _integer(value: Any, pointer: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise MachineDataError(f"must be an integer, got {value!r}", pointer)
    if not lo <= value <= hi:
        raise MachineDataError(f"must be within {lo} .. {hi}, got {value}", pointer)
    return value


def check_tool_number(number: Any, pointer: str = "") -> int:
    return _integer(number, pointer, 1, MAX_TOOL_OFFSET)


def tool_from_mapping(data: Any, pointer: str, base: ToolData | None = None) -> ToolData:
    """A ToolData from a JSON-like mapping; keys left out keep `base`'s value (or 0)."""
    if not isinstance(data, Mapping):
        raise MachineDataError(f"must be an object, got {type(data).__name__}", pointer)
    values: dict[str, Any] = {}
    for key, v in data.items():
        p = f"{pointer}/{key}"
        if key in _FLOAT_FIELDS:
            values[key] = _number(v, p, -MAX_OFFSET_MM, MAX_OFFSET_MM)
        elif key == "tip":
            values[key] = _integer(v, p, 0, 9)
        elif key in ("uses", "life_uses"):
            values[key] = _integer(v, p, 0, 10**9)
        elif key in ("cut_time_s", "life_time_s"):
            values[key] = _number(v, p, 0.0, 1e10)
        elif key == "comment":
            if not isinstance(v, str) or len(v) > 80:
                raise MachineDataError("must be a text of at most 80 characters", p)
            values[key] = v
        else:
            raise MachineDataError(f"unknown key (keys: {', '.join(TOOL_FIELDS)})", p)
    return dataclasses.replace(base or ToolData(), **values)


def _xyz(value: Any, pointer: str) -> tuple[float, float, float]:
    """An offset vector: [x, y, z] or {"x":..,"y":..,"z":..} (missing keys 0)."""
    lim = MAX_WORK_OFFSET_MM
    if isinstance(value, Mapping):
        for k in value:
            if k not in ("x", "y", "z", "X", "Y", "Z"):
                raise MachineDataError("unknown axis (x, y, z)", f"{pointer}/{k}")
        low = {str(k).lower(): v for k, v in value.items()}
        return (
            _number(low.get("x", 0.0), f"{pointer}/x", -lim, lim),
            _number(low.get("y", 0.0), f"{pointer}/y", -lim, lim),
            _number(low.get("z", 0.0), f"{pointer}/z", -lim, lim),
        )
    if isinstance(value, list | tuple) and len(value) == 3:
        return (
            _number(value[0], f"{pointer}/0", -lim, lim),
            _number(value[1], f"{pointer}/1", -lim, lim),
            _number(value[2], f"{pointer}/2", -lim, lim),
        )
    raise MachineDataError("must be [x, y, z] or {x, y, z} in mm", pointer)


# Fanuc #500-#999 and the 30i-B added #500000-#999999, Haas NGC #10000-#10999
KEPT_VARIABLES = (range(500, 1000), range(500000, 1000000), range(10000, 11000))


class KeptVariables(MutableMapping):
    """Macro B common variables kept across power cycles (#500-#999, the Fanuc 30i-B added
    #500000-#999999, Haas #10000-#10999), as
    the interpreter's `macro_variables` store: a vacant variable is an absent key. Each
    write counts the owner's revision, so the machine saves them like its offsets."""

    __slots__ = ("_owner", "_values")

    def __init__(self, owner: MachineData) -> None:
        self._owner = owner
        self._values: dict[int, float] = {}

    def __getitem__(self, number: int) -> float:
        return self._values[number]

    def __setitem__(self, number: int, value: float) -> None:
        p = f"/macro_variables/{number}"
        if not isinstance(number, int) or not any(number in r for r in KEPT_VARIABLES):
            raise MachineDataError(
                "a kept macro variable is #500-#999, #500000-#999999 or #10000-#10999", p
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise MachineDataError(f"must be a number, got {value!r}", p)
        if not math.isfinite(value):
            raise MachineDataError(f"must be finite, got {value!r}", p)
        if self._values.get(number) != float(value):
            self._values[number] = float(value)
            self._owner.revision += 1

    def __delitem__(self, number: int) -> None:
        del self._values[number]
        self._owner.revision += 1

    def __iter__(self):
        return iter(list(self._values))

    def __len__(self) -> int:
        return len(self._values)

    def to_dict(self) -> dict[str, float]:
        values = dict(self._values)
        return {str(n): values[n] for n in sorted(values)}

    def load(self, data: Any, pointer: str = "/macro_variables") -> None:
        """Replace all from {"<n>": value}; all or nothing."""
        if not isinstance(data, Mapping):
            raise MachineDataError("must be an object {number: value}", pointer)
        scratch = KeptVariables(self._owner)
        for key, v in data.items():
            try:
                n = int(str(key))
            except ValueError:
                raise MachineDataError(
                    "variable number must be an integer", f"{pointer}/{key}"
                ) from None
            scratch[n] = v
        self._values = scratch._values
        self._owner.revision += 1


class MachineData:
    """Tool offsets, work offsets, the G92 shift and the parameters kept across power cycles.

    `revision` counts changes: a shell compares it with the revision it last saved.
    """

    def __init__(
        self,
        tools: Mapping[int, ToolData] | None = None,
        work_offsets: Mapping[int, Iterable[float]] | None = None,
        *,
        g92: Iterable[float] = (0.0, 0.0, 0.0),
        power_on_units: str = "mm",
        decimal_style: str | None = None,
    ) -> None:
        self.tools: dict[int, ToolData] = {}
        self.work_offsets: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * (
            WORK_OFFSET_COUNT
        )
        self.g92: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.power_on_units = "mm"
        self.decimal_style: str | None = None
        self.macro_variables = KeptVariables(self)
        self.revision = 0
        for n, t in (tools or {}).items():
            self.set_tool(n, t)
        for i, v in (work_offsets or {}).items():
            self.set_work_offset(i, v)
        self.set_g92(g92)
        self.set_parameters(power_on_units=power_on_units, decimal_style=decimal_style)
        self.revision = 0

    # --- reading ------------------------------------------------------------------------

    def tool_offsets(self) -> dict[int, ToolOffset]:
        """The interpreter's view: number -> effective offset (geometry + wear)."""
        return {n: t.offset() for n, t in self.tools.items()}

    def copy(self) -> MachineData:
        """An independent copy (a check or a plan works on one; the controller keeps its own).

        Taken from snapshots of the table and the list (one C-level copy each), so a face
        thread may copy while the machine's thread books tool life."""
        out = MachineData.__new__(MachineData)
        out.tools = dict(self.tools)  # ToolData entries are frozen: shared safely
        out.work_offsets = list(self.work_offsets)
        out.g92 = self.g92
        out.power_on_units = self.power_on_units
        out.decimal_style = self.decimal_style
        out.macro_variables = KeptVariables(out)
        out.macro_variables._values = dict(self.macro_variables._values)
        out.revision = self.revision
        return out

    def __eq__(self, other: object) -> bool:
        return isinstance(other, MachineData) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]  # mutable

    # --- changing (each validates first, then changes, then counts the revision) -------

    def set_tool(self, number: Any, tool: ToolData | Mapping[str, Any], *, merge=False) -> None:
        n = check_tool_number(number, f"/tools/{number}")
        if not isinstance(tool, ToolData):
            tool = tool_from_mapping(tool, f"/tools/{n}", self.tools.get(n) if merge else None)
        else:
            tool_from_mapping(dataclasses.asdict(tool), f"/tools/{n}")  # range checks
        self.tools[n] = tool
        self.revision += 1

    def update_tool(self, number: Any, **fields: Any) -> ToolData:
        """Change some fields of tool offset `number` (created at 0 when missing)."""
        n = check_tool_number(number, f"/tools/{number}")
        new = tool_from_mapping(fields, f"/tools/{n}", self.tools.get(n))
        self.tools[n] = new
        self.revision += 1
        return new

    def delete_tool(self, number: Any) -> None:
        n = check_tool_number(number, f"/tools/{number}")
        if self.tools.pop(n, None) is not None:
            self.revision += 1

    def set_work_offset(self, index: Any, xyz: Any) -> None:
        i = _integer(index, f"/work_offsets/{index}", 0, WORK_OFFSET_COUNT - 1)
        self.work_offsets[i] = _xyz(xyz, f"/work_offsets/{work_offset_name(i)}")
        self.revision += 1

    def set_g92(self, xyz: Any) -> None:
        v = _xyz(list(xyz) if not isinstance(xyz, Mapping) else xyz, "/g92")
        if v != self.g92:
            self.g92 = v
            self.revision += 1

    def set_parameters(self, *, power_on_units: Any = None, decimal_style: Any = "keep") -> None:
        if power_on_units is not None and power_on_units not in UNITS:
            raise MachineDataError(
                f"must be mm or inch, got {power_on_units!r}", "/parameters/power_on_units"
            )
        if decimal_style not in ("keep", None, *DECIMAL_STYLES):
            raise MachineDataError(
                f"must be calculator, least_increment or null, got {decimal_style!r}",
                "/parameters/decimal_style",
            )
        if power_on_units is not None:
            self.power_on_units = power_on_units
        if decimal_style != "keep":
            self.decimal_style = decimal_style
        self.revision += 1

    def count_use(self, number: int, cut_time_s: float = 0.0) -> None:
        """Tool life: one more use and/or some more cutting time for tool offset `number`."""
        t = self.tools.get(number)
        if t is None:
            return
        self.tools[number] = dataclasses.replace(
            t, uses=t.uses + (1 if cut_time_s == 0.0 else 0), cut_time_s=t.cut_time_s + cut_time_s
        )
        self.revision += 1

    def replace_with(self, other: MachineData) -> None:
        """Take all of `other` (a validated whole, e.g. a PUT or a loaded file) at once."""
        self.tools = dict(other.tools)
        self.work_offsets = list(other.work_offsets)
        self.g92 = other.g92
        self.power_on_units = other.power_on_units
        self.decimal_style = other.decimal_style
        self.macro_variables._values = dict(other.macro_variables._values)
        self.revision += 1

    # --- JSON form ----------------------------------------------------------------------

    def tools_dict(self) -> dict[str, dict[str, Any]]:
        tools = dict(self.tools)  # a snapshot: another thread may book tool life meanwhile
        return {str(n): dataclasses.asdict(tools[n]) for n in sorted(tools)}

    def offsets_dict(self) -> dict[str, Any]:
        offsets = list(self.work_offsets)
        return {
            "work_offsets": {work_offset_name(i): list(v) for i, v in enumerate(offsets)},
            "g92": list(self.g92),
        }

    def parameters_dict(self) -> dict[str, Any]:
        return {"power_on_units": self.power_on_units, "decimal_style": self.decimal_style}

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": 1,
            "tools": self.tools_dict(),
            **self.offsets_dict(),
            "parameters": self.parameters_dict(),
            "macro_variables": self.macro_variables.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: Any) -> MachineData:
        """Validate a whole JSON document (`to_dict`'s form; every key optional)."""
        if not isinstance(data, Mapping):
            raise MachineDataError(f"must be an object, got {type(data).__name__}", "")
        for key in data:
            if key not in (
                "format",
                "tools",
                "work_offsets",
                "g92",
                "parameters",
                "macro_variables",
            ):
                raise MachineDataError(
                    "unknown key (format, tools, work_offsets, g92, parameters, macro_variables)",
                    f"/{key}",
                )
        if data.get("format", 1) != 1:
            raise MachineDataError(f"unknown format {data.get('format')!r}", "/format")
        md = cls()
        md.set_tools_from(data.get("tools", {}))
        md.set_offsets_from({k: data[k] for k in ("work_offsets", "g92") if k in data})
        params = data.get("parameters", {})
        if not isinstance(params, Mapping):
            raise MachineDataError("must be an object", "/parameters")
        for k in params:
            if k not in ("power_on_units", "decimal_style"):
                raise MachineDataError(
                    "unknown key (power_on_units, decimal_style)", f"/parameters/{k}"
                )
        md.set_parameters(
            power_on_units=params.get("power_on_units", "mm"),
            decimal_style=params.get("decimal_style"),
        )
        md.macro_variables.load(data.get("macro_variables", {}))
        md.revision = 0
        return md

    def set_tools_from(self, tools: Any, pointer: str = "/tools") -> None:
        """Replace the whole tool table from {"<n>": {...}}; all or nothing."""
        if not isinstance(tools, Mapping):
            raise MachineDataError("must be an object {number: tool}", pointer)
        new: dict[int, ToolData] = {}
        for key, v in tools.items():
            p = f"{pointer}/{key}"
            try:
                n = int(str(key))
            except ValueError:
                raise MachineDataError("tool offset number must be an integer", p) from None
            check_tool_number(n, p)
            new[n] = tool_from_mapping(v, p)
        self.tools = new
        self.revision += 1

    def set_offsets_from(self, data: Any, pointer: str = "") -> None:
        """Replace work offsets (by name; names left out keep their value) and G92; all or
        nothing."""
        if not isinstance(data, Mapping):
            raise MachineDataError("must be an object", pointer or "")
        for key in data:
            if key not in ("work_offsets", "g92"):
                raise MachineDataError("unknown key (work_offsets, g92)", f"{pointer}/{key}")
        wo = data.get("work_offsets", {})
        if not isinstance(wo, Mapping):
            raise MachineDataError("must be an object {name: [x, y, z]}", f"{pointer}/work_offsets")
        offsets = list(self.work_offsets)
        for name, v in wo.items():
            p = f"{pointer}/work_offsets/{name}"
            try:
                i = work_offset_index(str(name))
            except MachineDataError as e:
                raise MachineDataError(e.message, p) from None
            offsets[i] = _xyz(v, p)
        g92 = _xyz(data["g92"], f"{pointer}/g92") if "g92" in data else self.g92
        self.work_offsets = offsets
        self.g92 = g92
        self.revision += 1


def machine_data_from_config(section: Any) -> MachineData:
    """MachineData from a machine YAML's already-validated `machine_data` section (or None)."""
    if section is None:
        return MachineData()
    return MachineData.from_dict(section)
