"""One configuration line switches a machine's bus between the simulator and real hardware."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import can

from drives.bus.hub import CanHub, SimBus, get_hub

INTERFACES = ("sim", "socketcan", "virtual")
_KEYS = {"interface", "channel", "bitrate", "name", "receive_own_messages"}


def open_bus(config: Mapping[str, Any], *, hub: CanHub | None = None) -> can.BusABC:
    """A python-can bus for `config` = {interface, channel, bitrate?, name?}.

    `interface: sim` (default) attaches an endpoint to `hub` or to the process-wide hub named
    by `channel`; `interface: socketcan, channel: can0` opens the real interface (its bitrate is
    set with `ip link`, not here); `interface: virtual` is python-can's in-process bus.
    """
    unknown = set(config) - _KEYS
    if unknown:
        raise ValueError(f"bus config: unknown key(s) {sorted(unknown)}; allowed {sorted(_KEYS)}")
    interface = config.get("interface", "sim")
    if interface not in INTERFACES:
        raise ValueError(f"bus config: interface {interface!r} not one of {INTERFACES}")
    channel = config.get("channel", "can0")
    if not isinstance(channel, str) or not channel:
        raise ValueError(f"bus config: channel must be a non-empty string, got {channel!r}")
    bitrate = config.get("bitrate", 1_000_000)
    if not isinstance(bitrate, int) or isinstance(bitrate, bool) or bitrate <= 0:
        raise ValueError(f"bus config: bitrate must be a positive integer, got {bitrate!r}")
    receive_own = bool(config.get("receive_own_messages", False))
    if interface == "socketcan":
        return can.Bus(interface="socketcan", channel=channel, receive_own_messages=receive_own)
    if interface == "virtual":
        return can.Bus(interface="virtual", channel=channel, receive_own_messages=receive_own)
    if hub is None:
        hub = get_hub(channel, bitrate=bitrate)
    elif hub.bitrate != bitrate and "bitrate" in config:
        raise ValueError(
            f"bus config: bitrate {bitrate} differs from hub {hub.channel!r} at {hub.bitrate}"
        )
    return SimBus(hub=hub, name=str(config.get("name", "")), receive_own_messages=receive_own)
