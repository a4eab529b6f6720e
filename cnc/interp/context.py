"""What a code handler gets: the interpreter context and the block being executed.

Handlers (cnc.interp.codes rows) are plain functions `handler(ip, run)`. `ip` is the
interpreter, passed explicitly; `Context` below lists what handlers may use of it (the
modal state and the emitters of the geometry core), so a handler module depends on this
surface and not on the interpreter's class. `run` is a `BlockRun`: the block and what the
classification found in it.
"""

from __future__ import annotations

from enum import IntEnum
from typing import TYPE_CHECKING, Protocol

from cnc.gcode.lexer import Block

if TYPE_CHECKING:
    from cnc.canon import CanonCommand, SpindleDirection
    from cnc.errors import NcError
    from cnc.interp.codes import Code
    from cnc.interp.macro import MacroVariables
    from cnc.interp.rotary import RotaryAxes
    from cnc.interp.state import ToolOffset
    from cnc.interp.transform import Transform
    from cnc.params import MachineParams


class Step(IntEnum):
    """Order of execution within a block (RS274/NGC and Fanuc), first to last.

    Units come first because they decide how every number of the block is read (F, S, axis
    words): `G20 F10` feeds 10 in/min, as on a Fanuc control.
    """

    EXACT_STOP = 0  # G9 marks the block's moves
    UNITS = 1
    FEED_MODE = 2
    FEED = 3  # F word
    SPINDLE_MODE = 4
    SPEED = 5  # S word
    TOOL_SELECT = 6  # T word
    TOOL_CHANGE = 7  # M6
    SPINDLE = 8  # M3 M4 M5 M19; an S change re-issues a turning spindle
    COOLANT = 9
    AUX = 10  # any other M code (override switches, clamps...): handed to the PLC
    DWELL = 11
    PLANE = 12
    CUTTER_COMP = 13  # G40 G41 G42, or a D word alone
    LENGTH_COMP = 14  # G43 G44 G49, or an H word alone
    COORDINATE_SYSTEM = 15  # G54..G59, G54.1 P
    PATH_CONTROL = 16  # G61 G64
    DISTANCE = 17  # G90 G91, G90.1 G91.1
    RETRACT = 18  # G98 G99 (mill)
    POLAR = 19  # G15 G16
    MIRROR = 20  # G50.1 G51.1 (Fanuc: mirror, then scaling, then rotation)
    SCALING = 21  # G50 G51
    ROTATION = 22  # G68 G69
    NON_MODAL = 23  # G10 G28 G30 G31 G53 G92 (lathe G50)
    MOTION = 24  # G0..G3, canned cycles, G80
    STOP = 25  # M0 M1 M2 M30
    SUBPROGRAM = 26  # M98 M99


class Classified:
    """What the code table says of one combination of G and M codes (cached per program).

    `g` / `m`: modal group -> code number (M7 with M8: 78); `rows`: group -> its G row;
    `gcol`: group -> which G of the block it is (for error columns); `aux`: M codes outside
    the table, in order; `owner`: the first code owning the block's axis words (then no
    motion uses them); `needs`: (alternatives, row, nth) of codes needing a
    word; `used`: the words the codes use; `modal`: whether the modal motion (or cycle) uses
    the block's words too; `steps`: (step, handler) of the codes; `plans`: handler lists by
    the mask of words with a step of their own (filled as met).
    """

    __slots__ = (
        "g",
        "rows",
        "gcol",
        "m",
        "aux",
        "owner",
        "needs",
        "used",
        "modal",
        "used_with",
        "steps",
        "plans",
        "call",
    )

    def __init__(self) -> None:
        self.g: dict[str, int] = {}
        self.rows: dict[str, Code] = {}
        self.gcol: dict[str, int] = {}
        self.m: dict[str, int] = {}
        self.aux: list[int] = []
        self.owner: Code | None = None
        self.needs: list[tuple[tuple[str, ...], Code, int]] = []
        self.used: frozenset[str] = frozenset()
        self.modal = False
        self.used_with: dict[int, frozenset[str]] = {}
        self.steps: list = []
        self.plans: dict[int, list] = {}
        self.call: Code | None = None  # G65/G66: the block is a macro call with arguments


class BlockRun:
    """One block in execution: its words, its classification and the flags steps pass on.

    `g`, `rows`, `gcol`, `m`, `aux`, `owner`: from its `Classified` (shared, read only);
    `exact`: G9 is in the block (set at its step, the first); `spindle_changed`: G96/G97
    or S changed the speed (a turning spindle is re-issued).
    """

    __slots__ = (
        "blk",
        "words",
        "line",
        "g",
        "rows",
        "gcol",
        "m",
        "aux",
        "owner",
        "exact",
        "spindle_changed",
    )

    def __init__(self, blk: Block, cls: Classified) -> None:
        self.blk = blk
        self.words = blk.words
        self.line = blk.line
        self.g = cls.g
        self.rows = cls.rows
        self.gcol = cls.gcol
        self.m = cls.m
        self.aux = cls.aux
        self.owner = cls.owner
        self.exact = False
        self.spindle_changed = False


class Context(Protocol):
    """The interpreter as the code handlers see it (cnc.interp.interpreter.Interpreter)."""

    params: MachineParams
    file: str
    # modal state
    _lathe: bool
    _diam: bool
    _motion: int
    _cycle: int
    cyc: object  # cnc.interp.cycles.CycleData
    _plane: int
    _pu: int
    _pv: int
    _pw: int
    _abs: bool
    _arc_abs: bool
    _per_rev: bool
    _inch: bool
    units_programmed: bool
    _scale: float
    _moved: bool
    _comp_code: int
    _tlo_code: int
    _tlo: tuple[float, float, float]
    _h: int
    _d: int
    _wcs: int
    _wofs: list[list[float]]
    _g92: list[float]
    _path: int
    _tol: float
    _lookahead: int
    _retract: int
    _polar: bool
    _xf: Transform
    _xf_on: bool
    _s: float
    _css: bool
    _spindle: SpindleDirection
    _mist: bool
    _flood: bool
    _tool: int
    _tool_in: int
    _pos: tuple[float, float, float]
    _mach: tuple[float, float, float]
    _home: tuple[float, float, float]
    _second_ref: tuple[float, float, float]
    _second_ref_rot: list[float]
    _rot: RotaryAxes | None
    _off: tuple[float, float, float]
    _out: list[CanonCommand]
    _tools: dict[int, ToolOffset]
    skip_misses: list[tuple[str, int]]
    upward_holes: dict[tuple[str, int], None]
    _comp: object
    _frames: list  # the program levels (cnc.interp.interpreter._Frame), innermost last
    vars: MacroVariables
    _ended: bool
    _switch: bool

    # words and errors
    def _err(self, msg: str, blk: Block, letter: str | None = None, nth: int = 1) -> NcError: ...
    def _dim(self, blk: Block, letter: str) -> float: ...
    def _plain(self, blk: Block, letter: str, unit: float = 0.001) -> float: ...
    def _int_word(self, blk: Block, letter: str) -> int: ...
    def _set_feed(self, blk: Block, f: float) -> None: ...
    def _target(self, blk: Block, words: dict[str, float]) -> tuple[float, float, float]: ...
    def _tool_word(self, blk: Block, t: float) -> None: ...
    def _offset_entry(self, blk: Block, letter: str, number: int) -> ToolOffset: ...
    # emitting and moving
    def _emit(self, cmd: CanonCommand) -> None: ...
    def _emit_spindle(self, line: int) -> None: ...
    def _rpm_now_from(self, s: float, css: bool) -> float: ...
    def _feed(self, blk: Block) -> float: ...
    def _check(self, m: tuple[float, float, float], blk: Block | None, line: int) -> None: ...
    def _line_to(self, p, feed: float | None, blk: Block, exact: bool) -> None: ...
    def _arc_to(self, e, c, cw: bool, turns: int, feed: float, blk: Block, exact: bool) -> None: ...
    def _motion_block(self, blk: Block, words, exact: bool, explicit: int | None) -> None: ...
    def _prog_from_machine(self) -> tuple[float, float, float]: ...
    def skipped(self, latched, stop) -> None: ...
    def _refresh_offsets(self, resync: bool) -> None: ...
    def _set_plane(self, code: int) -> None: ...
    def _comp_engaged(self) -> bool: ...
    def _flush_comp(self) -> None: ...
    def _xf_changed(self) -> None: ...
    # machine data (G10, G92)
    def _g10(self, blk: Block) -> None: ...
    def _coordinate_set(self, blk: Block) -> None: ...
    # program flow
    def _call(self, blk: Block) -> None: ...
    def _return(self, blk: Block) -> None: ...
    def _macro_call(self, blk: Block, row: Code) -> None: ...
    def _macro_modal_cancel(self) -> None: ...
