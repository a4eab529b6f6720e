"""The remote operator panel: which Modbus coils and registers the cell host writes and reads.

The machine-tool program reads the host's commands from markers (%MX/%MW) that the Modbus
face lets the host write (`WRITABLE`, the allow-list to give `ModbusFace(writable=...)`), and
passes them through the same rungs as the machine panel: a remote cycle start with the door
open is refused by the same interlock. Push-button coils are pulses: the host writes 1, the
program acts on it in the next scan and clears it. Addresses are 0-based on the wire, default
`ModbusMap` (coil = 8192 + %MX bit, holding register = 1024 + %MW word).

    from pymodbus.client import ModbusTcpClient
    panel = RemotePanel(ModbusTcpClient("127.0.0.1", port=5020))
    panel.cycle_start(); panel.set_feed_override(80); panel.status()
"""

from __future__ import annotations

from plc.signals import HOST_TO_PLC, PLC_TO_HOST, PLC_TO_NC, signal, signals

# everything the host may write, and nothing else
WRITABLE = "%MX0.0-%MX0.2,%MW0-%MW3"

COMMAND_COILS = {s.name: s.modbus[1] for s in signals(HOST_TO_PLC) if s.area == "MX"}
COMMAND_REGISTERS = {s.name: s.modbus[1] for s in signals(HOST_TO_PLC) if s.area == "MW"}
ANSWER_COILS = {s.name: s.modbus[1] for s in signals(PLC_TO_HOST) if s.area == "MX"}
# read-only status the panel shows (the PLC->NC signals are coils/holding registers too)
STATUS_COILS = {s.name: s.modbus[1] for s in signals(PLC_TO_NC) if s.area == "QX"}
STATUS_REGISTERS = {s.name: s.modbus[1] for s in signals(PLC_TO_NC) if s.area == "QW"}


class RemotePanelError(RuntimeError):
    """A Modbus request of the panel failed (the text names the request and the answer)."""


class RemotePanel:
    """Thin host-side helper over a connected pymodbus synchronous client."""

    def __init__(self, client, unit: int = 1) -> None:
        self.client = client
        self.unit = unit

    def _check(self, what: str, rr):
        if rr.isError():
            raise RemotePanelError(f"{what}: {rr}")
        return rr

    def _pulse(self, name: str) -> None:
        self._check(f"write coil {name}", self.client.write_coil(COMMAND_COILS[name], True))

    def cycle_start(self) -> None:
        self._pulse("RemCycleStart")

    def feed_hold(self) -> None:
        self._pulse("RemFeedHold")

    def reset(self) -> None:
        self._pulse("RemReset")

    def _register(self, name: str, value: int) -> None:
        addr = COMMAND_REGISTERS[name]
        self._check(f"write register {name}", self.client.write_register(addr, value & 0xFFFF))

    def set_feed_override(self, percent: int) -> None:
        self._register("RemFeedOvr", percent)

    def set_rapid_override(self, percent: int) -> None:
        self._register("RemRapidOvr", percent)

    def set_spindle_override(self, percent: int) -> None:
        self._register("RemSpindleOvr", percent)

    def request_mode(self, mode: int) -> None:
        """1 AUTO, 2 MDI, 3 JOG, 4 REF (refused while a program is active: ModeRefused)."""
        self._register("RemModeReq", mode)

    def status(self) -> dict[str, bool | int]:
        """PLC->NC signals and the panel's answer bits, read in two requests."""
        first = min(STATUS_COILS.values())
        n = max(STATUS_COILS.values()) - first + 1
        bits = self._check("read status coils", self.client.read_coils(first, count=n)).bits
        out: dict[str, bool | int] = {k: bool(bits[a - first]) for k, a in STATUS_COILS.items()}
        first = min(STATUS_REGISTERS.values())
        n = max(STATUS_REGISTERS.values()) - first + 1
        rr = self._check("read status", self.client.read_holding_registers(first, count=n))
        for k, a in STATUS_REGISTERS.items():
            v = rr.registers[a - first]
            out[k] = v - 0x10000 if v > 0x7FFF else v
        first = min(ANSWER_COILS.values())
        n = max(ANSWER_COILS.values()) - first + 1
        bits = self._check("read answer coils", self.client.read_coils(first, count=n)).bits
        out.update({k: bool(bits[a - first]) for k, a in ANSWER_COILS.items()})
        return out


def coil_of(name: str) -> int:
    """Modbus coil address of a BOOL signal in %QX or %MX."""
    table, address = signal(name).modbus
    if table != "coil":
        raise ValueError(f"{name} is a {table}, not a coil")
    return address
