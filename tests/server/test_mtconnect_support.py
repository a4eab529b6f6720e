"""Shared helpers for the MTConnect tests (no tests here): a small agent, document checks."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from server.mtconnect import Agent, build_device

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
