"""Soft-PLC: ladder language, compiler, scan runtime and Modbus TCP face."""

from plc.image import ImageSize, ProcessImage, Snapshot, Write, WriteQueue

__all__ = ["ImageSize", "ProcessImage", "Snapshot", "Write", "WriteQueue"]
