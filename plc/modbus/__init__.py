"""The soft-PLC's Modbus TCP face: map, allow-list, strict MBAP framing and the server.

    face = ModbusFace(get_snapshot, write_queue, image_size,
                      host="127.0.0.1", port=5020, writable="coil:0-15,%MW0-99")
    face.start_in_thread()   # or: await face.start()
    ...
    face.stop_thread()       # or: await face.stop()

See docs/modbus.md for the address map and the protocol rules.
"""

from plc.modbus.allowlist import AllowList, AllowListError, WriteGuard
from plc.modbus.frame import FrameViolation, MbapDecoder
from plc.modbus.map import ModbusMap, Segment
from plc.modbus.pdu import DeviceIdentity, PduHandler, PduSizeError
from plc.modbus.server import FaceStats, ModbusFace

__all__ = [
    "AllowList",
    "AllowListError",
    "DeviceIdentity",
    "FaceStats",
    "FrameViolation",
    "MbapDecoder",
    "ModbusFace",
    "ModbusMap",
    "PduHandler",
    "PduSizeError",
    "Segment",
    "WriteGuard",
]
