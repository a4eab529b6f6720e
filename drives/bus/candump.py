"""candump log lines (`candump -l` format) with deterministic timestamps.

`(0.001051) can0 181#3706E8030000`, 29-bit identifiers as 8 hex digits, remote frames as
`123#R`, error frames as `20000080#0000000000000000` like python-can's CanutilsLogWriter, so
`can.CanutilsLogReader`, `canplayer` and `log2asc` read the files back.
"""

from __future__ import annotations

from typing import TextIO

import can

CAN_ERR_FLAG = 0x20000000
CAN_ERR_BUSERROR = 0x00000080


def candump_line(msg: can.Message, channel: str = "can0") -> str:
    """One candump log line for a frame, without the trailing newline."""
    if msg.is_error_frame:
        frame = f"{CAN_ERR_FLAG | CAN_ERR_BUSERROR:08X}#0000000000000000"
    else:
        ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
        frame = f"{ident}#R" if msg.is_remote_frame else f"{ident}#{bytes(msg.data).hex().upper()}"
    return f"({msg.timestamp:.6f}) {channel} {frame}"


def candump_frame(msg: can.Message) -> str:
    """The frame part only (`123#DEADBEEF`), the notation golden-frame tests compare."""
    return candump_line(msg).split(" ", 2)[2]


class CandumpWriter:
    """Writes every delivered frame to a text stream; the hub calls `write(msg)`."""

    def __init__(self, stream: TextIO, channel: str = "can0") -> None:
        self.stream = stream
        self.channel = channel

    def write(self, msg: can.Message) -> None:
        self.stream.write(candump_line(msg, self.channel) + "\n")
