"""Frames handed over to the simulated bus for good (`OwnedMessage`, `owned_frame`).

Kept out of the mypyc-compiled hub (drives/bus/mypyc.list): a subclass of python-can's
`Message` with `__slots__` must stay an ordinary Python class.
"""

from __future__ import annotations

import can

new_message = can.Message.__new__


class OwnedMessage(can.Message):
    """A frame its sender hands over for good: not kept, not sent twice, `data` a bytearray
    of its own. The hub turns it into the received frame in place (a plain `can.Message`
    again, timestamp and channel set) instead of delivering a copy: one Message less per
    frame. The slaves and the axis group build their frames as this; any python-can bus
    accepts it as the `can.Message` it is."""

    __slots__ = ()


def owned_frame(cob_id: int, data: bytes, remote: bool = False) -> OwnedMessage:
    """A new standard-ID frame to hand over to a bus for good. Filled slot by slot:
    can.Message() costs ~3 us per frame, and the slaves and the axis group send one per PDO."""
    msg = new_message(OwnedMessage)
    msg.timestamp = 0.0
    msg.arbitration_id = cob_id
    msg.is_extended_id = False
    msg.is_remote_frame = remote
    msg.is_error_frame = False
    msg.channel = None
    msg.dlc = len(data)
    msg.data = bytearray(data)
    msg.is_fd = msg.is_rx = msg.bitrate_switch = msg.error_state_indicator = False
    return msg
