"""MTConnect 2.5 XML documents: Devices (probe), Streams (current/sample), Error.

Plain string building with escaping: the documents are regular, and this is several times
faster than building an element tree for every /sample.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from xml.sax.saxutils import escape, quoteattr

from mtconnect.buffer import Observation
from mtconnect.model import AGENT_OWNED, Device, devices_element

SCHEMA_VERSION = "2.5"
AGENT_VERSION = "2.5.0.0"
_XSI = "http://www.w3.org/2001/XMLSchema-instance"
_SCHEMAS = "http://schemas.mtconnect.org/schemas"
EXTENSION_PREFIX = "x"


def _ns(kind: str) -> str:
    return f"urn:mtconnect.org:MTConnect{kind}:{SCHEMA_VERSION}"


def extension_ns(kind: str) -> str:
    return f"urn:fmscell:MTConnect{kind}:{SCHEMA_VERSION}"


# fmscell's extension schema for the x: observation elements of Streams documents, served
# by the router beside the documents. Its location in schemaLocation is relative, so it
# resolves under whatever prefix the router is mounted at (…/current and …/mill1/current).
EXTENSION_SCHEMA_FILE = f"fmscellStreams_{SCHEMA_VERSION}.xsd"
EXTENSION_SCHEMA_PATH = f"schemas/{EXTENSION_SCHEMA_FILE}"


def _root_open(kind: str) -> str:
    ns = _ns(kind)
    location = f"{ns} {_SCHEMAS}/MTConnect{kind}_{SCHEMA_VERSION}.xsd"
    if kind == "Streams":
        location += f" {extension_ns(kind)} {EXTENSION_SCHEMA_PATH}"
    return (
        f'<MTConnect{kind} xmlns="{ns}" xmlns:m="{ns}" xmlns:xsi="{_XSI}" '
        f'xmlns:{EXTENSION_PREFIX}="{extension_ns(kind)}" '
        f'xsi:schemaLocation="{location}">'
    )


# The 2.5 abstract element (and its type) an extension observation substitutes for.
_EXTENSION_HEADS = {"SAMPLE": "CommonSample", "EVENT": "StringEvent"}


def print_extension_schema(devices: Sequence[Device]) -> str:
    """An XSD declaring every x: observation element the devices can emit, each in the
    substitution group of the 2.5 element it stands for (a sample is a CommonSample, an
    event a StringEvent), so a validating client accepts the extension elements. Conditions
    need nothing: their element is the standard Normal/Warning/Fault/Unavailable."""
    heads: dict[str, str] = {}
    for device in devices:
        for di in device.all_items:
            prefix, _, _name = di.type.rpartition(":")
            if prefix != EXTENSION_PREFIX or di.category not in _EXTENSION_HEADS:
                continue
            local = di.element.split(":", 1)[1]
            head = _EXTENSION_HEADS[di.category]
            if heads.setdefault(local, head) != head:
                raise ValueError(f"extension type {di.type} is both a sample and an event")
    ns = _ns("Streams")
    elements = "".join(
        f'<xs:element name="{local}" type="m:{head}Type" substitutionGroup="m:{head}"/>\n'
        for local, head in sorted(heads.items())
    )
    return (
        _declaration() + '<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema" '
        f'xmlns:m="{ns}" targetNamespace="{extension_ns("Streams")}" '
        'elementFormDefault="qualified" attributeFormDefault="unqualified">\n'
        f'<xs:import namespace="{ns}" '
        f'schemaLocation="{_SCHEMAS}/MTConnectStreams_{SCHEMA_VERSION}.xsd"/>\n'
        + elements
        + "</xs:schema>\n"
    )


@dataclass(frozen=True, slots=True)
class HeaderInfo:
    creation_time: str
    sender: str
    instance_id: int
    buffer_size: int
    device_model_change_time: str


def _header(h: HeaderInfo, *, model_change_time: bool = True, **extra: int) -> str:
    """The Header element. MTConnectError 2.5's HeaderType has no deviceModelChangeTime
    (Devices and Streams require it), so error documents leave it out."""
    attrs = {
        "creationTime": h.creation_time,
        "sender": h.sender,
        "instanceId": str(h.instance_id),
        "version": AGENT_VERSION,
    }
    if model_change_time:
        attrs["deviceModelChangeTime"] = h.device_model_change_time
    attrs["bufferSize"] = str(h.buffer_size)
    attrs.update({k: str(v) for k, v in extra.items()})
    return "<Header " + " ".join(f"{k}={quoteattr(v)}" for k, v in attrs.items()) + "/>"


def _declaration() -> str:
    return '<?xml version="1.0" encoding="UTF-8"?>\n'


def print_probe(h: HeaderInfo, devices: Sequence[Device]) -> str:
    body = ET.tostring(devices_element(devices), encoding="unicode")
    return (
        _declaration()
        + _root_open("Devices")
        + _header(h, assetBufferSize=1024, assetCount=0)
        + body
        + "</MTConnectDevices>"
    )


def print_error(h: HeaderInfo, errors: Iterable[tuple[str, str]]) -> str:
    items = "".join(
        f"<Error errorCode={quoteattr(code)}>{escape(text)}</Error>" for code, text in errors
    )
    return (
        _declaration()
        + _root_open("Error")
        + _header(h, model_change_time=False)
        + f"<Errors>{items}</Errors>"
        + "</MTConnectError>"
    )


_CATEGORY_ORDER = (("SAMPLE", "Samples"), ("EVENT", "Events"), ("CONDITION", "Condition"))


def print_streams(
    h: HeaderInfo,
    devices: Sequence[Device],
    observations: Iterable[Observation],
    *,
    next_sequence: int,
    first_sequence: int,
    last_sequence: int,
) -> str:
    """A Streams document; observations are grouped by device and component, each group in
    sequence order, as the reference agent prints them."""
    by_component: dict[str, list[Observation]] = {}
    for obs in observations:
        by_component.setdefault(obs.item.component_id, []).append(obs)
    parts = [
        _declaration(),
        _root_open("Streams"),
        _header(
            h,
            nextSequence=next_sequence,
            firstSequence=first_sequence,
            lastSequence=last_sequence,
        ),
        "<Streams>",
    ]
    for device in devices:
        comps = [c for c in device.walk() if c.id in by_component]
        if not comps:
            continue
        parts.append(f"<DeviceStream name={quoteattr(device.name)} uuid={quoteattr(device.uuid)}>")
        for comp in comps:
            parts.append(
                f"<ComponentStream component={quoteattr(comp.kind)} name={quoteattr(comp.name)}"
                f" componentId={quoteattr(comp.id)}>"
            )
            group = sorted(by_component[comp.id], key=lambda o: o.sequence)
            for category, wrapper in _CATEGORY_ORDER:
                chosen = [o for o in group if o.item.category == category]
                if chosen:
                    parts.append(f"<{wrapper}>")
                    parts.extend(_observation(o) for o in chosen)
                    parts.append(f"</{wrapper}>")
            parts.append("</ComponentStream>")
        parts.append("</DeviceStream>")
    parts.append("</Streams></MTConnectStreams>")
    return "".join(parts)


def _observation(o: Observation) -> str:
    di = o.item
    attrs = [
        f"dataItemId={quoteattr(di.id)}",
        f"timestamp={quoteattr(o.timestamp)}",
        f"name={quoteattr(di.name)}",
        f'sequence="{o.sequence}"',
    ]
    if di.sub_type:
        attrs.append(f"subType={quoteattr(di.sub_type)}")
    if di.category == "CONDITION":
        tag = o.level.capitalize() or "Unavailable"
        attrs.append(f"type={quoteattr(di.type)}")
        if tag in _ACTIVATED:
            # Warning and Fault require conditionId in 2.5; like cppagent, the native code
            # identifies the activation (the data item id when the adapter gave none).
            attrs.append(f"conditionId={quoteattr(o.native_code or di.id)}")
        if o.native_code:
            attrs.append(f"nativeCode={quoteattr(o.native_code)}")
        if o.native_severity:
            attrs.append(f"nativeSeverity={quoteattr(o.native_severity)}")
        if o.qualifier:
            attrs.append(f"qualifier={quoteattr(o.qualifier)}")
        if o.value:
            return f"<{tag} {' '.join(attrs)}>{escape(o.value)}</{tag}>"
        return f"<{tag} {' '.join(attrs)}/>"
    if di.statistic:
        attrs.append(f"statistic={quoteattr(di.statistic)}")
    if di.type in AGENT_OWNED:
        # AssetChanged/AssetRemoved require assetType; this agent holds no assets, so the
        # events are only ever UNAVAILABLE, and so is their asset type (as cppagent prints).
        attrs.append('assetType="UNAVAILABLE"')
    tag = di.element
    return f"<{tag} {' '.join(attrs)}>{escape(o.value)}</{tag}>"


_ACTIVATED = ("Warning", "Fault")
