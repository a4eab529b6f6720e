"""Fanuc Macro B execution: variables, system variables and the macro statements.

`MacroVariables` is the environment the compiled expressions (cnc.gcode.macro) read and
write. Variable ranges (Fanuc 0i-F, with the 30i-B added common variables and the Haas NGC
extension #10000-#10999):

| Variables | Kind | Kept |
|---|---|---|
| #0 | always vacant, read only | |
| #1-#33 | local: one set per G65/G66 macro level (the arguments) | until the macro returns |
| #100-#499, #100000-#199999 | common (the 6-digit ones: the Fanuc 30i-B added common variables) | the injected `common` mapping (the controller clears it at reset / power off), else cleared with each interpreter |
| #500-#999, #500000-#999999, #10000-#10999 | common, kept across power cycles (Fanuc 30i-B added ones; Haas NGC; not on a `kitamura` map) | in the injected `persistent` mapping |
| #1000-#1035, #1100-#1135 | interface signals in / out | inputs read 0 (no PLC here) |
| #2001... | tool offsets (`_tools`) | tool memory |
| #10001-#10999, #11001-#11999 | `macro_variable_map: kitamura` only: tool length offset H1.. and its wear | tool memory |
| #3000, #3006 | alarm / stop with message (write) | |
| #3001, #3002 | timers ms / hours | from the injected clock |
| #3003, #3004, #3901, #3902 | single block / feed hold control, parts counters | this run |
| #4001-#4130 | modal information of the block before (read only); #4012 the G66/G67 group, on a `kitamura` map the work coordinate system | |
| #5001-#5105 | positions (read only): 1st digit group = end point, machine, current, skip (the G31 skip position, work coordinates; the current position before any G31), tool length offset, servo deviation; #50x4/#50x5 the rotary 4th/5th axis (degrees) | |
| #5201-#5325, #7001-#7945 | work offsets (`_wofs`; #52x4/#52x5 the rotary axes', degrees) | work offset memory |
| #5401-#5600 | Haas tool feed timers / total tool timers, seconds (read only) | read 0: no tool usage is recorded here |

Wear offsets: the tool memory keeps one value per offset (geometry and wear together), so a
wear variable reads 0 and takes 0 (a macro that measures a length and clears its wear,
O919100); any other wear value is refused (PS0116).

`macro_variable_map` (MachineParams) picks the builder's variables where controls differ:
`haas_ngc` (default) or `kitamura`, the Kitamura HMC of the mojimould programs, whose shop
notes #4012 as the current work coordinate system and #10000+n as the length of tool offset
n (Mould_Analytical_Calculation_Note/appendix_MACN/MACN_common_variables.tex, system
variables of the Kitamura), #11000+n as its wear (O919100's own variable list).

The persistent store is any `MutableMapping[int, float]` (a plain dict by default): the
controller passes its machine data so #500-#999 survive a power cycle; a vacant variable
is an absent key. Nothing here reads a clock or does I/O.
"""

from __future__ import annotations

from collections.abc import Callable, MutableMapping
from typing import TYPE_CHECKING

from cnc.gcode.macro import (
    PS_VARIABLE_NUMBER,
    PS_WRITE_PROTECTED,
    MacroAlarm,
)
from cnc.interp.gnum import G54, G80
from cnc.interp.state import ToolOffset

if TYPE_CHECKING:
    from cnc.interp.interpreter import Interpreter

INCH = 25.4
LOCAL = range(1, 34)
COMMON = range(100, 500)
COMMON_ADDED = range(100000, 200000)  # Fanuc 30i-B added common variables (cleared)
PERSISTENT = range(500, 1000)
PERSISTENT_ADDED = range(500000, 1000000)  # Fanuc 30i-B added common variables (kept)
PERSISTENT_EXT = range(10000, 11000)  # Haas NGC extended common variables
KITAMURA_NO_EXT = range(0)  # a Kitamura has tool offsets there
KITAMURA_TOOL_LENGTH = range(10001, 11000)  # H1..H999 tool length (geometry)
KITAMURA_TOOL_WEAR = range(11001, 12000)  # H1..H999 tool length wear
HAAS_TOOL_TIMERS = range(5401, 5601)  # Haas: feed time #5400+T, total time #5500+T (s)
MAX_ALARM = 200  # #3000 = 0..200: alarm 3000..3200 (Fanuc)

# argument specification I: address -> local variable number
ARGUMENTS = {
    "A": 1, "B": 2, "C": 3, "I": 4, "J": 5, "K": 6, "D": 7, "E": 8, "F": 9, "H": 11,
    "M": 13, "Q": 17, "R": 18, "S": 19, "T": 20, "U": 21, "V": 22, "W": 23, "X": 24,
    "Y": 25, "Z": 26,
}  # fmt: skip


class MacroVariables:
    """The variables of one interpreter (`env` of the compiled expressions)."""

    __slots__ = ("ip", "loc", "levels", "common", "persistent", "signals", "misc", "clock",
                 "timer_base", "ext", "kitamura")  # fmt: skip

    def __init__(
        self,
        ip: Interpreter,
        persistent: MutableMapping[int, float] | None,
        clock: Callable[[], float] | None,
        common: MutableMapping[int, float] | None = None,
    ) -> None:
        self.ip = ip
        self.loc: dict[int, float] = {}
        self.levels: list[dict[int, float]] = [self.loc]
        self.common: MutableMapping[int, float] = {} if common is None else common
        self.persistent: MutableMapping[int, float] = {} if persistent is None else persistent
        self.signals: dict[int, float] = {}
        self.misc: dict[int, float] = {}
        self.clock = clock
        self.timer_base = {3001: 0.0, 3002: 0.0}
        # the builder's variable map: on a Kitamura #10000.. are tool offsets, not common
        self.kitamura = ip.params.macro_variable_map == "kitamura"
        self.ext = KITAMURA_NO_EXT if self.kitamura else PERSISTENT_EXT

    # --- local levels (G65/G66) --------------------------------------------------------------

    def push(self, args: dict[int, float]) -> None:
        self.loc = dict(args)
        self.levels.append(self.loc)

    def pop(self) -> None:
        if len(self.levels) > 1:
            self.levels.pop()
            self.loc = self.levels[-1]

    @property
    def depth(self) -> int:
        """Macro call level: 0 in the main program, 1 in a G65 macro, ..."""
        return len(self.levels) - 1

    # --- read / write ----------------------------------------------------------------------

    def get(self, n: int, col: int = 0) -> float | None:
        if n in LOCAL:
            return self.loc.get(n)
        if n == 0:
            return None
        if n in COMMON or n in COMMON_ADDED:
            return self.common.get(n)
        if n in PERSISTENT or n in self.ext or n in PERSISTENT_ADDED:
            v = self.persistent.get(n)
            return None if v is None else float(v)
        return _read_system(self, n, col)

    def set(self, n: int, v: float | None, col: int = 0) -> None:
        if n in LOCAL:
            if v is None:
                self.loc.pop(n, None)
            else:
                self.loc[n] = v
            return
        if n in COMMON or n in COMMON_ADDED:
            _store(self.common, n, v)
            return
        if n in PERSISTENT or n in self.ext or n in PERSISTENT_ADDED:
            _store(self.persistent, n, v)
            return
        if n == 0:
            raise MacroAlarm(PS_WRITE_PROTECTED, "#0 is always vacant (read only)", 0, col)
        _write_system(self, n, v, col)


def _store(d: MutableMapping[int, float], n: int, v: float | None) -> None:
    if v is None:
        d.pop(n, None)
    else:
        d[n] = v


def _out_of_range(n: int, col: int) -> MacroAlarm:
    return MacroAlarm(PS_VARIABLE_NUMBER, f"variable #{n} does not exist", 0, col)


def _protected(n: int, col: int) -> MacroAlarm:
    return MacroAlarm(PS_WRITE_PROTECTED, f"#{n} is read only", 0, col)


# --- system variables ----------------------------------------------------------------------------


def _unit(ip: Interpreter) -> float:
    return INCH if ip._inch else 1.0


def _tool_field(ip: Interpreter, n: int) -> tuple[int, str] | None:
    """(offset number, field) of a tool offset variable; field "" is a wear value (0)."""
    if ip._lathe:
        for base, name in ((2000, ""), (2100, ""), (2200, ""), (2700, "x"), (2800, "z"),
                           (2900, "radius")):  # fmt: skip
            if base < n <= base + 64:
                return n - base, name
        return None
    for base, name in ((2000, "length"), (2200, ""), (2400, "radius"), (2600, "")):
        if base < n <= base + 200:
            return n - base, name
    return None


def _work_offset_index(n: int) -> tuple[int, int] | None:
    """(index into _wofs, axis 0..4) of a work offset variable."""
    if 5201 <= n <= 5325:
        k, ax = divmod(n - 5201, 20)
        if ax < 5:
            return k, ax  # 0 = external/common, 1..6 = G54..G59
        return None
    if 7001 <= n <= 7945:
        k, ax = divmod(n - 7001, 20)
        if ax < 5:
            return 7 + k, ax  # G54.1 P1..P48
    return None


def _modal(ip: Interpreter, n: int) -> float | None:
    """#4001-#4130: the modal information (G codes as numbers, then words)."""
    lathe = ip._lathe
    if n == 4001:
        return float(ip._motion // 10) if ip._cycle == G80 else ip._cycle / 10.0
    if n == 4002:
        return ip._plane / 10.0
    if n == 4003:
        return 90.0 if ip._abs else 91.0
    if n == 4005:
        if lathe:
            return 99.0 if ip._per_rev else 98.0
        return 95.0 if ip._per_rev else 94.0
    if n == 4006:
        return 20.0 if ip._inch else 21.0
    if n == 4007:
        return ip._comp_code / 10.0
    if n == 4008:
        return ip._tlo_code / 10.0
    if n == 4009:
        return ip._cycle / 10.0
    if n == 4010:
        return ip._retract / 10.0 if not lathe else 98.0
    if n == 4011:
        return 51.0 if ip._xf.scale is not None else 50.0
    if n == 4012:
        if ip.vars.kitamura:  # the Kitamura's #4012: the work coordinate system (the shop's note)
            return (G54 / 10.0 + ip._wcs - 1) if ip._wcs <= 6 else 54.1
        return 66.0 if ip._g66 is not None else 67.0
    if n == 4013:
        return 96.0 if ip._css else 97.0
    if n == 4014:
        return (G54 / 10.0 + ip._wcs - 1) if ip._wcs <= 6 else 54.1
    if n == 4015:
        return ip._path / 10.0
    if n == 4016:
        return 68.0 if ip._xf.rot else 69.0
    if n == 4017:
        return 16.0 if ip._polar else 15.0
    if n == 4022:
        return 51.1 if any(ip._xf.mirror) else 50.1
    if 4001 <= n <= 4030:
        return 0.0
    u = _unit(ip)
    if n == 4107:
        return float(ip._d)
    if n == 4109:
        return None if ip._f is None else ip._f / u
    if n == 4111:
        return float(ip._h)
    if n == 4114:
        return None if ip._nword is None else float(ip._nword)
    if n == 4115:
        return None if ip._program is None else float(ip._program)
    if n == 4119:
        return ip._s
    if n == 4120:
        return float(ip._tool)
    if n == 4130:
        return float(ip._wcs - 6) if ip._wcs > 6 else 0.0
    if n in (4102, 4108, 4113):
        return None  # B, E, M of the block before: not kept
    return None


def _read_system(env: MacroVariables, n: int, col: int) -> float | None:
    ip = env.ip
    if 1000 <= n <= 1035 or 1100 <= n <= 1135:
        return env.signals.get(n, 0.0)  # no PLC in the interpreter: inputs read 0
    if 2001 <= n <= 2999:
        hit = _tool_field(ip, n)
        if hit is None:
            raise _out_of_range(n, col)
        number, name = hit
        if not name:
            return 0.0  # wear: the tool memory keeps one value per offset
        off = ip._tools.get(number, ToolOffset())
        v = getattr(off, name)
        if name == "x" and ip._diam:
            v *= 2.0
        return v / _unit(ip)
    if n in (3001, 3002):
        return _timer(env, n)
    if n in (3000, 3006):
        return None
    if n in (3003, 3004, 3901, 3902):
        return env.misc.get(n, 0.0)
    if 4001 <= n <= 4130:
        return _modal(ip, n)
    if 5001 <= n <= 5105:
        return _position(ip, n, col)
    if n in HAAS_TOOL_TIMERS:
        return 0.0  # a tool-life check (IF [#5405 GE 6000] ...) sees fresh tools
    if env.kitamura:
        if n in KITAMURA_TOOL_LENGTH:
            return ip._tools.get(n - 10000, ToolOffset()).length / _unit(ip)
        if n in KITAMURA_TOOL_WEAR:
            return 0.0  # wear: the tool memory keeps one value per offset
    hit = _work_offset_index(n)
    if hit is not None:
        k, ax = hit
        if ax > 2:  # 4th/5th axis: a rotary axis's offset in degrees, else none (0)
            rot = ip._rot
            return rot.wofs[k][ax - 3] if rot is not None and ax - 3 < len(rot.names) else 0.0
        v = ip._wofs[k][ax]
        if ax == 0 and ip._diam:
            v *= 2.0
        return v / _unit(ip)
    raise _out_of_range(n, col)


def _position(ip: Interpreter, n: int, col: int) -> float | None:
    group, ax = divmod(n - 5001, 20)
    if ax > 4:
        raise _out_of_range(n, col)
    if ax > 2:
        return _rotary_position(ip, group, ax - 3, n, col)
    u = _unit(ip)
    d = 2.0 if ax == 0 and ip._diam else 1.0
    if group == 3 and ip._skip_pos is not None:  # skip position (G31)
        return ip._skip_pos[ax] * d / u
    if group in (0, 2, 3):  # block end point, current work position (skip before any G31)
        return ip._pos[ax] * d / u
    if group == 1:  # machine coordinates
        return ip._mach[ax] / u
    if group == 4:  # tool length offset
        return ip._tlo[ax] / u
    if group == 5:  # servo deviation
        return 0.0
    raise _out_of_range(n, col)


def _rotary_position(ip: Interpreter, group: int, i: int, n: int, col: int) -> float:
    """#5004/#5005 and their families: the 4th and 5th axes are the machine's rotary axes
    in configured order (mill4: A is the 4th; mill5: B the 4th, C the 5th), in degrees,
    never scaled by G20. A machine without that axis reads 0."""
    rot = ip._rot
    if rot is None or i >= len(rot.names):
        return 0.0
    if group in (0, 2, 3):  # block end point, current position, skip position: program angle
        return rot.program(ip._wcs)[i]
    if group == 1:  # machine angle
        return rot.mach[i]
    if group in (4, 5):  # tool length offset along a rotary axis, servo deviation
        return 0.0
    raise _out_of_range(n, col)


def _timer(env: MacroVariables, n: int) -> float:
    now = env.clock() if env.clock is not None else 0.0
    if n == 3001:
        return (now - env.timer_base[3001]) * 1000.0
    return (now - env.timer_base[3002]) / 3600.0


def _write_system(env: MacroVariables, n: int, v: float | None, col: int) -> None:
    ip = env.ip
    if 1100 <= n <= 1135:
        env.signals[n] = 0.0 if v is None else v
        return
    if n in (3001, 3002):
        now = env.clock() if env.clock is not None else 0.0
        val = 0.0 if v is None else v
        env.timer_base[n] = now - (val / 1000.0 if n == 3001 else val * 3600.0)
        return
    if n in (3003, 3004, 3901, 3902):
        env.misc[n] = 0.0 if v is None else v
        return
    if 2001 <= n <= 2999:
        hit = _tool_field(ip, n)
        if hit is None:
            raise _out_of_range(n, col)
        number, name = hit
        if not name:
            _clear_wear(n, v, col)
            return
        _set_tool(ip, number, name, v)
        return
    if env.kitamura:
        if n in KITAMURA_TOOL_LENGTH:
            _set_tool(ip, n - 10000, "length", v)
            return
        if n in KITAMURA_TOOL_WEAR:
            _clear_wear(n, v, col)
            return
    hit = _work_offset_index(n)
    if hit is not None:
        k, ax = hit
        if ax > 2:
            rot = ip._rot
            if rot is None or ax - 3 >= len(rot.names):
                raise _out_of_range(n, col)  # no 4th/5th axis on this machine
            rot.wofs[k][ax - 3] = 0.0 if v is None else v  # degrees: the table stays put,
            return  # its program angle moves with the offset
        val = (0.0 if v is None else v) * _unit(ip)
        if ax == 0 and ip._diam:
            val *= 0.5
        ip._wofs[k][ax] = val
        if k in (0, ip._wcs):
            ip._refresh_offsets(resync=True)
        return
    if 4001 <= n <= 4130 or 5001 <= n <= 5105 or 1000 <= n <= 1035 or n in HAAS_TOOL_TIMERS:
        raise _protected(n, col)
    raise _out_of_range(n, col)


def _clear_wear(n: int, v: float | None, col: int) -> None:
    """A wear variable takes 0 (or vacant): the one value kept per offset is unchanged."""
    if v:
        raise MacroAlarm(PS_WRITE_PROTECTED, f"#{n}: wear offsets are not kept", 0, col)


def _set_tool(ip: Interpreter, number: int, name: str, v: float | None) -> None:
    val = (0.0 if v is None else v) * _unit(ip)
    if name == "x" and ip._diam:
        val *= 0.5
    cur = ip._tools.get(number, ToolOffset())
    fields = {"length": cur.length, "radius": cur.radius, "x": cur.x, "z": cur.z}
    fields[name] = val
    ip._tools[number] = ToolOffset(**fields)


def alarm_number(v: float | None, col: int) -> int:
    """#3000 = n: alarm 3000 + n, n an integer 0..200."""
    n = 0 if v is None else v
    if n != int(n) or not 0 <= n <= MAX_ALARM:
        raise MacroAlarm(
            "PS0119", f"#3000 = {n:g}: the alarm number must be 0..{MAX_ALARM}", 0, col
        )
    return 3000 + int(n)


def arguments(words: dict[str, float], col: int) -> dict[int, float]:
    """G65/G66 words -> local variables (argument specification I)."""
    out: dict[int, float] = {}
    for letter, v in words.items():
        if letter in ("P", "L", "N"):
            continue
        k = ARGUMENTS.get(letter)
        if k is None:
            raise MacroAlarm("PS0129", f"address {letter} is not a macro argument", 0, col)
        out[k] = v
    return out
