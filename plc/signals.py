"""The machine's NC<->PLC signal set: one declared table, as LinuxCNC's HAL declares pins.

Every signal the machine-tool PLC program (`plc/programs/machine_tool.ld`) exchanges with the
NC, the field (the simulated machine in `plc/machine_io.py`) and the cell host's remote
operator panel is declared here once, with its direction, IEC address, type and meaning. The
NC reads and writes the PLC only through this table (`NcPort`); the program's tag table is
checked against it by the tests, so the two cannot drift apart.

Directions, seen from the PLC:

    NC->PLC      written by the NC into PLC inputs (%IX/%IW): strobes, codes, NC status
    PLC->NC      PLC outputs the NC reads (%QX/%QW): finishes, cycle start, feed hold ...
    field->PLC   machine sensors into PLC inputs (%IX/%IW)
    PLC->field   PLC outputs to actuators (%QX/%QW)
    host->PLC    remote operator panel, Modbus-writable markers (%MX/%MW)
    PLC->host    PLC answers to the remote operator panel (%MX/%MW, read-only on Modbus)

Usage::

    from plc.signals import SIGNALS, signal, NcPort
    signal("MStrobe").address        # '%IX0.3'
    port = NcPort()
    port.set("MCode", 6); port.set("MStrobe", True)   # NC side, NC->PLC signals only
    port.get("MFinish")                                # PLC->NC, from the last scan
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

NC_TO_PLC = "NC->PLC"
PLC_TO_NC = "PLC->NC"
FIELD_TO_PLC = "field->PLC"
PLC_TO_FIELD = "PLC->field"
HOST_TO_PLC = "host->PLC"
PLC_TO_HOST = "PLC->host"
DIRECTIONS = (NC_TO_PLC, PLC_TO_NC, FIELD_TO_PLC, PLC_TO_FIELD, HOST_TO_PLC, PLC_TO_HOST)

# NC operating modes as the NC reports them in NcMode and the PLC selects them in ModeSelect.
MODE_NONE, MODE_AUTO, MODE_MDI, MODE_JOG, MODE_REF = 0, 1, 2, 3, 4
MODE_NAMES = {MODE_NONE: "NONE", MODE_AUTO: "AUTO", MODE_MDI: "MDI", MODE_JOG: "JOG",
              MODE_REF: "REF"}  # fmt: skip

# Why a program select or a zero return was refused: one code table for the NC's answers
# (ProgSelectFailCode, HomeFailCode), the PLC's own refusals and the remote panel's
# ProgRefuseCode / HomeRefuseCode.
REFUSE_NOT_IN_MEMORY = 1
REFUSE_PROGRAM_ACTIVE = 2
REFUSE_BAD_NUMBER = 3
REFUSE_NO_ANSWER = 4
REFUSE_NOT_REF_MODE = 5
REFUSE_ESTOP = 6
REFUSE_NOT_ENABLED = 7
REFUSE_HOMING = 8
REFUSE_OTHER = 9
REFUSE_ABORTED = 10
REFUSAL_TEXTS = {
    REFUSE_NOT_IN_MEMORY: "program not in memory",
    REFUSE_PROGRAM_ACTIVE: "a program is active (running or held)",
    REFUSE_BAD_NUMBER: "program number outside 1..99999999",
    REFUSE_NO_ANSWER: "the NC did not answer within 1 s (PLC alarm 1050/1051)",
    REFUSE_NOT_REF_MODE: "mode is not REF",
    REFUSE_ESTOP: "emergency stop active",
    REFUSE_NOT_ENABLED: "axis drives not enabled",
    REFUSE_HOMING: "homing already in progress",
    REFUSE_OTHER: "refused by the NC (see its event log)",
    REFUSE_ABORTED: "reset or E-stop aborted the request",
}
AXIS_BITS = "XYZABC"  # bit n of ReferencedAxes is the axis AXIS_BITS[n]

_ADDR = re.compile(r"^%([IQM])([XW])(\d+)(?:\.([0-7]))?$")
_AREAS_BY_DIRECTION = {
    NC_TO_PLC: ("IX", "IW"),
    FIELD_TO_PLC: ("IX", "IW"),
    PLC_TO_NC: ("QX", "QW"),
    PLC_TO_FIELD: ("QX", "QW"),
    HOST_TO_PLC: ("MX", "MW"),
    PLC_TO_HOST: ("MX", "MW"),
}


@dataclass(frozen=True, slots=True)
class Signal:
    """One declared signal. `area`/`index` locate it in the process image (bit areas are
    indexed byte*8+bit, as in `plc.image`)."""

    name: str
    direction: str
    address: str
    type: str  # "BOOL" or "INT"
    meaning: str
    area: str = field(init=False)
    index: int = field(init=False)

    def __post_init__(self) -> None:
        m = _ADDR.match(self.address)
        if m is None:
            raise ValueError(f"signal {self.name}: malformed address {self.address!r}")
        kind, size, num, bit = m.group(1), m.group(2), int(m.group(3)), m.group(4)
        if (size == "X") != (bit is not None):
            raise ValueError(f"signal {self.name}: {self.address!r} bit/word form is wrong")
        area = kind + size
        want = "BOOL" if size == "X" else "INT"
        if self.type != want:
            raise ValueError(f"signal {self.name}: {self.address} holds {want}, not {self.type}")
        if self.direction not in DIRECTIONS:
            raise ValueError(f"signal {self.name}: unknown direction {self.direction!r}")
        if area not in _AREAS_BY_DIRECTION[self.direction]:
            raise ValueError(f"signal {self.name}: {self.direction} cannot live in %{area}")
        object.__setattr__(self, "area", area)
        object.__setattr__(self, "index", num * 8 + int(bit) if bit is not None else num)

    @property
    def modbus(self) -> tuple[str, int]:
        """(table, 0-based address) on the PLC's Modbus face with the default map."""
        return {
            "IX": ("discrete input", self.index),
            "QX": ("coil", self.index),
            "MX": ("coil", 8192 + self.index),
            "IW": ("input register", self.index),
            "QW": ("holding register", self.index),
            "MW": ("holding register", 1024 + self.index),
        }[self.area]


# An O number has up to 8 digits (1..99999999): more than a 16-bit word holds. It travels as
# a 32-bit unsigned value in two words, low word first (a Fanuc PMC keeps 4-byte data low
# byte first), e.g. RemProgNumber (holding register 1028) + RemProgNumberHigh (1029). O
# numbers up to 65535 have a high word of 0, so a host that writes only the low word keeps
# working as long as it leaves the high word at 0.
MAX_PROGRAM_NUMBER = 99_999_999


def dword_words(value: int) -> tuple[int, int]:
    """A 32-bit unsigned value as (low, high) words, each as the IEC INT the image holds."""
    if not 0 <= value <= 0xFFFF_FFFF:
        raise ValueError(f"{value} does not fit 32 bits unsigned")
    return _int16(value & 0xFFFF), _int16(value >> 16)


def dword_value(low: int, high: int) -> int:
    """The 32-bit unsigned value of two words (low, high), each INT or unsigned 16-bit."""
    return ((int(high) & 0xFFFF) << 16) | (int(low) & 0xFFFF)


def _int16(v: int) -> int:
    return v - 0x10000 if v & 0x8000 else v


def _s(name: str, direction: str, address: str, meaning: str) -> Signal:
    return Signal(name, direction, address, "BOOL" if "X" in address[:3] else "INT", meaning)


SIGNALS: tuple[Signal, ...] = (
    # --- NC -> PLC -----------------------------------------------------------------------
    _s("NcReady", NC_TO_PLC, "%IX0.0", "NC ready: NC running, no NC system fault"),
    _s("NcInCycle", NC_TO_PLC, "%IX0.1", "automatic operation in progress (cycle lamp)"),
    _s("NcResetting", NC_TO_PLC, "%IX0.2", "NC reset in progress (clears PLC handshakes)"),
    _s("MStrobe", NC_TO_PLC, "%IX0.3", "M function strobe: MCode is valid"),
    _s("SStrobe", NC_TO_PLC, "%IX0.4", "S function strobe: SCode is valid"),
    _s("TStrobe", NC_TO_PLC, "%IX0.5", "T function strobe: TCode is valid"),
    _s("NcAlarm", NC_TO_PLC, "%IX0.6", "NC alarm active"),
    _s("MCode", NC_TO_PLC, "%IW0", "M code number (3, 4, 5, 6, 7, 8, 9, 19, ...)"),
    _s("SCode", NC_TO_PLC, "%IW1", "programmed spindle speed, rpm (0..12000)"),
    _s("TCode", NC_TO_PLC, "%IW2", "programmed tool number = pocket number (1..20)"),
    _s("NcMode", NC_TO_PLC, "%IW3", "active NC mode: 1 AUTO, 2 MDI, 3 JOG, 4 REF"),
    _s("ProgSelectDone", NC_TO_PLC, "%IX0.7", "program selected (held while ProgSelectReq)"),
    _s("ProgSelectFail", NC_TO_PLC, "%IX1.0", "program select refused (held while ProgSelectReq)"),
    _s("HomeAck", NC_TO_PLC, "%IX1.1", "zero return request taken, homing started (held)"),
    _s("HomeFail", NC_TO_PLC, "%IX1.2", "zero return request refused (held while HomeAllReq)"),
    _s("HomingActive", NC_TO_PLC, "%IX1.3", "zero return (homing) in progress"),
    _s("AllReferenced", NC_TO_PLC, "%IX1.4", "every axis referenced since power-on / E-stop"),
    _s("ProgSelectFailCode", NC_TO_PLC, "%IW4", "why the NC refused the program select (code)"),
    _s("HomeFailCode", NC_TO_PLC, "%IW5", "why the NC refused the zero return (code)"),
    _s("ActiveProgram", NC_TO_PLC, "%IW6", "selected program O number, low word; 0 = none"),
    _s("ReferencedAxes", NC_TO_PLC, "%IW7", "referenced axes: bit 0 X, 1 Y, 2 Z, 3 A, 4 B, 5 C"),
    _s("ActiveProgramHigh", NC_TO_PLC, "%IW10", "selected program O number, high word"),
    # --- PLC -> NC -----------------------------------------------------------------------
    _s("PlcReady", PLC_TO_NC, "%QX0.0", "PLC program running"),
    _s("MFinish", PLC_TO_NC, "%QX0.1", "M function finished (held until MStrobe drops)"),
    _s("SFinish", PLC_TO_NC, "%QX0.2", "S function finished (held until SStrobe drops)"),
    _s("TFinish", PLC_TO_NC, "%QX0.3", "T function finished: carousel at the pocket"),
    _s("CycleStart", PLC_TO_NC, "%QX0.4", "cycle start (accepted request, one scan or held)"),
    _s("FeedHold", PLC_TO_NC, "%QX0.5", "feed hold: stop feed motion, keep position"),
    _s("NcReset", PLC_TO_NC, "%QX0.6", "reset request from the operator panel"),
    _s("EStopActive", PLC_TO_NC, "%QX0.7", "emergency stop active: quick stop, drives off"),
    _s("AxisEnable", PLC_TO_NC, "%QX1.0", "NC may enable the axis drives"),
    _s("SpindleAtSpeed", PLC_TO_NC, "%QX1.1", "spindle turning at the commanded speed"),
    _s("DoorClosed", PLC_TO_NC, "%QX1.2", "guard door closed"),
    _s("DoorLocked", PLC_TO_NC, "%QX1.3", "guard door closed and locked"),
    _s("PlcAlarm", PLC_TO_NC, "%QX1.4", "at least one PLC alarm active"),
    _s("ModeSelect", PLC_TO_NC, "%QW0", "mode the NC shall take: 1 AUTO, 2 MDI, 3 JOG, 4 REF"),
    _s("FeedOverride", PLC_TO_NC, "%QW1", "feed override, % (0..200)"),
    _s("RapidOverride", PLC_TO_NC, "%QW2", "rapid override, % (0..200)"),
    _s("SpindleOverride", PLC_TO_NC, "%QW3", "spindle override, % (0..200)"),
    _s("PlcAlarmNumber", PLC_TO_NC, "%QW4", "lowest-numbered active PLC alarm, 0 = none"),
    _s("ToolInSpindle", PLC_TO_NC, "%QW5", "tool number in the spindle, 0 = empty"),
    _s("PreparedTool", PLC_TO_NC, "%QW6", "tool prepared by the last T function"),
    _s("ProgSelectReq", PLC_TO_NC, "%QX1.5", "program select request (held until answered)"),
    _s("HomeAllReq", PLC_TO_NC, "%QX1.6", "zero return request, all axes (held until answered)"),
    _s("ProgSelectNumber", PLC_TO_NC, "%QW7", "O number of the program select, low word"),
    _s("ProgSelectNumberHigh", PLC_TO_NC, "%QW10", "O number of the program select, high word"),
    # --- field -> PLC --------------------------------------------------------------------
    _s("EStopChainOk", FIELD_TO_PLC, "%IX2.0", "E-stop chain closed (NC wired: 0 = E-stop)"),
    _s("DoorClosedSw", FIELD_TO_PLC, "%IX2.1", "door switch: guard door closed"),
    _s("DoorLockedSw", FIELD_TO_PLC, "%IX2.2", "door lock bolt engaged"),
    _s("SpindleDriveReady", FIELD_TO_PLC, "%IX2.3", "spindle drive ready"),
    _s("SpindleAtSpeedFb", FIELD_TO_PLC, "%IX2.4", "spindle drive speed arrival"),
    _s("SpindleOriented", FIELD_TO_PLC, "%IX2.5", "spindle oriented (M19 position)"),
    _s("SpindleZeroSpeed", FIELD_TO_PLC, "%IX2.6", "spindle at zero speed"),
    _s("CoolantPressureOk", FIELD_TO_PLC, "%IX2.7", "coolant pressure switch"),
    _s("LubeLevelOk", FIELD_TO_PLC, "%IX3.0", "lubricant tank level above minimum"),
    _s("LubePressureOk", FIELD_TO_PLC, "%IX3.1", "lubrication line pressure switch"),
    _s("AirPressureOk", FIELD_TO_PLC, "%IX3.2", "shop air pressure switch"),
    _s("CarouselInPos", FIELD_TO_PLC, "%IX3.3", "carousel stopped at a pocket"),
    _s("ArmAtHome", FIELD_TO_PLC, "%IX3.4", "changer arm at home"),
    _s("ArmAtGrip", FIELD_TO_PLC, "%IX3.5", "changer arm gripping spindle and pocket tools"),
    _s("ArmAtExtract", FIELD_TO_PLC, "%IX3.6", "changer arm extracted (tools pulled out)"),
    _s("ArmAtSwap", FIELD_TO_PLC, "%IX3.7", "changer arm turned 180 deg (tools swapped)"),
    _s("ArmAtInsert", FIELD_TO_PLC, "%IX4.0", "changer arm inserted (tools pushed in)"),
    _s("PanelCycleStart", FIELD_TO_PLC, "%IX4.1", "machine panel cycle start button"),
    _s("PanelFeedHold", FIELD_TO_PLC, "%IX4.2", "machine panel feed hold button"),
    _s("PanelReset", FIELD_TO_PLC, "%IX4.3", "machine panel reset button"),
    _s("CarouselPocket", FIELD_TO_PLC, "%IW8", "carousel pocket at the change position"),
    _s("SpindleSpeedFb", FIELD_TO_PLC, "%IW9", "spindle actual speed, rpm (signed)"),
    # --- PLC -> field --------------------------------------------------------------------
    _s("SpindleEnable", PLC_TO_FIELD, "%QX2.0", "spindle drive enable"),
    _s("SpindleFwd", PLC_TO_FIELD, "%QX2.1", "spindle run clockwise (M3)"),
    _s("SpindleRev", PLC_TO_FIELD, "%QX2.2", "spindle run counter-clockwise (M4)"),
    _s("SpindleOrient", PLC_TO_FIELD, "%QX2.3", "spindle orient (M19, tool change)"),
    _s("CoolantPump", PLC_TO_FIELD, "%QX2.4", "flood coolant pump (M8)"),
    _s("CoolantMist", PLC_TO_FIELD, "%QX2.5", "mist coolant valve (M7)"),
    _s("DoorLock", PLC_TO_FIELD, "%QX2.6", "door lock solenoid (power to lock)"),
    _s("LubePump", PLC_TO_FIELD, "%QX2.7", "way lubrication pump"),
    _s("CarouselGo", PLC_TO_FIELD, "%QX3.0", "carousel: index to CarouselTarget"),
    _s("ArmToHome", PLC_TO_FIELD, "%QX3.1", "changer arm valve: to home"),
    _s("ArmToGrip", PLC_TO_FIELD, "%QX3.2", "changer arm valve: to grip"),
    _s("ArmToExtract", PLC_TO_FIELD, "%QX3.3", "changer arm valve: extract"),
    _s("ArmToSwap", PLC_TO_FIELD, "%QX3.4", "changer arm valve: swap (180 deg)"),
    _s("ArmToInsert", PLC_TO_FIELD, "%QX3.5", "changer arm valve: insert"),
    _s("AlarmLamp", PLC_TO_FIELD, "%QX3.6", "red stack light: PLC alarm or E-stop"),
    _s("SpindleSpeedRef", PLC_TO_FIELD, "%QW8", "spindle speed reference, rpm (override applied)"),
    _s("CarouselTarget", PLC_TO_FIELD, "%QW9", "carousel target pocket"),
    # --- remote operator panel (host <-> PLC over Modbus) --------------------------------
    _s("RemCycleStart", HOST_TO_PLC, "%MX0.0", "remote cycle start (write 1; PLC clears it)"),
    _s("RemFeedHold", HOST_TO_PLC, "%MX0.1", "remote feed hold (write 1; PLC clears it)"),
    _s("RemReset", HOST_TO_PLC, "%MX0.2", "remote reset (write 1; PLC clears it)"),
    _s("RemFeedOvr", HOST_TO_PLC, "%MW0", "feed override request, % (limited to 0..200)"),
    _s("RemRapidOvr", HOST_TO_PLC, "%MW1", "rapid override request, % (limited to 0..200)"),
    _s("RemSpindleOvr", HOST_TO_PLC, "%MW2", "spindle override request, % (limited 0..200)"),
    _s("RemModeReq", HOST_TO_PLC, "%MW3", "mode request 1..4 (PLC clears it when taken)"),
    _s("RemProgSelect", HOST_TO_PLC, "%MX0.3", "program select strobe (hold 1 until answered)"),
    _s("RemHomeAll", HOST_TO_PLC, "%MX0.4", "home all axes, REF mode (hold 1 until answered)"),
    _s("RemProgNumber", HOST_TO_PLC, "%MW4", "O number for the program select, low word"),
    _s("RemProgNumberHigh", HOST_TO_PLC, "%MW5", "O number, high word (0 up to O65535)"),
    _s("CycleStartRefused", PLC_TO_HOST, "%MX1.0", "last cycle start request was refused"),
    _s("ModeRefused", PLC_TO_HOST, "%MX1.1", "last mode request was refused"),
    _s("ProgSelected", PLC_TO_HOST, "%MX1.2", "program select done (valid while RemProgSelect)"),
    _s("ProgSelectRefused", PLC_TO_HOST, "%MX1.3", "program select refused: ProgRefuseCode"),
    _s("HomeAccepted", PLC_TO_HOST, "%MX1.4", "home all taken, homing runs (while RemHomeAll)"),
    _s("HomeRefused", PLC_TO_HOST, "%MX1.5", "home all refused: HomeRefuseCode"),
    _s("ProgRefuseCode", PLC_TO_HOST, "%MW8", "why the program select was refused (code)"),
    _s("HomeRefuseCode", PLC_TO_HOST, "%MW9", "why the home all was refused (code)"),
)

_BY_NAME = {s.name.upper(): s for s in SIGNALS}
if len(_BY_NAME) != len(SIGNALS):  # pragma: no cover - a typo in the table above
    raise RuntimeError("duplicate signal name in plc.signals.SIGNALS")


def signal(name: str) -> Signal:
    """The declared signal `name` (case-insensitive); KeyError with the name if unknown."""
    try:
        return _BY_NAME[name.upper()]
    except KeyError:
        raise KeyError(f"no signal {name!r} in the NC<->PLC signal table") from None


def signals(direction: str | None = None) -> tuple[Signal, ...]:
    """All signals, or those of one direction (e.g. `NC_TO_PLC`)."""
    if direction is None:
        return SIGNALS
    if direction not in DIRECTIONS:
        raise ValueError(f"unknown direction {direction!r}; one of {', '.join(DIRECTIONS)}")
    return tuple(s for s in SIGNALS if s.direction == direction)


class NcPort:
    """The NC's side of the interface: the NC sets NC->PLC signals and reads PLC->NC ones.

    The I/O provider (`MachineIO`) copies the NC->PLC values into the PLC's inputs every scan
    (`apply_inputs`) and takes the PLC->NC values from its outputs (`take_outputs`), so the NC
    sees what the last scan published and the PLC sees what the NC set before the scan.
    """

    def __init__(self) -> None:
        self._inputs = {s.name: (False if s.type == "BOOL" else 0) for s in signals(NC_TO_PLC)}
        self._outputs = {s.name: (False if s.type == "BOOL" else 0) for s in signals(PLC_TO_NC)}
        self._in_bits = [(signal(n).index, n) for n in self._inputs if signal(n).area == "IX"]
        self._in_words = [(signal(n).index, n) for n in self._inputs if signal(n).area == "IW"]
        self._out_bits = [(signal(n).index, n) for n in self._outputs if signal(n).area == "QX"]
        self._out_words = [(signal(n).index, n) for n in self._outputs if signal(n).area == "QW"]

    def set(self, name: str, value: bool | int) -> None:
        """Set an NC->PLC signal (the PLC sees it at its next scan)."""
        s = signal(name)
        if s.direction != NC_TO_PLC:
            raise ValueError(f"{s.name} is {s.direction}; the NC can only set NC->PLC signals")
        if s.type == "BOOL":
            self._inputs[s.name] = bool(value)
        else:
            v = int(value)
            if not -32768 <= v <= 32767:
                raise ValueError(f"{s.name} = {v} does not fit an INT (-32768..32767)")
            self._inputs[s.name] = v

    def get(self, name: str) -> bool | int:
        """An NC->PLC value as set, or a PLC->NC value as the last scan wrote it."""
        s = signal(name)
        if s.direction == NC_TO_PLC:
            return self._inputs[s.name]
        if s.direction == PLC_TO_NC:
            return self._outputs[s.name]
        raise ValueError(f"{s.name} is {s.direction}, not part of the NC interface")

    def outputs(self) -> dict[str, bool | int]:
        """All PLC->NC values of the last scan."""
        return dict(self._outputs)

    def apply_inputs(self, ix: list[bool], iw: list[int]) -> None:
        inputs = self._inputs
        for i, n in self._in_bits:
            ix[i] = inputs[n]
        for i, n in self._in_words:
            iw[i] = inputs[n]

    def take_outputs(self, qx: list[bool], qw: list[int]) -> None:
        outputs = self._outputs
        for i, n in self._out_bits:
            outputs[n] = bool(qx[i])
        for i, n in self._out_words:
            outputs[n] = qw[i]
