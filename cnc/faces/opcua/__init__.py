"""The machine's OPC UA face: OPC 40501-1 MachineTool (on OPC 40001-1 Machinery and
OPC 10000-100 DI) served with asyncua; see docs/opcua.md."""

from cnc.faces.opcua.face import Identification, OpcUaFace
from cnc.faces.opcua.host_data import (
    FaceCommand,
    FaceUser,
    HostData,
    HostDataError,
    ProductionJob,
)
from cnc.faces.opcua.security import Security

__all__ = [
    "FaceCommand",
    "FaceUser",
    "HostData",
    "HostDataError",
    "Identification",
    "OpcUaFace",
    "ProductionJob",
    "Security",
]
