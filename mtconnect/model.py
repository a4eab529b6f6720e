"""The agent's device model, generated from the cell configuration.

One MTConnect Device per machine, its data items taken from the declared SHDR table of the
machine's status face (`cnc.faces.shdr.shdr_items`), so the adapter and the agent can never
disagree on a key:

    Device mill1            Availability, AssetChanged, AssetRemoved
      Axes base             ACTUATOR condition (drive alarms without an axis)
        Linear X, Y, Z      POSITION ACTUAL/COMMANDED (mm), ACTUATOR condition
        Rotary C (spindle)  ROTARY_VELOCITY, LOAD, ROTARY_VELOCITY_OVERRIDE, ROTARY_MODE
      Controller controller EMERGENCY_STOP, CONTROLLER_MODE, conditions per alarm source, ...
        Path path           EXECUTION, PROGRAM, LINE_NUMBER, BLOCK, PATH_FEEDRATE, ...
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from cnc.faces.shdr import ROTARY_AXES, ShdrItem, shdr_items, spindle_name
from cnc.status import EXECUTION


@dataclass(frozen=True, slots=True)
class DataItem:
    id: str
    name: str
    category: str  # SAMPLE | EVENT | CONDITION
    type: str
    component_id: str
    sub_type: str | None = None
    units: str | None = None
    native_units: str | None = None
    statistic: str | None = None  # AVERAGE, MAXIMUM: a statistic, not a subType in 2.5

    @property
    def element(self) -> str:
        """The observation's element name in a Streams document (POSITION -> Position)."""
        return pascal(self.type)

    def accepts(self, value: str) -> bool:
        """Whether `value` is a valid result for this data item in an MTConnectStreams 2.5
        document: samples are xs:float, integer and float events their XML types, controlled
        vocabularies their words. UNAVAILABLE is always valid; anything else the schema
        would reject is refused here so that a bad adapter value cannot make an invalid
        document."""
        if value == "UNAVAILABLE":
            return True
        if self.category == "SAMPLE":
            if self.units is not None and self.units.endswith("_3D"):
                # a three-space sample (PATH_POSITION): 'X Y Z', ThreeSpaceValueType
                parts = value.split()
                return len(parts) == 3 and all(_XS_FLOAT.match(p) for p in parts)
            return _XS_FLOAT.match(value) is not None
        kind = EVENT_VALUES.get(self.type)
        if kind is None:
            return True  # string events and extensions
        if kind == "integer":
            return _XS_INTEGER.match(value) is not None
        if kind == "float":
            return _XS_FLOAT.match(value) is not None
        return value in kind


@dataclass(slots=True)
class Component:
    kind: str  # Device, Axes, Linear, Rotary, Controller, Path
    id: str
    name: str
    data_items: list[DataItem] = field(default_factory=list)
    children: list[Component] = field(default_factory=list)

    def walk(self):
        yield self
        for child in self.children:
            yield from child.walk()


@dataclass(slots=True)
class Device(Component):
    uuid: str = ""
    description: str = ""
    by_key: dict[str, DataItem] = field(default_factory=dict)  # SHDR key -> data item
    components: dict[str, Component] = field(default_factory=dict)  # id -> component

    @property
    def all_items(self) -> list[DataItem]:
        return [di for comp in self.walk() for di in comp.data_items]


# The lexical spaces of xs:float and xs:integer (XML Schema part 2), as the schemas check them.
_XS_FLOAT = re.compile(r"^(?:[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?|[+-]?INF|NaN)$")
_XS_INTEGER = re.compile(r"^[+-]?\d+$")

# Event value types of MTConnectStreams 2.5 for the event types this agent publishes:
# IntegerEvent, FloatEvent, or the controlled vocabulary of the event (without UNAVAILABLE,
# which every event accepts). Event types not listed are string events.
EVENT_VALUES: dict[str, str | frozenset[str]] = {
    "LINE_NUMBER": "integer",
    "PART_COUNT": "integer",
    "PATH_FEEDRATE_OVERRIDE": "float",
    "ROTARY_VELOCITY_OVERRIDE": "float",
    "AVAILABILITY": frozenset({"AVAILABLE"}),
    "EMERGENCY_STOP": frozenset({"ARMED", "TRIGGERED"}),
    "CONTROLLER_MODE": frozenset(
        {"AUTOMATIC", "MANUAL", "MANUAL_DATA_INPUT", "SEMI_AUTOMATIC", "EDIT", "FEED_HOLD"}
    ),
    # what the controller reports (cnc.status) plus the two 2.5 values it never sends
    "EXECUTION": frozenset(EXECUTION) | {"WAIT", "PROGRAM_OPTIONAL_STOP"},
    "ROTARY_MODE": frozenset({"SPINDLE", "INDEX", "CONTOUR"}),
}

# Condition qualifiers of MTConnectStreams 2.5 (QualifierType).
QUALIFIERS = frozenset({"HIGH", "LOW"})

# Words the SHDR table uses as a subType that MTConnect 2.5 has as a DataItem `statistic`
# (DataItemStatisticsEnum) and not in DataItemSubEnumEnum: AVERAGE is no subType at all.
STATISTICS = frozenset({"AVERAGE", "MAXIMUM", "MINIMUM"})

# Data items the agent owns (asset events): an adapter cannot write them.
AGENT_OWNED = frozenset({"ASSET_CHANGED", "ASSET_REMOVED"})

# xs:NCName, simplified to ASCII: ids and componentIds are xs:ID in the 2.5 schemas.
_NCNAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")


def pascal(type_: str) -> str:
    """MTConnect element name of a data item type; `x:FOO_BAR` keeps its prefix."""
    prefix, _, name = type_.rpartition(":")
    text = "".join(part.capitalize() for part in name.split("_"))
    return f"{prefix}:{text}" if prefix else text


def build_device(
    name: str,
    axes: Sequence[str],
    *,
    uuid: str | None = None,
    description: str = "",
    tool_tip: bool = False,
) -> Device:
    """The Device of one machine with these axes."""
    if not _NCNAME.match(name):
        raise ValueError(
            f"machine name {name!r} cannot name an MTConnect device: ids are xs:ID, so the "
            "name must start with a letter or '_' and hold only letters, digits, '_', '-', '.'"
        )
    device = Device("Device", name, name, uuid=uuid or f"fmscell-{name}", description=description)
    axes_c = Component("Axes", f"{name}_axes", "base")
    controller = Component("Controller", f"{name}_cont", "controller")
    path = Component("Path", f"{name}_path", "path")
    controller.children.append(path)
    device.children += [axes_c, controller]
    by_component: dict[str, Component] = {
        "Device": device,
        "Axes": axes_c,
        "Controller": controller,
        "Path": path,
    }
    for axis in axes:
        kind = "Rotary" if axis in ROTARY_AXES else "Linear"
        comp = Component(kind, f"{name}_{axis.lower()}", axis)
        axes_c.children.append(comp)
        by_component[axis] = comp
    spindle = Component("Rotary", f"{name}_{spindle_name(axes).lower()}", spindle_name(axes))
    axes_c.children.append(spindle)
    by_component["Spindle"] = spindle

    def add(item: ShdrItem) -> None:
        comp = by_component[item.component]
        sub_type, statistic = item.sub_type, None
        if item.category == "SAMPLE" and sub_type in STATISTICS:
            sub_type, statistic = None, sub_type
        di = DataItem(
            id=f"{name}_{item.key}",
            name=item.key,
            category=item.category,
            type=item.type,
            component_id=comp.id,
            sub_type=sub_type,
            units=item.units,
            native_units=item.native_units,
            statistic=statistic,
        )
        comp.data_items.append(di)
        device.by_key[item.key] = di

    for item in shdr_items(axes, tool_tip):
        add(item)
    # MTConnect 2.x devices carry the asset events; the agent owns them (no assets yet).
    add(ShdrItem("asset_chg", "EVENT", "ASSET_CHANGED", "Device"))
    add(ShdrItem("asset_rem", "EVENT", "ASSET_REMOVED", "Device"))
    device.components = {c.id: c for c in device.walk()}
    return device


def devices_from_cell(cell) -> list[Device]:
    """One Device per machine of a `server.config.CellConfig`, in file order."""
    return [
        build_device(name, list(m.axes), description=m.description, tool_tip=m.kind == "mill5")
        for name, m in cell.machines.items()
    ]


# --- the model as an element tree (probe document body and XPath filtering) ---------------


def component_element(comp: Component) -> ET.Element:
    attrs = {"id": comp.id, "name": comp.name}
    if isinstance(comp, Device):
        attrs["uuid"] = comp.uuid
    el = ET.Element(comp.kind, attrs)
    if isinstance(comp, Device):
        desc = ET.SubElement(el, "Description", {"manufacturer": "fmscell"})
        desc.text = comp.description or None
    if comp.data_items:
        items = ET.SubElement(el, "DataItems")
        for di in comp.data_items:
            ET.SubElement(items, "DataItem", _item_attrs(di))
    if comp.children:
        children = ET.SubElement(el, "Components")
        for child in comp.children:
            children.append(component_element(child))
    return el


def _item_attrs(di: DataItem) -> Mapping[str, str]:
    attrs = {"category": di.category, "id": di.id, "name": di.name, "type": di.type}
    if di.sub_type:
        attrs["subType"] = di.sub_type
    if di.statistic:
        attrs["statistic"] = di.statistic
    if di.units:
        attrs["units"] = di.units
    if di.native_units:
        attrs["nativeUnits"] = di.native_units
    return attrs


def devices_element(devices: Sequence[Device]) -> ET.Element:
    root = ET.Element("Devices")
    for d in devices:
        root.append(component_element(d))
    return root
