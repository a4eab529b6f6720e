"""The cell's MTConnect agent: device model, circular buffer, SHDR ingest, XML documents."""

from server.mtconnect.agent import Agent, RestError
from server.mtconnect.buffer import DEFAULT_BUFFER_SIZE, CircularBuffer, Observation
from server.mtconnect.client import AdapterConnection, AgentConnections, connect_cell
from server.mtconnect.model import DataItem, Device, build_device, devices_from_cell

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
