"""The machine's OPC UA face: OPC 40501-1 MachineTool (on OPC 40001-1 Machinery and
OPC 10000-100 DI) served with asyncua; see docs/opcua.md."""

from cnc.faces.opcua.face import HostData, Identification, OpcUaFace, ProductionJob
from cnc.faces.opcua.security import Security

__all__ = ["HostData", "Identification", "OpcUaFace", "ProductionJob", "Security"]
