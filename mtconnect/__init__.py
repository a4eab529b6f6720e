"""The cell's MTConnect agent: device model, circular buffer, SHDR ingest, XML documents."""

from mtconnect.agent import Agent, RestError
from mtconnect.buffer import DEFAULT_BUFFER_SIZE, CircularBuffer, Observation
from mtconnect.client import AdapterConnection, AgentConnections, connect_cell
from mtconnect.model import DataItem, Device, build_device, devices_from_cell

__all__ = [
    "DEFAULT_BUFFER_SIZE",
    "AdapterConnection",
    "AgentConnections",
    "Agent",
    "CircularBuffer",
    "DataItem",
    "Device",
    "Observation",
    "RestError",
    "build_device",
    "connect_cell",
    "devices_from_cell",
]
