"""Shared helpers for the MTConnect tests (no tests here): a small agent, document checks."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

from mtconnect import Agent, build_device

NS = {
    "Streams": "urn:mtconnect.org:MTConnectStreams:2.5",
    "Devices": "urn:mtconnect.org:MTConnectDevices:2.5",
    "Error": "urn:mtconnect.org:MTConnectError:2.5",
}
T0 = 1_795_000_000.0  # 2026-11-18


class FakeClock:
    def __init__(self, t: float = T0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def small_agent(**kw) -> Agent:
    devices = [build_device("m1", ["X", "Y", "Z"]), build_device("m2", ["X", "Z"])]
    kw.setdefault("clock", FakeClock())
    return Agent(devices, **kw)


def parse(kind: str, text: str) -> ET.Element:
    """Parse a document, checking what every MTConnect 2.5 document of that kind has."""
    root = ET.fromstring(text.encode())
    ns = NS[kind]
    assert root.tag == f"{{{ns}}}MTConnect{kind}", root.tag
    header = root.find(f"{{{ns}}}Header")
    assert header is not None
    for attr in ("creationTime", "sender", "instanceId", "version", "bufferSize"):
        assert header.get(attr), attr
    assert header.get("version").startswith("2.5")
    return root


def header(root: ET.Element) -> dict[str, str]:
    return dict(root[0].attrib)


def seqs(root: ET.Element) -> list[int]:
    """Sequence numbers of every observation in a Streams document, ascending (the document
    groups them by component)."""
    return sorted(int(e.get("sequence")) for e in root.iter() if e.get("sequence"))


def values(root: ET.Element) -> dict[str, list[str]]:
    """dataItemId -> observed values (a condition's level) in a Streams document."""
    out: dict[str, list[str]] = {}
    for e in root.iter():
        if e.get("dataItemId"):
            tag = e.tag.split("}")[1]
            value = tag.upper() if tag in ("Normal", "Warning", "Fault", "Unavailable") else e.text
            out.setdefault(e.get("dataItemId"), []).append(value)
    return out


def error_code(text: str) -> tuple[str, str]:
    root = parse("Error", text)
    errors = root.findall(f".//{{{NS['Error']}}}Error")
    assert len(errors) == 1
    return errors[0].get("errorCode"), errors[0].text


# --- what the MTConnect 2.5 XSDs require of the documents this agent prints ---------------
#
# Written from MTConnectDevices/Streams/Error_2.5.xsd (see docs/mtconnect.md, "Schema
# validation"): CI has no copy of the schemas, so each rule that the agent once broke, and
# the main structural rules of what it emits, is restated here and checked on every document.

XS_FLOAT = re.compile(r"^(?:[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?|[+-]?INF|NaN)$")
XS_INTEGER = re.compile(r"^[+-]?\d+$")
XS_DATETIME = re.compile(r"^-?\d{4,}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?(Z|[+-]\d{2}:\d{2})?$")
NCNAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")
EXTENSION_WORD = re.compile(r"^[a-ln-z][a-z]*:[A-Z_0-9]+$")  # the schemas' *ExtType pattern

# Header attributes: (required, optional) per document (HeaderType of each schema).
HEADER_ATTRS = {
    "Error": (
        {"version", "creationTime", "instanceId", "sender", "bufferSize"},
        {"testIndicator"},
    ),
    "Devices": (
        {
            "version",
            "creationTime",
            "instanceId",
            "sender",
            "deviceModelChangeTime",
            "bufferSize",
            "assetBufferSize",
            "assetCount",
        },
        {"testIndicator", "validation"},
    ),
    "Streams": (
        {
            "version",
            "creationTime",
            "instanceId",
            "sender",
            "deviceModelChangeTime",
            "bufferSize",
            "nextSequence",
            "lastSequence",
            "firstSequence",
        },
        {"testIndicator", "validation"},
    ),
}
HEADER_MINIMUM = {  # xs:integer attributes and their minInclusive
    "instanceId": 1,
    "bufferSize": 1,
    "assetBufferSize": 1,
    "assetCount": 0,
    "nextSequence": 1,
    "lastSequence": 1,
    "firstSequence": 1,
}
HEADER_TIMES = ("creationTime", "deviceModelChangeTime")

# ErrorCodeType of MTConnectError 2.5 (cppagent's INVALID_XPATH and QUERY_ERROR are not in
# it: this agent sends INVALID_PATH and INVALID_REQUEST instead).
ERROR_CODES_25 = {
    "UNAUTHORIZED",
    "NO_DEVICE",
    "OUT_OF_RANGE",
    "TOO_MANY",
    "INVALID_URI",
    "INVALID_REQUEST",
    "INTERNAL_ERROR",
    "INVALID_PATH",
    "UNSUPPORTED",
    "ASSET_NOT_FOUND",
}

OBSERVATION_ATTRS = {
    "sequence",
    "subType",
    "timestamp",
    "name",
    "dataItemId",
    "compositionId",
    "deprecated",
    "extended",
    "quality",
}
# Attributes each kind of observation may carry besides OBSERVATION_ATTRS, and must carry.
OBSERVATION_KINDS = {
    "Sample": ({"sampleRate", "resetTriggered", "statistic", "duration"}, set()),
    "Event": ({"resetTriggered"}, set()),
    "AssetEvent": ({"resetTriggered", "assetType", "hash"}, {"assetType"}),
    "Normal": ({"type", "nativeCode", "nativeSeverity", "qualifier", "statistic"}, {"type"}),
    "Unavailable": ({"type", "nativeCode", "nativeSeverity", "qualifier", "statistic"}, {"type"}),
    "Warning": (
        {"type", "nativeCode", "nativeSeverity", "qualifier", "statistic", "conditionId"},
        {"type", "conditionId"},
    ),
    "Fault": (
        {"type", "nativeCode", "nativeSeverity", "qualifier", "statistic", "conditionId"},
        {"type", "conditionId"},
    ),
}
# Value space of each standard observation element the agent prints: "float" (CommonSample,
# FloatEvent), "integer" (IntegerEvent), "string" (StringEvent) or the controlled words.
OBSERVATION_VALUES = {
    "Position": "float",
    "PathFeedrate": "float",
    "RotaryVelocity": "float",
    "Load": "float",
    "PathFeedrateOverride": "float",
    "RotaryVelocityOverride": "float",
    "LineNumber": "integer",
    "PartCount": "integer",
    "Program": "string",
    "Block": "string",
    "AssetChanged": "string",
    "AssetRemoved": "string",
    "Availability": {"AVAILABLE"},
    "EmergencyStop": {"ARMED", "TRIGGERED"},
    "ControllerMode": {
        "AUTOMATIC",
        "MANUAL",
        "MANUAL_DATA_INPUT",
        "SEMI_AUTOMATIC",
        "EDIT",
        "FEED_HOLD",
    },
    "Execution": {
        "READY",
        "ACTIVE",
        "INTERRUPTED",
        "FEED_HOLD",
        "STOPPED",
        "OPTIONAL_STOP",
        "PROGRAM_STOPPED",
        "PROGRAM_COMPLETED",
        "WAIT",
        "PROGRAM_OPTIONAL_STOP",
    },
    "RotaryMode": {"SPINDLE", "INDEX", "CONTOUR"},
}
SAMPLE_ELEMENTS = {"Position", "PathFeedrate", "RotaryVelocity", "Load"}
# Words of the 2.5 enumerations that the agent uses (DataItemSubEnumEnum, DataItemStatistics-
# Enum, UnitsEnum); AVERAGE is a statistic only, never a subType.
SUB_TYPES_25 = {"ABSOLUTE", "ACTUAL", "COMMANDED", "PROGRAMMED", "RAPID", "MAXIMUM", "MINIMUM"}
STATISTICS_25 = {"AVERAGE", "MAXIMUM", "MINIMUM"}
UNITS_25 = {"MILLIMETER", "DEGREE", "MILLIMETER/SECOND", "REVOLUTION/MINUTE", "PERCENT"}
QUALIFIERS_25 = {"HIGH", "LOW"}
DATA_ITEM_ATTRS = {
    "name",
    "id",
    "type",
    "subType",
    "statistic",
    "units",
    "nativeUnits",
    "nativeScale",
    "category",
    "coordinateSystem",
    "coordinateSystemIdRef",
    "compositionId",
    "sampleRate",
    "representation",
    "significantDigits",
    "discrete",
}
COMPONENT_CHILDREN = {"Description", "Configuration", "DataItems", "Components"}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _word(value: str | None, standard: set[str]) -> bool:
    return value is None or value in standard or EXTENSION_WORD.match(value) is not None


def schema_problems(text: str) -> list[str]:
    """Every place where `text` breaks one of the rules above; [] for a valid document."""
    root = ET.fromstring(text.encode())
    kind = _local(root.tag).removeprefix("MTConnect")
    ns = NS[kind]
    out: list[str] = []
    location = root.get("{http://www.w3.org/2001/XMLSchema-instance}schemaLocation", "")
    if not location.startswith(f"{ns} ") or not location.split()[1].endswith("_2.5.xsd"):
        out.append(f"schemaLocation {location!r} does not name {ns} and its 2.5 XSD")
    head = root.find(f"{{{ns}}}Header")
    required, optional = HEADER_ATTRS[kind]
    got = set(head.attrib)
    out += [f"Header lacks {a}" for a in sorted(required - got)]
    out += [f"Header may not carry {a}" for a in sorted(got - required - optional)]
    for a, low in HEADER_MINIMUM.items():
        v = head.get(a)
        if v is not None and not (XS_INTEGER.match(v) and int(v) >= low):
            out.append(f"Header {a}={v!r} is not an integer >= {low}")
    out += [
        f"Header {a}={head.get(a)!r} is no xs:dateTime"
        for a in HEADER_TIMES
        if head.get(a) is not None and not XS_DATETIME.match(head.get(a))
    ]
    if kind == "Error":
        for e in root.iter(f"{{{ns}}}Error"):
            if e.get("errorCode") not in ERROR_CODES_25:
                out.append(f"errorCode {e.get('errorCode')!r} is not a 2.5 ErrorCodeType")
    elif kind == "Devices":
        out += _devices_problems(root, ns)
    else:
        out += _streams_problems(root, ns)
    return out


def _devices_problems(root: ET.Element, ns: str) -> list[str]:
    out = []
    devices = root.find(f"{{{ns}}}Devices")
    if devices is None or not devices.findall(f"{{{ns}}}Device"):
        out.append("Devices holds no Device (minOccurs 1)")
    ids = [e.get("id") for e in root.iter() if e.get("id") is not None]
    if len(ids) != len(set(ids)):
        out.append("ids are not unique (xs:ID)")
    out += [f"id {i!r} is no NCName" for i in ids if not NCNAME.match(i)]
    for el in root.iter():
        tag = _local(el.tag)
        if el.get("id") is not None and tag != "DataItem":
            children = [_local(c.tag) for c in el]
            out += [
                f"{tag} {el.get('id')}: unknown child {c}"
                for c in children
                if c not in COMPONENT_CHILDREN
            ]
            out += [
                f"{tag} {el.get('id')}: {c} twice" for c in set(children) if children.count(c) > 1
            ]
            for group in ("DataItems", "Components"):
                g = el.find(f"{{{ns}}}{group}")
                if g is not None and len(g) == 0:
                    out.append(f"{tag} {el.get('id')}: empty {group}")
            if tag == "Device" and not (el.get("uuid") and el.get("name")):
                out.append(f"Device {el.get('id')} lacks uuid or name")
        if tag == "DataItem":
            a = el.attrib
            where = f"DataItem {a.get('id')}"
            out += [f"{where}: attribute {k} not allowed" for k in set(a) - DATA_ITEM_ATTRS]
            out += [f"{where}: lacks {k}" for k in ("id", "type", "category") if k not in a]
            if a.get("category") not in ("SAMPLE", "EVENT", "CONDITION"):
                out.append(f"{where}: category {a.get('category')!r}")
            if not _word(a.get("subType"), SUB_TYPES_25):
                out.append(f"{where}: subType {a.get('subType')!r} is not a 2.5 subType")
            if not _word(a.get("statistic"), STATISTICS_25):
                out.append(f"{where}: statistic {a.get('statistic')!r}")
            if not _word(a.get("units"), UNITS_25):
                out.append(f"{where}: units {a.get('units')!r}")
    return out


def _streams_problems(root: ET.Element, ns: str) -> list[str]:
    out = []
    comp_ids = [cs.get("componentId") for cs in root.iter(f"{{{ns}}}ComponentStream")]
    if len(comp_ids) != len(set(comp_ids)):
        out.append("componentIds are not unique (xs:ID)")
    for ds in root.iter(f"{{{ns}}}DeviceStream"):
        if not (ds.get("name") and ds.get("uuid")):
            out.append("DeviceStream lacks name or uuid")
    for cs in root.iter(f"{{{ns}}}ComponentStream"):
        where = f"ComponentStream {cs.get('componentId')}"
        if not (cs.get("componentId") and cs.get("component")):
            out.append(f"{where} lacks componentId or component")
        groups = [_local(g.tag) for g in cs]
        out += [f"{where}: {g} twice" for g in set(groups) if groups.count(g) > 1]
        out += [
            f"{where}: unknown group {g}"
            for g in groups
            if g not in ("Samples", "Events", "Condition")
        ]
        for group in cs:
            gname = _local(group.tag)
            if len(group) == 0:
                out.append(f"{where}: empty {gname} (minOccurs 1)")
            for obs in group:
                out += _observation_problems(ns, gname, obs)
    return out


def _observation_problems(ns: str, group: str, obs: ET.Element) -> list[str]:
    tag = _local(obs.tag)
    standard = obs.tag.startswith(f"{{{ns}}}")
    where = f"{tag} {obs.get('dataItemId')}"
    if group == "Condition":
        kind = tag
        if kind not in ("Normal", "Warning", "Fault", "Unavailable") or not standard:
            return [f"{where}: not a condition state"]
    elif group == "Samples":
        kind = "Sample"
        if standard and tag not in SAMPLE_ELEMENTS:
            return [f"{where}: not a Sample"]
    else:
        kind = "AssetEvent" if tag in ("AssetChanged", "AssetRemoved") else "Event"
        if standard and tag in SAMPLE_ELEMENTS:
            return [f"{where}: a Sample among Events"]
    allowed, required = OBSERVATION_KINDS[kind]
    got = set(obs.attrib)
    out = [f"{where}: attribute {a} not allowed" for a in sorted(got - allowed - OBSERVATION_ATTRS)]
    out += [
        f"{where}: lacks {a}"
        for a in sorted((required | {"sequence", "timestamp", "dataItemId"}) - got)
    ]
    seq = obs.get("sequence", "")
    if not (XS_INTEGER.match(seq) and int(seq) >= 1):
        out.append(f"{where}: sequence {seq!r}")
    if not XS_DATETIME.match(obs.get("timestamp", "")):
        out.append(f"{where}: timestamp {obs.get('timestamp')!r} is no xs:dateTime")
    if not _word(obs.get("subType"), SUB_TYPES_25):
        out.append(f"{where}: subType {obs.get('subType')!r} is not a 2.5 subType")
    if not _word(obs.get("statistic"), STATISTICS_25):
        out.append(f"{where}: statistic {obs.get('statistic')!r}")
    if obs.get("qualifier") is not None and obs.get("qualifier") not in QUALIFIERS_25:
        out.append(f"{where}: qualifier {obs.get('qualifier')!r} is not HIGH or LOW")
    value = obs.text or ""
    if group != "Condition" and value != "UNAVAILABLE":
        space = "float" if kind == "Sample" else OBSERVATION_VALUES.get(tag, "string")
        ok = (
            XS_FLOAT.match(value)
            if space == "float"
            else XS_INTEGER.match(value)
            if space == "integer"
            else True
            if space == "string"
            else value in space
        )
        if not ok:
            out.append(f"{where}: value {value!r} is not valid for {tag}")
    return out
