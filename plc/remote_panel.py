"""The remote operator panel: which Modbus coils and registers the cell host writes and reads.

The machine-tool program reads the host's commands from markers (%MX/%MW) that the Modbus
face lets the host write (`WRITABLE`, the allow-list to give `ModbusFace(writable=...)`), and
passes them through the same rungs as the machine panel: a remote cycle start with the door
open is refused by the same interlock. Addresses are 0-based on the wire, default `ModbusMap`
(coil = 8192 + %MX bit, holding register = 1024 + %MW word; NC->PLC signals are discrete
inputs and input registers).

Two kinds of command:

* push buttons (cycle start, feed hold, reset) are pulses: the host writes 1, the program
  acts on it in the next scan and writes 0;
* requests with an answer (program select, home all) are a strobe / answer handshake: the
  host writes the strobe 1 (after the O number for a select), keeps it at 1 until it reads
  the answer (selected / refused with a code; homing accepted / refused with a code), then
  writes 0; the PLC drops the answer with the strobe. An answer read together with the
  strobe at 1 in one Modbus read belongs to this request, never to an earlier one.

    from pymodbus.client import ModbusTcpClient
    panel = RemotePanel(ModbusTcpClient("127.0.0.1", port=5020))
    panel.cycle_start(); panel.set_feed_override(80); panel.status()
    panel.select_program(1234)             # PanelRefused says why not
    panel.request_mode(4); panel.home_all(); panel.referenced()
"""

from __future__ import annotations

import time
from collections.abc import Callable

from plc.errors import PlcError
from plc.signals import (
    AXIS_BITS,
    HOST_TO_PLC,
    MAX_PROGRAM_NUMBER,
    NC_TO_PLC,
    PLC_TO_HOST,
    PLC_TO_NC,
    REFUSAL_TEXTS,
    dword_value,
    dword_words,
    signal,
    signals,
)

# everything the host may write, and nothing else; overrides outside 0..200 % are refused
# by the face with exception 03 (illegal data value), never wrapped or clamped
WRITABLE = "%MX0.0-%MX0.4,%MW0-%MW2=0..200,%MW3-%MW5"

COMMAND_COILS = {s.name: s.modbus[1] for s in signals(HOST_TO_PLC) if s.area == "MX"}
COMMAND_REGISTERS = {s.name: s.modbus[1] for s in signals(HOST_TO_PLC) if s.area == "MW"}
ANSWER_COILS = {s.name: s.modbus[1] for s in signals(PLC_TO_HOST) if s.area == "MX"}
ANSWER_REGISTERS = {s.name: s.modbus[1] for s in signals(PLC_TO_HOST) if s.area == "MW"}
# read-only status the panel shows (the PLC->NC signals are coils/holding registers too)
STATUS_COILS = {s.name: s.modbus[1] for s in signals(PLC_TO_NC) if s.area == "QX"}
STATUS_REGISTERS = {s.name: s.modbus[1] for s in signals(PLC_TO_NC) if s.area == "QW"}
# what the NC tells the PLC (mode, selected program, referenced axes, homing) is readable too
NC_INPUTS = {s.name: s.modbus[1] for s in signals(NC_TO_PLC) if s.area == "IX"}
NC_REGISTERS = {s.name: s.modbus[1] for s in signals(NC_TO_PLC) if s.area == "IW"}


class RemotePanelError(PlcError, RuntimeError):
    """A Modbus request of the panel failed (the text names the request and the answer), or
    a request got no answer in time."""


class PanelRefused(PlcError, RuntimeError):
    """The PLC or the NC refused a program select or a home all; `code` is one of
    `plc.signals.REFUSE_*`, the text says what and why."""

    def __init__(self, what: str, code: int) -> None:
        why = REFUSAL_TEXTS.get(code, f"refusal code {code}")
        super().__init__(f"{what} refused: {why} (code {code})")
        self.code = code


class RemotePanel:
    """Thin host-side helper over a connected pymodbus synchronous client."""

    def __init__(
        self, client, unit: int = 1, *, sleep: Callable[[float], None] = time.sleep
    ) -> None:
        self.client = client
        self.unit = unit
        self.sleep = sleep  # between two polls of a handshake (a lockstep test scans here)

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

    # ------------------------------------------------------------------ handshakes
    def _bits(self, table: dict[str, int], what: str, *, inputs: bool = False) -> dict:
        """One read of the coils (or discrete inputs) `table` names: one scan's values."""
        first = min(table.values())
        n = max(table.values()) - first + 1
        read = self.client.read_discrete_inputs if inputs else self.client.read_coils
        bits = self._check(f"read {what}", read(first, count=n)).bits
        return {k: bool(bits[a - first]) for k, a in table.items()}

    def _words(self, table: dict[str, int], what: str, *, inputs: bool = False) -> dict:
        first = min(table.values())
        n = max(table.values()) - first + 1
        read = self.client.read_input_registers if inputs else self.client.read_holding_registers
        rr = self._check(f"read {what}", read(first, count=n))
        out = {}
        for k, a in table.items():
            v = rr.registers[a - first]
            out[k] = v - 0x10000 if v > 0x7FFF else v
        return out

    def _panel_bits(self) -> dict[str, bool]:
        """The host's command coils and the PLC's answer coils in ONE read (one scan)."""
        return self._bits({**COMMAND_COILS, **ANSWER_COILS}, "panel coils")

    def _handshake(
        self, strobe: str, done: str, refused: str, code: str, what: str, timeout_s: float
    ) -> None:
        """Strobe / answer: clear any strobe left at 1, raise it, wait for the answer read
        together with the strobe, drop the strobe. PanelRefused on a refusal."""
        end = time.monotonic() + timeout_s
        bits = self._panel_bits()
        if bits[strobe] or bits[done] or bits[refused]:
            # an earlier host left its strobe up: drop it and let the PLC clear the answer
            self._set_coil(strobe, False)
            while (bits := self._panel_bits())[strobe] or bits[done] or bits[refused]:
                if time.monotonic() > end:
                    raise RemotePanelError(f"{what}: the PLC did not clear the last answer")
                self.sleep(0.005)
        self._set_coil(strobe, True)
        try:
            while True:
                bits = self._panel_bits()
                if bits[strobe] and (bits[done] or bits[refused]):
                    break
                if time.monotonic() > end:
                    raise RemotePanelError(f"{what}: no answer from the PLC in {timeout_s} s")
                self.sleep(0.005)
            if bits[refused]:
                number = self._words(ANSWER_REGISTERS, "answer registers")[code]
                raise PanelRefused(what, number)
        finally:
            self._set_coil(strobe, False)

    def _set_coil(self, name: str, value: bool) -> None:
        self._check(f"write coil {name}", self.client.write_coil(COMMAND_COILS[name], value))

    def select_program(self, number: int, timeout_s: float = 5.0) -> None:
        """Program select of O`number` (1..99999999) through the PLC to the NC; returns once
        the NC selected it. PanelRefused (not in memory, a program active ...) says why not.

        The O number goes as 32 bits in holding registers 1028 (low word) and 1029 (high
        word), both in ONE write so the PLC never sees half of a new number."""
        if not 1 <= number <= MAX_PROGRAM_NUMBER:
            raise ValueError(f"O{number} outside O1..O{MAX_PROGRAM_NUMBER}")
        low, high = dword_words(number)
        addr = COMMAND_REGISTERS["RemProgNumber"]
        assert COMMAND_REGISTERS["RemProgNumberHigh"] == addr + 1
        self._check(
            "write registers RemProgNumber, RemProgNumberHigh",
            self.client.write_registers(addr, [low & 0xFFFF, high & 0xFFFF]),
        )
        self._handshake(
            "RemProgSelect",
            "ProgSelected",
            "ProgSelectRefused",
            "ProgRefuseCode",
            f"program select O{number:04d}",
            timeout_s,
        )

    def home_all(self, timeout_s: float = 5.0) -> None:
        """Home all (zero return) in REF mode; returns once the NC started the homing
        sequence (wait for `referenced()` to see it end). PanelRefused says why not."""
        self._handshake(
            "RemHomeAll", "HomeAccepted", "HomeRefused", "HomeRefuseCode", "home all", timeout_s
        )

    def nc_state(self) -> dict[str, bool | int]:
        """What the NC reports to the PLC: NcMode, NcInCycle, ActiveProgram, HomingActive,
        AllReferenced, ReferencedAxes ... (discrete inputs and input registers)."""
        out: dict[str, bool | int] = dict(self._bits(NC_INPUTS, "NC inputs", inputs=True))
        words = self._words(NC_REGISTERS, "NC registers", inputs=True)
        # the selected O number is 32 bits in two input registers (low word first)
        words["ActiveProgram"] = dword_value(words["ActiveProgram"], words.pop("ActiveProgramHigh"))
        out.update(words)
        return out

    def referenced(self) -> dict[str, bool]:
        """Referenced state per axis letter (X Y Z A B C), from ReferencedAxes."""
        mask = self._words(NC_REGISTERS, "NC registers", inputs=True)["ReferencedAxes"]
        return {a: bool(mask >> i & 1) for i, a in enumerate(AXIS_BITS)}

    def status(self) -> dict[str, bool | int]:
        """PLC->NC signals and the panel's answer bits and registers."""
        out: dict[str, bool | int] = dict(self._bits(STATUS_COILS, "status coils"))
        out.update(self._words(STATUS_REGISTERS, "status"))
        out.update({k: v for k, v in self._panel_bits().items() if k in ANSWER_COILS})
        out.update(self._words(ANSWER_REGISTERS, "answer registers"))
        return out


def coil_of(name: str) -> int:
    """Modbus coil address of a BOOL signal in %QX or %MX."""
    table, address = signal(name).modbus
    if table != "coil":
        raise ValueError(f"{name} is a {table}, not a coil")
    return address
