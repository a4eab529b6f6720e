"""The Fanuc-dialect interpreter: blocks in, canonical machine commands out.

The interpreter is a pure core: it reads lines from an iterable, keeps the modal state and
appends canonical commands (cnc.canon) in machine coordinates, mm, mm/min, s and rpm. It
never reads a clock or does I/O other than reading the program (and, for in-file
subprograms, re-reading its own source file; see cnc.gcode.source).

Coordinates move through these stages (docs/gcode.md, "Coordinates"):
    words (program units, abs/incr, polar, lathe diameter) -> program point (work, mm)
    -> mirror/scale/rotation -> cutter compensation (in the plane)
    -> + work offset (G54..G59, G10 L2 P0 common, G92) + tool offset -> machine point
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, MutableMapping
from operator import itemgetter
from typing import TYPE_CHECKING

from cnc.canon import (
    ArcFeed,
    CanonCommand,
    Plane,
    Pose,
    ProgramStop,
    Spindle,
    SpindleDirection,
    StopKind,
    StraightFeed,
    StraightTraverse,
    ToolChange,
    ToolSelect,
)
from cnc.errors import NcError
from cnc.gcode.lexer import Block, parse_line
from cnc.gcode.macro import (
    ASSIGN,
    DO,
    END,
    GOTO,
    IF_GOTO,
    IF_THEN,
    PS_DNC_JUMP,
    PS_GOTO_NOT_FOUND,
    PS_LOOP_NUMBER,
    PS_MACRO_NESTING,
    PS_MISSING_END,
    PS_NESTING,
    PS_PROGRAM_NOT_FOUND,
    PS_SEQUENCE_NOT_FOUND,
    WHILE,
    WORDS,
    MacroAlarm,
    MacroBlock,
    build_block,
)
from cnc.gcode.source import (
    Lines,
    ProgramLibrary,
    Pushback,
    ends_with_m99,
    main_lines,
    skip_leader,
)
from cnc.interp import codes
from cnc.interp.codes import fmt_g
from cnc.interp.context import BlockRun, Classified
from cnc.interp.cycles import MAX_REPEAT, CycleData
from cnc.interp.gnum import (
    G0,
    G1,
    G2,
    G3,
    G17,
    G18,
    G19,
    G40,
    G41,
    G49,
    G53,
    G54,
    G64,
    G80,
    G98,
    M7,
    M7_M8,
    M8,
)
from cnc.interp.macro import MacroVariables, alarm_number, arguments
from cnc.interp.rotary import RotaryAxes
from cnc.interp.state import ModalState, ToolOffset
from cnc.interp.transform import Transform
from cnc.params import DecimalStyle, MachineParams
from cnc.program_memory import MAX_PROGRAM_NUMBER

if TYPE_CHECKING:  # cnc.machine_data imports cnc.interp.state: no import at run time
    from cnc.machine_data import MachineData

INCH = 25.4
ARC_TOLERANCE_MM = 0.01  # |start radius - end radius| allowed (000_nc_book TV-INT-3)
MAX_SUB_NESTING = 10  # call levels at most (Fanuc 0i-D/F: 10; per machine: params.call_nesting)
MAX_TOOL_OFFSET = 999  # H/D/T offset numbers (= cnc.machine_data.MAX_TOOL_OFFSET)
EXTENDED_OFFSETS = 48  # G54.1 P1..P48; work offset list index = 6 + P
MAX_MACRO_NESTING = 5  # G65/G66 macro levels at most (Fanuc 0i-D/F: 5; params.macro_nesting)
MAX_LOOPS = 3  # WHILE/DO nesting (Fanuc: 3, ids 1..3)
MACRO_BUDGET = 1_000_000  # macro statements in a row without any command: an endless loop
LOOP_WATCH_AFTER = 10_000  # backward jumps before loops are watched for a repeated state
_EPS = 1e-9

# Letters the interpreter understands, per machine kind (others: "unknown address").
_MILL_WORDS = frozenset("XYZIJKRFSTNPQLHDE")  # E: Haas G47 plunge feed, G187 tolerance
_LATHE_WORDS = frozenset("XZUWIKRFSTNPQLHDA")  # A: the Haas G76 tool angle only
_DIM_LETTERS = frozenset("XYZUVWIJKRQ")
_AXIS_OF = {"X": 0, "Y": 1, "Z": 2}
_AXIS_NAME = "XYZ"

# Plane: (u, v, normal) axis indices and the centre words for u and v.
_PLANES = {
    G17: (0, 1, 2, "I", "J", Plane.XY),
    G18: (2, 0, 1, "K", "I", Plane.ZX),
    G19: (1, 2, 0, "J", "K", Plane.YZ),
}

_MOTION_CODES = frozenset((G0, G1, G2, G3))
_step_of = itemgetter(0)
# words with an execution step of their own (F, S, T, D, H), as bits of a plan's key
_STEP_BITS = tuple(1 << i for i in range(len(codes.WORD_STEPS)))
_STEP_WORDS = tuple(zip(_STEP_BITS, (w[0] for w in codes.WORD_STEPS), strict=True))
_CLASSIFIED_MAX = 4096  # distinct G/M combinations remembered per interpreter


class _Frame:
    """One program level: main, M98 subprogram or G65/G66 macro.

    `src` gives random access for jumps (GOTO, WHILE/END, M99 P): the lines as a list, a
    file path (read into memory on the first jump) or None (a stream: no jumps, PS0123);
    `start` is the line number of the program's first line; `loops` the open WHILE/DO
    loops as [loop id, line of the WHILE/DO]; `macro` whether it has a local variable
    level of its own (G65/G66), `args` its arguments (a repeat gets them afresh).
    """

    __slots__ = (
        "it",
        "file",
        "number",
        "repeats",
        "call_line",
        "header_seen",
        "body_started",
        "src",
        "start",
        "loops",
        "macro",
        "modal_call",
        "args",
    )

    def __init__(
        self,
        it: Lines,
        file: str,
        number: int | None,
        repeats: int,
        call_line: int,
        src: list[str] | str | None = None,
        start: int = 1,
    ):
        self.it = Pushback(it)  # a lathe cycle may look ahead for its contour
        self.file = file
        self.number = number
        self.repeats = repeats
        self.call_line = call_line
        self.header_seen = False
        self.body_started = False
        self.src = src
        self.start = start
        self.loops: list[list[int]] = []
        self.macro = False
        self.modal_call = False
        self.args: dict[int, float] | None = None


# a sequence number at the start of a line (after '/' and comments): GOTO / M99 P targets
_N_AT = re.compile(r"\s*(?:/\d?\s*)?(?:\([^)]*\)\s*)*[Nn]\s*(\d+)")
_O_AT = re.compile(r"\s*(?:/\d?\s*)?[Oo:]\s*\d")
_END_OF = re.compile(r"(?<![A-Z])END\s*(\d+)")
_COMMENT = re.compile(r"\([^)]*\)|;.*")


class Interpreter:
    """Interprets Fanuc-dialect part programs into canonical machine commands.

    `programs` maps program numbers to program text (str or lines) for M98 calls;
    `tools` maps offset numbers to ToolOffset (H, D and lathe T offsets share the table);
    None means "no tool table known" (offsets read as 0, as a DNC-side check needs), while
    a mapping makes a missing entry an error;
    `work_offsets` maps 1..6 (G54..G59), 0 (common/EXT) and 7..54 (G54.1 P1..P48, index
    6 + P) to offsets in mm;
    `machine_data` (cnc.machine_data.MachineData) is the controller's own machine data:
    tool offsets (every number 1..999 exists, 0 until set), work offsets, the G92 shift,
    the power-on unit and decimal style come from it, and G10 / G92 write into it for good
    (give a copy to keep it unchanged); it replaces `tools` and `work_offsets`;
    `block_delete` is the BLOCK DELETE switch (`/` blocks are skipped when True);
    `start` is the machine position in mm (default: every axis at its reference point);
    `max_blocks` bounds the number of executed blocks (None: unbounded) so a checker can
    refuse programs whose subprogram repeats would run for ever;
    `macro_variables` is the store of the common variables kept across power cycles
    (#500-#999, #500000-#999999, #10000-#10999): any mutable mapping number -> value, a
    vacant variable being an absent key (the controller passes its machine data; default: a
    new dict); `common_variables` holds #100-#499 and #100000-#199999 the same way (the
    controller keeps one dict from program to program and clears it at reset or power off,
    as Fanuc; default: a new dict, so they start vacant);
    `clock` gives seconds for the #3001/#3002 timers (default: time stands still);
    `macro_budget` bounds the macro statements executed in a row without any command
    coming out (an endless WHILE or GOTO loop is an alarm naming its line, not a hang);
    `subprogram`: what an M99 in the main program does: False (default) refuses it (on
    the control it would repeat the program for ever), True ends the program there (a
    subprogram checked on its own), None decides by the file: a program whose M99 is its
    last block is a subprogram.
    """

    def __init__(
        self,
        params: MachineParams,
        *,
        programs: Mapping[int, str | Iterable[str]] | None = None,
        tools: Mapping[int, ToolOffset] | None = None,
        block_delete: bool = False,
        file: str = "<program>",
        start: Pose | None = None,
        work_offsets: Mapping[int, tuple[float, ...]] | None = None,
        arc_tolerance: float = ARC_TOLERANCE_MM,
        max_blocks: int | None = None,
        machine_data: MachineData | None = None,
        macro_variables: MutableMapping[int, float] | None = None,
        clock: Callable[[], float] | None = None,
        macro_budget: int = MACRO_BUDGET,
        subprogram: bool | None = False,
        common_variables: MutableMapping[int, float] | None = None,
    ) -> None:
        self.params = params
        self._md = machine_data
        self.units_programmed = False  # a G20/G21 was read (else the power-on unit holds)
        self.macro_budget = macro_budget
        self.subprogram = subprogram
        # a subprogram checked on its own (no caller): set when a run starts
        self.checked_alone = False
        # line of the first feed move that took its caller's feed (none given in the file)
        self.caller_feed_line: int | None = None
        self.vars = MacroVariables(self, macro_variables, clock, common_variables)
        self._g66: tuple[int, dict[int, float], int] | None = None
        self._mrun = 0  # macro statements since the last command came out
        self._loaded: dict[str, list[str]] = {}
        self._nindex: dict[tuple[int, int], dict[int, list[int]]] = {}
        self._ends: dict[tuple[int, int, int], int | None] = {}
        self.messages: list[tuple[int, str]] = []  # #3006 operator messages (line, text)
        self._seen_errors: set[tuple[str, int, int, str]] = set()
        self._jumps = 0  # backward jumps (GOTO, END) so far
        self._loop_seen: dict[tuple[int, int], tuple] = {}
        self.file = file
        self.block_delete = block_delete
        self.arc_tolerance = arc_tolerance
        self.max_blocks = max_blocks
        self._lathe = params.kind == "lathe"
        self._call_nesting = min(params.call_nesting, MAX_SUB_NESTING)
        self._macro_nesting = min(params.macro_nesting, MAX_MACRO_NESTING)
        self._diam = self._lathe and params.lathe_diameter_mode
        style = params.decimal_style
        if machine_data is not None and machine_data.decimal_style is not None:
            style = DecimalStyle(machine_data.decimal_style)
        self._li = style is DecimalStyle.LEAST_INCREMENT
        self._words_ok = _LATHE_WORDS if self._lathe else _MILL_WORDS
        self._axis_words = frozenset("XZUW" if self._lathe else "XYZ")
        # fast-path words of a G0/G1 and of a G2/G3 block (others take the checked path)
        self._fast_line = frozenset("XZUWFN" if self._lathe else "XYZFN")
        self._fast_arc = frozenset("XZUWIKRFN" if self._lathe else "XYZIJKRFN")
        # a mill5 reads the mill's code table (its B/C words are the rotary axes')
        code_kind = "mill" if params.kind == "mill5" else params.kind
        self._codes = kt = codes.for_kind(code_kind, params.lathe_gcode_system)
        self._gtab = kt.g
        self._mtab = kt.m
        self._classified: dict[tuple[int, ...], Classified] = {}
        self._lib = ProgramLibrary(programs)
        if machine_data is not None:
            tools = machine_data.tool_offsets()
            work_offsets = dict(enumerate(machine_data.work_offsets))
        self._tools: dict[int, ToolOffset] = dict(tools or {})
        # rotary axes (A, B, C) of a mill4/mill5: their words and angles (cnc.interp.rotary)
        self._rot: RotaryAxes | None = None
        if params.rotary_axes and not self._lathe:
            self._rot = RotaryAxes(
                params,
                tuple(start) if start else None,
                dict(work_offsets or {}),
                7 + EXTENDED_OFFSETS,
            )
            self._words_ok = self._words_ok | self._rot.letters
        # the rotary axes a block moved or set (G92): what a machine must have to run the
        # program (the host's scheduler matches it to the machines' axes, dnc/requirements.py)
        self.rotary_named: set[str] = set()
        self._tools_known = tools is not None
        self._limits: list[tuple[int, float, float, str]] = []
        home = [0.0, 0.0, 0.0]
        # the G30 point: one figure per axis of params.axes, in their order (a lathe's X Z)
        sr = params.second_reference_mm
        second = [0.0, 0.0, 0.0]
        for k, ax in enumerate(params.axes):
            idx = _AXIS_OF.get(ax.name)
            if idx is not None:
                self._limits.append((idx, ax.min_mm, ax.max_mm, ax.name))
                home[idx] = ax.home_mm
                second[idx] = float(sr[k]) if sr is not None and k < len(sr) else ax.home_mm
        self._home = tuple(home)
        self._second_ref = tuple(second)
        lo = [-math.inf] * 3
        hi = [math.inf] * 3
        for idx, a, b, _ in self._limits:
            lo[idx], hi[idx] = a - 1e-9, b + 1e-9
        self._lo = tuple(lo)
        self._hi = tuple(hi)
        self._axes_present = {ax.name for ax in params.axes}
        self._second_ref_rot = [
            float(sr[k]) if sr is not None and k < len(sr) else ax.home_mm
            for k, ax in enumerate(params.axes)
            if ax.rotary
        ]
        self._mach: tuple[float, float, float] = (
            (float(start[0]), float(start[1]), float(start[2])) if start else self._home
        )
        # work offsets: index 0 = common (EXT), 1..6 = G54..G59, 7..54 = G54.1 P1..P48
        n_wofs = 7 + EXTENDED_OFFSETS
        self._wofs: list[list[float]] = [[0.0, 0.0, 0.0] for _ in range(n_wofs)]
        for k, v in (work_offsets or {}).items():
            if not 0 <= k < n_wofs:
                raise NcError(f"work offset number {k} is not 0..{n_wofs - 1}", 0, 0, file)
            self._wofs[k] = [float(v[0]), float(v[1]), float(v[2])]
        self._reset_modal()
        if machine_data is not None:
            self._g92 = list(machine_data.g92)
            self._inch = machine_data.power_on_units == "inch"
            self._scale = INCH if self._inch else 1.0
            self._update_simple()
        self._off = self._compute_off()
        self._pos = self._prog_from_machine()
        self._out: list[CanonCommand] = []
        self.errors: list[NcError] = []
        self._frames: list[_Frame] = []
        self._line = 0
        self._nword: int | None = None
        self._program: int | None = None
        self._ended = False
        self._executed = 0
        self._moved = False
        # G31: the skip position (work coordinates, mm) for #5061..; None before any G31
        self._skip_pos: tuple[float, float, float] | None = None
        # (file, line) of the G31 moves that ran to their end without a skip signal
        self.skip_misses: list[tuple[str, int]] = []
        # (file, line) of the canned cycles whose hole bottom was above R (they feed upward),
        # in order, once each
        self.upward_holes: dict[tuple[str, int], None] = {}

    # --- modal state ------------------------------------------------------------------

    def _reset_modal(self) -> None:
        lathe = self._lathe
        self._motion = 0
        self._cycle = G80
        self._plane = G18 if lathe else G17
        self._set_plane(self._plane)
        self._abs = True
        self._arc_abs = False
        self._per_rev = lathe  # lathe power-on G99 (feed per revolution)
        self._inch = False
        self._scale = 1.0
        self._comp_code = G40
        self._tlo_code = G49
        self._tlo = (0.0, 0.0, 0.0)
        self._h = 0
        self._d = 0
        self._wcs = 1
        self._g92 = [0.0, 0.0, 0.0]
        self._path = G64
        self._tol = self.params.default_path_tolerance  # G64 P / G187 path tolerance, mm
        self._lookahead = 0  # G103 P look-ahead limit, 0 = the machine's
        self._retract = G98
        self._polar = False
        self._xf = Transform()
        self._xf_on = False
        self._f: float | None = None  # mm/min or mm/rev
        self._s = 0.0  # rpm (G97) or surface speed m/min (G96)
        self._css = False
        self._max_rpm = self.params.max_spindle_rpm  # G50 S / G92 S lowers it
        self._spindle = SpindleDirection.STOP
        self._mist = False
        self._flood = False
        self._tool = 0
        self._tool_in = 0
        self.cyc = CycleData()
        self._comp = None
        self._comp_uv = (0.0, 0.0)
        self._comp_w = 0.0
        self._polar_ra = (0.0, 0.0)
        self._simple = True
        self._switch = False
        self._plainxyz = not self._lathe

    def _set_plane(self, code: int) -> None:
        self._plane = code
        self._pu, self._pv, self._pw, self._ci, self._cj, self._plane_enum = _PLANES[code]

    def _compute_off(self) -> tuple[float, float, float]:
        w = self._wofs[self._wcs]
        c = self._wofs[0]
        g = self._g92
        t = self._tlo
        return (w[0] + c[0] + g[0] + t[0], w[1] + c[1] + g[1] + t[1], w[2] + c[2] + g[2] + t[2])

    def _prog_from_machine(self) -> tuple[float, float, float]:
        o = self._off
        m = self._mach
        t = (m[0] - o[0], m[1] - o[1], m[2] - o[2])
        return self._xf.inverse(t) if self._xf_on else t

    @property
    def state(self) -> ModalState:
        """A snapshot of the modal state (for status displays)."""
        u = INCH if self._inch else 1.0
        pos = [p / u for p in self._pos]
        if self._diam:
            pos[0] *= 2.0
        g = {
            "motion": fmt_g(self._motion),
            "cycle": fmt_g(self._cycle),
            "plane": fmt_g(self._plane),
            "distance": "G90" if self._abs else "G91",
            "arc_distance": "G90.1" if self._arc_abs else "G91.1",
            "feed_mode": ("G99" if self._per_rev else "G98")
            if self._lathe
            else ("G95" if self._per_rev else "G94"),
            "units": "G20" if self._inch else "G21",
            "cutter_comp": fmt_g(self._comp_code),
            "length_comp": fmt_g(self._tlo_code),
            "work_offset": fmt_g(G54 + 10 * (self._wcs - 1)) if self._wcs <= 6 else "G54.1",
            "path_mode": fmt_g(self._path),
            "return_level": fmt_g(self._retract),
            "spindle_mode": "G96" if self._css else "G97",
            "polar": "G16" if self._polar else "G15",
            "scaling": "G51" if self._xf.scale is not None else "G50",
            "rotation": "G68" if self._xf.rot else "G69",
            "mirror": "G51.1" if any(self._xf.mirror) else "G50.1",
        }
        fr = self._frames[-1] if self._frames else None
        return ModalState(
            file=fr.file if fr else self.file,
            line=self._line,
            block_number=self._nword,
            program=self._program,
            subprogram_depth=max(0, len(self._frames) - 1),
            gcodes=g,
            units="inch" if self._inch else "mm",
            work_offset=g["work_offset"] if self._wcs <= 6 else f"G54.1 P{self._wcs - 6}",
            tool_selected=self._tool,
            tool_in_spindle=self._tool_in,
            length_offset=self._h,
            radius_offset=self._d,
            feed=None if self._f is None else self._f / u,
            spindle_rpm=self._rpm_now() if self._css else self._s,
            spindle=self._spindle.value,
            surface_speed=self._s if self._css else None,
            coolant_mist=self._mist,
            coolant_flood=self._flood,
            work_position=tuple(pos),
            machine_position=tuple(self._mach),
            ended=self._ended,
        )

    # --- running ----------------------------------------------------------------------

    def check_all(self, lines: Iterable[str] | str) -> list[NcError]:
        """Interpret a whole program carrying on after errors; ALL its errors (see `check`)."""
        for _ in self._run(lines, recover=True):
            pass
        return self.errors

    def run(self, lines: Iterable[str] | str) -> Iterator[CanonCommand]:
        """Interpret `lines` lazily, yielding canonical commands as blocks are read.

        Raises NcError at the offending block (unless running under `check`, which records
        the error and carries on with the next block).
        """
        return self._run(lines, recover=False)

    def _run(self, lines: Iterable[str] | str, recover: bool) -> Iterator[CanonCommand]:
        self._lib.attach(lines, self.file)
        self._ended = False
        self.checked_alone = self.subprogram is True or (
            self.subprogram is None and ends_with_m99(self._lib.main_source())
        )
        frames = self._frames
        frames.clear()
        frames.append(
            _Frame(skip_leader(main_lines(lines)), self.file, None, 1, 0, self._lib.main_source())
        )
        out = self._out
        li = self._li
        while frames and not self._ended:
            fr = frames[-1]
            file = fr.file
            self._switch = False  # set by M98/M99/M2/M30/end of tape: leave this frame's loop
            for lineno, text in fr.it:
                try:
                    blk = parse_line(text, lineno, file, li)
                    if blk is not None:
                        self._block(blk, fr)
                except NcError as err:
                    if not recover:
                        raise
                    out.clear()
                    self._record(err, file)
                    if getattr(err, "fatal", False):
                        self._ended = self._switch = True  # an alarm stops the program
                if out:
                    self._mrun = 0
                    if self._rot is not None:
                        self._rot.stamp(out)
                    if len(out) == 1:
                        yield out[0]
                    else:
                        yield from out
                    out.clear()
                if self._switch:
                    break
            else:
                # the frame's lines ran out
                if len(frames) == 1:
                    frames.pop()
                    if fr.loops:
                        err = self._open_loop(fr)
                        if not recover:
                            raise err
                        self._record(err, file)
                    break
                err = NcError(
                    f"subprogram O{fr.number} ends without M99",
                    self._line,
                    1,
                    file,
                )
                if fr.loops:
                    err = self._open_loop(fr)
                if not recover:
                    raise err
                self._record(err, file)
                frames.pop()
                if fr.macro:
                    self.vars.pop()
        try:
            self._flush_comp()
        except NcError as err:
            if not recover:
                raise
            self._record(err, self.file)
        if out:
            if self._rot is not None:
                self._rot.stamp(out)
            yield from out
            out.clear()
        self._ended = self._switch = True

    def _open_loop(self, fr: _Frame) -> MacroAlarm:
        ident, line, _ = fr.loops[-1]
        return MacroAlarm(PS_MISSING_END, f"DO {ident} without END {ident}", line, 1, fr.file)

    def _record(self, err: NcError, file: str) -> None:
        self._update_simple()
        if err.file == "<program>" and file != "<program>":
            err.file = file
        key = (err.file, err.line, err.col, err.message)
        if key in self._seen_errors:
            # the same error again: the program loops (a macro loop or repeats); stop here
            self._ended = self._switch = True
            return
        self._seen_errors.add(key)
        self.errors.append(err)
        if len(self.errors) >= CHECK_MAX_ERRORS:
            self._ended = self._switch = True

    def _err(self, msg: str, blk: Block, letter: str | None = None, nth: int = 1) -> NcError:
        if letter:
            col = blk.col(letter, nth)
        else:
            stripped = blk.text.lstrip()
            col = len(blk.text) - len(stripped) + 1 if stripped else 1
        fr = self._frames[-1] if self._frames else None
        return NcError(msg, blk.line, col, fr.file if fr else self.file)

    # --- one block --------------------------------------------------------------------

    def _block(self, blk: Block, fr: _Frame) -> None:
        if type(blk) is not Block:
            if self._marks(blk, fr):  # type: ignore[arg-type]
                return
            if type(blk) is MacroBlock:
                blk = self._macro(blk, fr)  # type: ignore[assignment]
                if blk is None:
                    return
        if not fr.body_started:
            fr.body_started = True
        words = blk.words
        g = blk.g
        if not (words or g or blk.m):
            return
        self._line = line = blk.line
        self._executed += 1
        if self.max_blocks is not None and self._executed > self.max_blocks:
            err = self._err(f"program executes more than {self.max_blocks} blocks", blk)
            err.fatal = True  # type: ignore[attr-defined]  # check stops here: it would loop
            raise err
        # fast path: a motion block (G0..G3 at most, with only the words of its motion)
        # without any other modal change
        if self._simple and not blk.m and (not g or (len(g) == 1 and g[0] in _MOTION_CODES)):
            mo = g[0] if g else self._motion
            if words.keys() <= (self._fast_arc if mo >= G2 else self._fast_line):
                self._motion = mo
                if "N" in words:
                    self._nword = int(words["N"])
                if "F" in words:
                    self._set_feed(blk, words["F"])
                if mo < G2 and self._plainxyz and blk.nopoint is None:
                    # the commonest block of all: G0/G1 X Y Z in G90, mm, no transforms
                    if not ("X" in words or "Y" in words or "Z" in words):
                        return
                    p = self._pos
                    t = (words.get("X", p[0]), words.get("Y", p[1]), words.get("Z", p[2]))
                    o = self._off
                    m = (t[0] + o[0], t[1] + o[1], t[2] + o[2])
                    lo, hi = self._lo, self._hi
                    if not (
                        lo[0] <= m[0] <= hi[0] and lo[1] <= m[1] <= hi[1] and lo[2] <= m[2] <= hi[2]
                    ):
                        self._check(m, blk, line)
                    if mo == G0:
                        self._out.append(StraightTraverse(line, m, False))
                    else:
                        f = self._f
                        if f is None or f <= 0.0 or self._per_rev:
                            f = self._feed(blk)
                        self._out.append(StraightFeed(line, m, f, False))
                    self._pos = t
                    self._mach = m
                    self._moved = True
                    return
                self._motion_block(blk, words, False, g[0] if g else None)
                return
        key = (*blk.g, -1, *blk.m)
        cls = self._classified.get(key)
        if cls is None:
            cls = self._classify(blk)
            if len(self._classified) < _CLASSIFIED_MAX:
                self._classified[key] = cls
        if cls.call is not None:
            self._macro_call(blk, cls.call)
            return
        self._check_words(blk, cls)
        n = words.get("N")
        if n is not None:
            self._nword = int(n)
        mask = 0
        for bit, letter in _STEP_WORDS:
            if letter in words:
                mask |= bit
        plan = cls.plans.get(mask)
        if plan is None:
            plan = cls.plans[mask] = self._plan(cls, mask)
        run = BlockRun(blk, cls)
        for handler in plan:
            handler(self, run)
        self._update_simple()
        if (
            self._g66 is not None
            and cls.owner is None
            and not words.keys().isdisjoint(self._axis_words)
            and not any(f.modal_call for f in self._frames)
        ):
            number, args, reps = self._g66
            self._push_macro(number, args, reps, blk, modal_call=True)

    def _classify(self, blk: Block) -> Classified:
        """The block's codes -> table rows by modal group; two codes of a group are refused."""
        cls = Classified()
        gset = cls.g
        gtab = self._gtab
        kt = self._codes
        used = set(codes.BLOCK_WORDS)
        for i, code in enumerate(blk.g):
            row = gtab.get(code)
            if row is None:
                raise self._err(f"unsupported G code {fmt_g(code)}", blk, "G", i + 1)
            if row.refused:
                raise self._err(row.refused, blk, "G", i + 1)
            grp = row.group
            if row.name in ("G65", "G66"):
                cls.call = row  # the other codes of the block run first (_macro_call)
                return cls
            if (
                grp in gset
                or (grp == "cycle" and code != G80 and "motion" in gset)
                or (grp == "motion" and gset.get("cycle", G80) != G80)
            ):
                raise self._err(
                    f"{fmt_g(code)} and another G code of modal group '{grp}' in one block",
                    blk,
                    "G",
                    i + 1,
                )
            if (grp == "skip" and gset.get("nonmodal", G53) != G53) or (
                grp == "nonmodal" and "skip" in gset and code != G53
            ):  # G31 shares group 00 with G53 only (a skip in machine coordinates)
                raise self._err(
                    f"{fmt_g(code)} and another G code of group 00 in one block (only G53"
                    " goes with G31)",
                    blk,
                    "G",
                    i + 1,
                )
            gset[grp] = code
            cls.rows[grp] = row
            cls.gcol[grp] = i + 1
            used |= kt.g_words[code]
            if row.owns_axes and cls.owner is None:
                cls.owner = row
            alts = kt.g_needs.get(code)
            if alts:
                cls.needs.append((alts, row, i + 1))
            cls.steps.append((row.step, row.handler))
        mset = cls.m
        mtab = self._mtab
        for i, code in enumerate(blk.m):
            row = mtab.get(code)
            if row is None:
                plc_codes = self.params.plc_m_codes
                if plc_codes is not None and code not in plc_codes:
                    raise self._err(
                        f"M{code} is not an M code of this machine (neither the NC's nor in"
                        " its PLC's M-code table, plc.m_codes)",
                        blk,
                        "M",
                        i + 1,
                    )
                cls.aux.append(code)  # not the kernel's: handed to the PLC
                continue
            grp = row.group
            prev = mset.get(grp)
            if prev is not None and not (grp == "coolant" and {prev, code} == {M7, M8}):
                raise self._err(
                    f"M{code} and M{prev} of one M group '{grp}' in one block", blk, "M", i + 1
                )
            mset[grp] = code if prev is None else M7_M8  # M7 with M8: both coolants
            used |= kt.m_words[code]
            alts = kt.m_needs.get(code)
            if alts:
                cls.needs.append((alts, row, i + 1))
            if prev is None:
                cls.steps.append((row.step, row.handler))
        if cls.aux:
            cls.steps.append(codes.AUX_STEP)
        cls.steps.extend(codes.ALWAYS_STEPS)
        cls.used = frozenset(used)
        cy = gset.get("cycle")
        cls.modal = cls.owner is None and "motion" not in gset and cy in (None, G80)
        return cls

    def _check_words(self, blk: Block, cls: Classified) -> None:
        """Every word must be one a code of the block (or the modal motion) uses."""
        words = blk.words
        if not words.keys() <= codes.BLOCK_WORDS:
            ok = self._words_ok
            if not words.keys() <= ok:
                for k in words:
                    if k not in ok:
                        if k == "Y" and self._lathe:
                            raise self._err("a lathe has no Y axis", blk, k)
                        if k in "ABCUVW" and not self._lathe:
                            raise self._err(
                                f"unknown address {k} (axis {k} is not configured)", blk, k
                            )
                        raise self._err(f"unknown address {k}", blk, k)
            used = cls.used
            rot = self._rot
            if rot is not None and not words.keys().isdisjoint(rot.letters):
                used = used | self._rotary_words_ok(blk, cls)
            if cls.modal:
                # no motion code and no code owning the axis words: the modal motion moves
                # (or, without G80 in the block, the modal cycle drills)
                modal = self._cycle if self._cycle != G80 and "cycle" not in cls.g else self._motion
                with_modal = cls.used_with.get(modal)
                if with_modal is None:
                    with_modal = cls.used_with[modal] = used | self._codes.g_words[modal]
                used = with_modal
            if not words.keys() <= used:
                for k in words:
                    if k not in used:
                        raise self._err(f"{k} word with no code in this block that uses it", blk, k)
        for alts, row, nth in cls.needs:
            for alt in alts:
                if not any(letter in words for letter in alt):
                    need = (
                        " or ".join(alt) if len(alt) <= 2 else f"{', '.join(alt[:-1])} or {alt[-1]}"
                    )
                    raise self._err(f"{row.name} needs {need}", blk, row.letter, nth)

    def _rotary_words_ok(self, blk: Block, cls: Classified) -> frozenset[str]:
        """A rotary word moves the table with the block's G0/G1, G53 or G28/G30, or sets
        its G92 shift; anywhere else it is refused at the word."""
        assert self._rot is not None
        nonmodal = cls.rows.get("nonmodal")
        name = nonmodal.name if nonmodal is not None else None
        cycle = cls.g.get("cycle", self._cycle if "motion" not in cls.g else G80)
        motion = cls.g.get("motion", self._motion)
        ok = name in ("G53", "G28", "G30", "G92") or (
            name is None and cycle == G80 and motion in (G0, G1) and cls.owner is None
        )
        named = self._rot.words_in(blk)
        letter = named[0]
        if not ok:
            raise self._err(
                f"rotary axis word {letter} moves only with G0/G1, G53 or G28/G30"
                " (or sets G92): not in a circle or a canned cycle",
                blk,
                letter,
            )
        if self._comp is not None and self._comp.active:
            raise self._err(
                f"rotary axis word {letter} with cutter compensation active (cancel with G40)",
                blk,
                letter,
            )
        self.rotary_named.update(named)
        return self._rot.letters

    @staticmethod
    def _plan(cls: Classified, mask: int) -> list:
        """The block's handlers in the order of execution (codes.Step), each once."""
        todo = list(cls.steps)
        for bit, (_, step, handler) in zip(_STEP_BITS, codes.WORD_STEPS, strict=True):
            if mask & bit:
                todo.append((step, handler))
        todo.sort(key=_step_of)
        out = []
        for _, handler in todo:
            if handler not in out:  # G0..G3 and the cycles share the motion step
                out.append(handler)
        return out

    def _update_simple(self) -> None:
        """Whether the next plain motion block may take the fast path."""
        comp = self._comp
        self._simple = (
            self._cycle == G80
            and not self._xf_on
            and (comp is None or not comp.active)
            and self._g66 is None
        )
        self._plainxyz = (
            self._simple and self._abs and not self._polar and not self._inch and not self._lathe
        )

    def _marks(self, blk, fr: _Frame) -> bool:
        """Tape marks, block delete and O headers; True when the block is done with."""
        main = len(self._frames) == 1
        if blk.tape:
            if main:
                if fr.body_started:
                    self._ended = self._switch = True  # closing '%': end of tape
                fr.body_started = True
            elif fr.body_started:
                raise self._err(f"subprogram O{fr.number} ends without M99", blk)
            return True
        if blk.delete and self.block_delete:
            return True
        if blk.program is not None:
            if main:
                if self._program is None and not self._moved:
                    self._program = blk.program
                else:
                    self._ended = self._switch = (
                        True  # the next program in the file: main program ends
                    )
                    return True
            elif fr.header_seen or fr.body_started:
                raise self._err(f"subprogram O{fr.number} ends without M99", blk)
            fr.header_seen = True
        return False

    # --- words --------------------------------------------------------------------------

    def _set_feed(self, blk: Block, f: float) -> None:
        f *= self._scale
        if f < 0:
            raise self._err("F must not be negative", blk, "F")
        if not self._per_rev:
            f = min(f, self.params.max_feed)
        self._f = f

    def _dim(self, blk: Block, letter: str) -> float:
        """A length word in mm (decimal-point rule, then units)."""
        v = blk.words[letter]
        if blk.nopoint is not None and letter in blk.nopoint:
            v *= self.params.least_increment_inch if self._inch else self.params.least_increment_mm
        return v * self._scale

    def _plain(self, blk: Block, letter: str, unit: float = 0.001) -> float:
        """An angle/factor/time word: without a point in least-increment style, x unit."""
        v = blk.words[letter]
        if blk.nopoint is not None and letter in blk.nopoint:
            v *= unit
        return v

    def _int_word(self, blk: Block, letter: str) -> int:
        v = blk.words[letter]
        if v != int(v) or v < 0:
            raise self._err(f"{letter} needs a non-negative integer", blk, letter)
        return int(v)

    def _target(self, blk: Block, words: dict[str, float]) -> tuple[float, float, float]:
        """The block's end point in program coordinates (mm, work system)."""
        x, y, z = self._pos
        sc = self._scale
        np_ = blk.nopoint
        if np_ is None and sc == 1.0 and not self._polar:
            if self._abs:
                if "X" in words:
                    x = words["X"] * 0.5 if self._diam else words["X"]
                if "Y" in words:
                    y = words["Y"]
                if "Z" in words:
                    z = words["Z"]
            else:
                if "X" in words:
                    x += words["X"] * 0.5 if self._diam else words["X"]
                if "Y" in words:
                    y += words["Y"]
                if "Z" in words:
                    z += words["Z"]
            if self._lathe:
                if "U" in words:
                    x += words["U"] * 0.5 if self._diam else words["U"]
                if "W" in words:
                    z += words["W"]
            return (x, y, z)
        p = [x, y, z]
        vals = {}
        for letter in "XYZ":
            if letter in words:
                v = self._dim(blk, letter)
                if letter == "X" and self._diam:
                    v *= 0.5
                vals[letter] = v
        if self._polar:
            return self._polar_target(blk, vals)
        for letter, v in vals.items():
            i = _AXIS_OF[letter]
            p[i] = v if self._abs else p[i] + v
        if self._lathe:
            if "U" in words:
                p[0] += self._dim(blk, "U") * (0.5 if self._diam else 1.0)
            if "W" in words:
                p[2] += self._dim(blk, "W")
        return (p[0], p[1], p[2])

    def _polar_target(self, blk: Block, vals: dict[str, float]) -> tuple[float, float, float]:
        u, v, w = self._pu, self._pv, self._pw
        p = list(self._pos)
        names = _AXIS_NAME
        if names[w] in vals:
            p[w] = vals[names[w]] if self._abs else p[w] + vals[names[w]]
        r_letter, a_letter = names[u], names[v]
        if r_letter not in vals and a_letter not in vals:
            return (p[0], p[1], p[2])
        pr, pa = getattr(self, "_polar_ra", (0.0, 0.0))
        r = vals.get(r_letter, pr)
        if a_letter in blk.words:
            a = self._plain(blk, a_letter)
            a = a if self._abs else pa + a
        else:
            a = pa
        self._polar_ra = (r, a)
        pole = (0.0, 0.0) if self._abs else (p[u], p[v])
        rad = math.radians(a)
        p[u] = pole[0] + r * math.cos(rad)
        p[v] = pole[1] + r * math.sin(rad)
        return (p[0], p[1], p[2])

    def _tool_word(self, blk: Block, t: float) -> None:
        if t != int(t) or t < 0:
            raise self._err("T needs a non-negative integer", blk, "T")
        t = int(t)
        line = blk.line
        if self._lathe:
            tool, ofs = (t // 100, t % 100) if t >= 100 else (t, t)
            self._tool = tool
            self._emit(ToolSelect(line, tool))
            self._emit(ToolChange(line, tool))
            self._tool_in = tool
            if ofs == 0:
                self._tlo = (0.0, 0.0, 0.0)
            else:
                off = self._tools.get(ofs)
                if off is None and (not self._tools_known or self._md is not None):
                    if ofs > MAX_TOOL_OFFSET:
                        raise self._err(f"T{t}: offset number {ofs} is out of range", blk, "T")
                    off = ToolOffset()  # not set in the machine data: 0 as on a control
                if off is None:
                    raise self._err(f"T{t}: no tool offset number {ofs}", blk, "T")
                self._tlo = (off.x, 0.0, off.z)
                self._d = ofs
            self._refresh_offsets(resync=False)
        else:
            self._tool = t
            self._emit(ToolSelect(line, t))

    def _offset_entry(self, blk: Block, letter: str, number: int) -> ToolOffset:
        if number == 0:
            return ToolOffset()
        if not 0 < number <= MAX_TOOL_OFFSET:
            raise self._err(
                f"{letter}{number}: offset number out of range 1..{MAX_TOOL_OFFSET}", blk, letter
            )
        off = self._tools.get(number)
        if off is None:
            if not self._tools_known or self._md is not None:
                # no tool table given (a DNC check), or an offset the control has but
                # nobody set: it reads 0
                return ToolOffset()
            raise self._err(f"{letter}{number}: no such tool offset", blk, letter)
        return off

    # --- emitting ---------------------------------------------------------------------

    def _emit(self, cmd: CanonCommand) -> None:
        """Append a non-motion command, keeping it in order behind held comp segments."""
        comp = self._comp
        if comp is not None and comp.active:
            uv = self._comp_uv
            seg = self._seg_cls("line", uv, uv, None, False, cmd.line, 1, ("cmd", cmd))
            self._comp_out(comp.push(seg))
        else:
            self._out.append(cmd)

    def _check(self, m: tuple[float, float, float], blk: Block | None, line: int) -> None:
        for idx, lo, hi, name in self._limits:
            v = m[idx]
            if v < lo - 1e-9 or v > hi + 1e-9:
                col = 1
                if blk is not None:
                    letters = {0: "XU", 1: "Y", 2: "ZW"}[idx]
                    for letter in letters:
                        if letter in blk.words:
                            col = blk.col(letter)
                            break
                raise NcError(
                    f"axis {name} move to {v:.4f} mm is beyond the soft limit "
                    f"[{lo:g}, {hi:g}] mm (machine coordinates)",
                    line,
                    col,
                    self._frames[-1].file if self._frames else self.file,
                )

    def _rpm_now(self) -> float:
        return self._rpm_now_from(self._s, self._css)

    def _rpm_now_from(self, s: float, css: bool) -> float:
        if not css:
            return s
        x = abs(self._xf.apply(self._pos)[0] if self._xf_on else self._pos[0])
        mx = self._max_rpm
        if x < 1e-9:
            return mx if mx is not None else 0.0
        rpm = 1000.0 * s / (math.pi * 2.0 * x)
        return min(rpm, mx) if mx is not None else rpm

    def _emit_spindle(self, line: int) -> None:
        if self._css:
            self._emit(Spindle(line, self._spindle, self._rpm_now(), self._s, self._max_rpm))
        else:
            self._emit(Spindle(line, self._spindle, self._s))

    def _feed(self, blk: Block) -> float:
        f = self._f
        if f is None:
            if self.checked_alone:
                # a subprogram on its own (or a program it calls): its caller set the feed
                # (F is modal across M98/G65); the move is checked at the machine's top feed
                if self.caller_feed_line is None:
                    self.caller_feed_line = blk.line
                return self.params.max_feed
            raise self._err("feed move without F", blk)
        if self._per_rev:
            rpm = self._rpm_now()
            if rpm <= 0.0:
                raise self._err("feed per revolution (G95) with no spindle speed", blk)
            f = min(f * rpm, self.params.max_feed)
        if f <= 0.0:
            raise self._err("feed move with F0", blk, "F" if "F" in blk.words else None)
        return f

    # --- motion -------------------------------------------------------------------------

    def _motion_block(
        self, blk: Block, words: dict[str, float], exact: bool, explicit: int | None
    ) -> None:
        has_axis = (
            "X" in words
            or "Y" in words
            or "Z" in words
            or (self._lathe and ("U" in words or "W" in words))
        )
        mo = self._motion
        rot = self._rot
        if rot is not None and mo < G2 and rot.move(self, blk, self._abs) and not has_axis:
            # a rotary-only block: the table turns, X Y Z stay (stamped on the way out)
            m = self._mach
            if mo == G0:
                self._out.append(StraightTraverse(blk.line, m, exact))
            else:
                self._out.append(StraightFeed(blk.line, m, self._feed(blk), exact))
            self._moved = True
            return
        if mo >= G2:
            if not has_axis and not (self._ci in words or self._cj in words or "R" in words):
                if explicit is not None and explicit >= G2:
                    raise self._err("arc without end point or centre", blk, "G")
                return
            self._arc(blk, words, mo == G2, exact)
            return
        if not has_axis:
            return
        target = self._target(blk, words)
        if mo == G0:
            self._line_to(target, None, blk, exact)
        else:
            self._line_to(target, self._feed(blk), blk, exact)

    def _line_to(
        self,
        p: tuple[float, float, float],
        feed: float | None,
        blk: Block,
        exact: bool,
    ) -> None:
        """Straight move to program point `p` (rapid when feed is None)."""
        t = self._xf.apply(p) if self._xf_on else p
        line = blk.line
        if self._comp is not None and self._comp.active:
            self._comp_line(t, feed, blk, exact)
            self._pos = p
            self._moved = True
            return
        o = self._off
        m = (t[0] + o[0], t[1] + o[1], t[2] + o[2])
        if self._lathe:
            m = (m[0], 0.0, m[2])
        lo, hi = self._lo, self._hi
        if not (lo[0] <= m[0] <= hi[0] and lo[1] <= m[1] <= hi[1] and lo[2] <= m[2] <= hi[2]):
            self._check(m, blk, line)
        if feed is None:
            self._out.append(StraightTraverse(line, m, exact))
        else:
            self._out.append(StraightFeed(line, m, feed, exact))
        self._pos = p
        self._mach = m
        self._moved = True

    def _arc(self, blk: Block, words: dict[str, float], cw: bool, exact: bool) -> None:
        u, v, w = self._pu, self._pv, self._pw
        s = self._pos
        e = self._target(blk, words)
        su, sv, eu, ev = s[u], s[v], e[u], e[v]
        tol = self.arc_tolerance
        full = abs(su - eu) < _EPS and abs(sv - ev) < _EPS
        if "R" in words:
            if self._ci in words or self._cj in words:
                raise self._err("arc with both R and I/J/K", blk, "R")
            r = words["R"] if blk.nopoint is None and self._scale == 1.0 else self._dim(blk, "R")
            if full:
                raise self._err("R arc with start point equal to end point (full circle)", blk, "R")
            du, dv = eu - su, ev - sv
            chord = math.hypot(du, dv)
            half = chord / 2.0
            rr = abs(r)
            if rr < half - tol:
                raise self._err(
                    f"arc radius R{rr:.4f} mm is smaller than half the chord {half:.4f} mm",
                    blk,
                    "R",
                )
            h = math.sqrt(max(rr * rr - half * half, 0.0))
            side = 1.0 if not cw else -1.0  # centre left of the chord for a short CCW arc
            if r < 0:
                side = -side
            cu = su + du / 2.0 - dv / chord * h * side
            cv = sv + dv / 2.0 + du / chord * h * side
        else:
            ci, cj = self._ci, self._cj
            if ci not in words and cj not in words:
                raise self._err("arc needs R or a centre (I/J/K)", blk, "G")
            if blk.nopoint is None and self._scale == 1.0:
                oi = words.get(ci, 0.0)
                oj = words.get(cj, 0.0)
            else:
                oi = self._dim(blk, ci) if ci in words else 0.0
                oj = self._dim(blk, cj) if cj in words else 0.0
            if self._arc_abs:
                cu = oi if ci in words else su
                cv = oj if cj in words else sv
            else:
                cu, cv = su + oi, sv + oj
            r1 = math.hypot(su - cu, sv - cv)
            r2 = math.hypot(eu - cu, ev - cv)
            if r1 < _EPS:
                raise self._err("arc with zero radius (centre at the start point)", blk, ci)
            if abs(r1 - r2) > tol:
                raise self._err(
                    f"arc start radius {r1:.4f} mm and end radius {r2:.4f} mm differ by "
                    f"{abs(r1 - r2):.4f} mm (tolerance {tol:g} mm)",
                    blk,
                    ci if ci in words else cj,
                )
            if not full and abs(r1 - r2) > 1e-12 * r1:
                # put the centre on the chord's perpendicular bisector: no spiral
                mu, mv = (su + eu) / 2.0, (sv + ev) / 2.0
                du, dv = eu - su, ev - sv
                ch = math.hypot(du, dv)
                nu, nv = -dv / ch, du / ch
                off = (cu - mu) * nu + (cv - mv) * nv
                moved = abs((cu - mu) * du + (cv - mv) * dv) / ch + abs(r1 - r2)
                cu, cv = mu + off * nu, mv + off * nv
                if self._comp is not None and self._comp.active:
                    # the contour is known only this well now: the interference check allows it
                    self._comp.widen_slack(moved)
        turns = 0
        if "P" in words:
            p = words["P"]
            if p != int(p) or not 1 <= p <= MAX_REPEAT:
                raise self._err(f"arc P (number of turns) must be 1..{MAX_REPEAT}", blk, "P")
            turns = int(p) - 1
        c = [0.0, 0.0, 0.0]
        c[u], c[v], c[w] = cu, cv, s[w]
        feed = self._f
        if feed is None or feed <= 0.0 or self._per_rev:
            feed = self._feed(blk)
        self._arc_to(e, c, cw, turns, feed, blk, exact)

    def _arc_to(
        self,
        e: tuple[float, float, float],
        c: tuple[float, float, float] | list[float],
        cw: bool,
        turns: int,
        feed: float,
        blk: Block,
        exact: bool,
    ) -> None:
        """Arc in the active plane from the current point to program point `e` about the
        program point `c` (its plane components), through transforms, compensation and
        offsets like a programmed G2/G3 (the cycles that cut arcs use it too)."""
        u, v, w = self._pu, self._pv, self._pw
        s = self._pos
        tol = self.arc_tolerance
        cw_out = cw
        if self._xf_on:
            xf = self._xf
            if xf.plane_scale(u, v) is None:
                raise self._err("arc under unequal in-plane scaling (G51 I/J/K)", blk, "G")
            if xf.rot and xf.rot_uv != (u, v):
                raise self._err("arc outside the G68 rotation plane", blk, "G")
            et = xf.apply(e)
            ct = list(xf.apply(c))
            if xf.handedness(u, v) < 0:
                cw_out = not cw
        else:
            et, ct = e, c
        comp = self._comp
        if comp is not None and comp.active:
            st = self._xf.apply(s) if self._xf_on else s
            ct = list(ct)
            ct[w] = st[w]
            self._comp_arc(st, et, ct, cw_out, feed, turns, blk, exact)
            self._pos = e
            self._moved = True
            return
        o = self._off
        ms = self._mach  # the arc starts where the tool is
        m = (et[0] + o[0], et[1] + o[1], et[2] + o[2])
        mc = [ct[0] + o[0], ct[1] + o[1], ct[2] + o[2]]
        mc[w] = ms[w]
        if self._lathe:
            m = (m[0], 0.0, m[2])
            mc[1] = 0.0
        mc = (mc[0], mc[1], mc[2])
        du, dv = ms[u] - mc[u], ms[v] - mc[v]
        r = math.sqrt(du * du + dv * dv)
        eu, ev = m[u] - mc[u], m[v] - mc[v]
        if abs(math.sqrt(eu * eu + ev * ev) - r) > tol:
            raise self._err(
                "arc start is not the current position (an offset changed without a move)",
                blk,
                "G",
            )
        lo, hi = self._lo, self._hi
        if not (
            lo[u] <= mc[u] - r
            and mc[u] + r <= hi[u]
            and lo[v] <= mc[v] - r
            and mc[v] + r <= hi[v]
            and lo[w] <= m[w] <= hi[w]
        ):
            self._check(m, blk, blk.line)
            self._check_arc_extent(ms, m, mc, cw_out, turns, blk)
        self._out.append(ArcFeed(blk.line, m, mc, self._plane_enum, cw_out, feed, turns, exact))
        self._pos = e
        self._mach = m
        self._moved = True

    def _check_arc_extent(self, ms, me, mc, cw: bool, turns: int, blk: Block) -> None:
        u, v = self._pu, self._pv
        r = math.hypot(ms[u] - mc[u], ms[v] - mc[v])
        a0 = math.atan2(ms[v] - mc[v], ms[u] - mc[u])
        a1 = math.atan2(me[v] - mc[v], me[u] - mc[u])
        sweep = (a0 - a1) if cw else (a1 - a0)
        sweep %= 2.0 * math.pi
        if sweep < 1e-12 or turns > 0:
            sweep = 2.0 * math.pi
        for k in range(4):
            th = k * math.pi / 2.0
            d = ((a0 - th) if cw else (th - a0)) % (2.0 * math.pi)
            if d <= sweep:
                p = list(ms)
                p[u] = mc[u] + r * math.cos(th)
                p[v] = mc[v] + r * math.sin(th)
                try:
                    self._check((p[0], p[1], p[2]), None, blk.line)
                except NcError as err:
                    raise NcError(
                        "arc extent: " + err.message, blk.line, blk.col("G"), err.file
                    ) from None

    # --- modes with axis words ---------------------------------------------------------

    def skipped(self, latched: Pose | None, stop: Pose) -> None:
        """The outcome of the last G31 (cnc.interp.skip): the machine position (mm) latched
        at the skip signal, None when none came, and where the machine stopped. The next
        block starts from `stop`; #5061.. read `latched` (else the end point) in work
        coordinates. The controller calls it with the encoder's latch before it takes the
        next block from the interpreter."""
        self._mach = (float(stop[0]), float(stop[1]), float(stop[2]))
        self._pos = self._prog_from_machine()
        if latched is None:
            self._skip_pos = self._pos
        else:
            keep = self._mach
            self._mach = (float(latched[0]), float(latched[1]), float(latched[2]))
            self._skip_pos = self._prog_from_machine()
            self._mach = keep

    def _refresh_offsets(self, resync: bool) -> None:
        self._off = self._compute_off()
        if resync:
            self._pos = self._prog_from_machine()

    def _cutter_comp(self, blk: Block, code: int) -> None:
        self._comp_code = code
        if code == G40:
            if self._comp is not None and self._comp.active:
                self._comp.cancel()
            return
        if self._plane == G19:
            raise self._err("cutter compensation in the G19 plane is not supported", blk, "G")
        try:  # deferred: optional, a build without cnc.cutter_comp refuses G41/G42 (below)
            from cnc.cutter_comp import CutterCompensation, Segment
        except ImportError:
            raise self._err(
                "G41/G42 cutter radius compensation is not available (cnc.cutter_comp is missing)",
                blk,
                "G",
            ) from None
        if "D" in blk.words:
            self._d = self._int_word(blk, "D")
        radius = self._offset_entry(blk, "D", self._d).radius if self._d else 0.0
        side = "left" if code == G41 else "right"
        if self._xf_on and self._xf.handedness(self._pu, self._pv) < 0:
            side = "right" if side == "left" else "left"
        if self._comp is None:
            self._comp = CutterCompensation(self._frames[-1].file if self._frames else self.file)
            self._seg_cls = Segment
        t = self._xf.apply(self._pos) if self._xf_on else self._pos
        if not self._comp.active:
            self._comp_uv = (t[self._pu], t[self._pv])
            self._comp_w = t[self._pw]
        self._comp.start(side, radius, line=blk.line, col=blk.col("G"))

    def _comp_line(self, t, feed, blk: Block, exact: bool) -> None:
        u, v, w = self._pu, self._pv, self._pw
        uv = (t[u], t[v])
        payload = ("move", blk.line, feed, self._comp_w, t[w], self._off, exact, None, 0)
        seg = self._seg_cls(
            "line", self._comp_uv, uv, None, False, blk.line, blk.col("G"), payload,
            rapid=feed is None,
        )  # fmt: skip
        self._comp_uv = uv
        self._comp_w = t[w]
        self._comp_out(self._comp.push(seg))
        if self._comp_code == G40 and not self._comp.active:
            self._comp_out(self._comp.flush())

    def _comp_arc(self, st, et, ct, cw, feed, turns, blk: Block, exact: bool) -> None:
        u, v, w = self._pu, self._pv, self._pw
        uv = (et[u], et[v])
        payload = ("move", blk.line, feed, st[w], et[w], self._off, exact, cw, turns)
        seg = self._seg_cls(
            "arc", self._comp_uv, uv, (ct[u], ct[v]), not cw, blk.line, blk.col("G"), payload
        )
        self._comp_uv = uv
        self._comp_w = et[w]
        self._comp_out(self._comp.push(seg))

    def _comp_out(self, segs) -> None:
        u, v, w = self._pu, self._pv, self._pw
        out = self._out
        for seg in segs:
            p = seg.payload
            if p[0] == "cmd":
                out.append(p[1])
                continue
            _, line, feed, w0, w1, off, exact, cw, turns = p
            if seg.role == "corner":
                # The arc around an outside corner is inserted before the next element and
                # carries its payload; it turns once and stays at the current height.
                w1, turns, exact = self._mach[w] - off[w], 0, False
            e = [0.0, 0.0, 0.0]
            e[u], e[v], e[w] = seg.end[0], seg.end[1], w1
            m = (e[0] + off[0], e[1] + off[1], e[2] + off[2])
            if self._lathe:
                m = (m[0], 0.0, m[2])
            self._check(m, None, line)
            if seg.kind == "arc":
                c = [0.0, 0.0, 0.0]
                c[u], c[v], c[w] = seg.center[0], seg.center[1], self._mach[w] - off[w]
                mc = (c[0] + off[0], c[1] + off[1], c[2] + off[2])
                if self._lathe:
                    mc = (mc[0], 0.0, mc[2])
                f = feed if feed is not None else self._f or 1.0
                out.append(ArcFeed(line, m, mc, self._plane_enum, not seg.ccw, f, turns, exact))
            elif feed is None:
                out.append(StraightTraverse(line, m, exact))
            else:
                out.append(StraightFeed(line, m, feed, exact))
            self._mach = m

    def _comp_engaged(self) -> bool:
        """Whether G41/G42 is in effect; a G40 still waiting for its cancel move ends here.

        G40 programmed with no in-plane move leaves the compensator waiting for a cancel
        move; a block that needs compensation over (G28/G30/G53, a plane change, a canned
        cycle, a transform) completes it instead: the last element ends at its
        perpendicular offset and the next move leaves from there, uncompensated.
        """
        comp = self._comp
        if comp is None or not comp.active:
            return False
        if comp.cancelling:
            self._comp_out(comp.finish())
            return False
        return True

    def _flush_comp(self) -> None:
        if self._comp is not None:
            self._comp_out(self._comp.flush())

    def _xf_changed(self) -> None:
        self._xf_on = self._xf.active
        if self._comp_engaged():
            raise NcError(
                "mirror/scaling/rotation change while cutter compensation is active",
                self._line,
                1,
                self.file,
            )
        # the program point stays; the machine reaches it on the next move

    def _g10(self, blk: Block) -> None:
        """G10 data setting (Fanuc): L2 P0..P6 work offsets (P0 = EXT), L20 P1..P48 the
        G54.1 extended offsets; L1 / L10 / L11 / L12 / L13 P<n> R tool offsets (memory A,
        length geometry / wear, radius geometry / wear; lathe: X Z for the tip offset, R the
        nose radius, Q the tip; or the T-series form G10 P X Z R Q / U W). Values are
        absolute in G90, added in G91. With machine data the change is written there for
        good."""
        words = blk.words
        if "L" not in words and self._lathe and "P" in words:
            # Fanuc T series: G10 P<n> X Z R Q (U W add), P1..999 the wear,
            # P10001..10999 the geometry of offset n
            p = self._int_word(blk, "P")
            n = p - 10000 if p > 10000 else p
            if not 1 <= n <= MAX_TOOL_OFFSET:
                raise self._err(
                    f"G10 P{p}: P must be 1..{MAX_TOOL_OFFSET} (wear) or"
                    f" 10001..{10000 + MAX_TOOL_OFFSET} (geometry)",
                    blk,
                    "P",
                )
            if not any(letter in words for letter in "XZUWRQ"):
                raise self._err(f"G10 P{p} needs X, Z, U, W, R or Q", blk, "G")
            self._set_tool_offset(blk, 10 if p > 10000 else 11, n)
            return
        if "L" not in words:
            raise self._err("G10 needs L (L2/L20: work offset, L1/L10..L13: tool offset)", blk, "G")
        lv = self._int_word(blk, "L")
        if "P" not in words:
            raise self._err(f"G10 L{lv} needs P (offset number)", blk, "G")
        p = self._int_word(blk, "P")
        md = self._md
        if lv in (2, 20):
            if lv == 2 and not 0 <= p <= 6:
                raise self._err(f"G10 L2 P{p}: only P0..P6 (EXT, G54..G59)", blk, "P")
            if lv == 20 and not 1 <= p <= EXTENDED_OFFSETS:
                raise self._err(
                    f"G10 L20 P{p}: P must be 1 .. {EXTENDED_OFFSETS} (G54.1 P1..P48)", blk, "P"
                )
            idx = p if lv == 2 else 6 + p
            if not any(letter in words for letter in "XYZ"):
                raise self._err(f"G10 L{lv} needs X, Y or Z", blk, "G")
            ofs = list(self._wofs[idx])
            for letter in "XYZ":
                if letter in words:
                    i = _AXIS_OF[letter]
                    val = self._dim(blk, letter) * (0.5 if letter == "X" and self._diam else 1.0)
                    ofs[i] = val if self._abs else ofs[i] + val
            if md is not None:
                try:
                    md.set_work_offset(idx, ofs)
                except ValueError as e:
                    raise self._err(f"G10 L{lv} P{p}: {e}", blk, "G") from None
            self._wofs[idx] = ofs
            if idx in (0, self._wcs):
                self._refresh_offsets(resync=True)
        elif lv in (1, 10, 11, 12, 13):
            if not 1 <= p <= MAX_TOOL_OFFSET:
                raise self._err(
                    f"G10 L{lv} P{p}: offset number must be 1..{MAX_TOOL_OFFSET}", blk, "P"
                )
            lathe_words = self._lathe and any(letter in words for letter in "XZUWQ")
            if "R" not in words and not lathe_words:
                need = "R, X or Z" if self._lathe else "R"
                raise self._err(f"G10 L{lv} needs {need} (offset value)", blk, "G")
            self._set_tool_offset(blk, lv, p)
        else:
            raise self._err(f"G10 L{lv} is not supported (L1, L2, L10..L13, L20)", blk, "L")

    def _set_tool_offset(self, blk: Block, lv: int, p: int) -> None:
        words = blk.words
        wear = lv in (11, 13)
        # which fields this L sets: (length or radius, geometry or wear); lathe X/Z go to
        # geometry with L1/L10/L12, wear with L11/L13
        fields: dict[str, float] = {}
        added: set[str] = set()  # fields given incrementally (G91, lathe U/W)
        if "R" in words:
            key = "length" if lv in (1, 10, 11) and not self._lathe else "radius"
            fields[key + ("_wear" if wear else "")] = self._dim(blk, "R")
        if self._lathe:
            for letter, key in (("X", "x"), ("Z", "z"), ("U", "x"), ("W", "z")):
                if letter in words:
                    val = self._dim(blk, letter) * (0.5 if letter in "XU" and self._diam else 1.0)
                    fields[key + ("_wear" if wear else "")] = val
                    if letter in "UW":
                        added.add(key + ("_wear" if wear else ""))
        if not self._abs:
            added.update(fields)
        md = self._md
        if md is not None:
            cur = md.tools.get(p)
            new = {}
            for k, v in fields.items():
                base = getattr(cur, k) if cur is not None else 0.0
                new[k] = base + v if k in added else v
            if lv == 1:  # memory A: one value per number, no separate wear
                new.update({k: 0.0 for k in ("length_wear", "radius_wear") if k not in new})
            if "Q" in words:
                new["tip"] = self._int_word(blk, "Q")
            try:
                entry = md.update_tool(p, **new)
            except ValueError as e:
                raise self._err(f"G10 L{lv} P{p}: {e}", blk, "P") from None
            self._tools[p] = entry.offset()
            return
        # no machine data (a bare check): geometry and wear share the effective value
        cur_off = self._tools.get(p, ToolOffset())
        vals = {"length": cur_off.length, "radius": cur_off.radius, "x": cur_off.x, "z": cur_off.z}
        for k, v in fields.items():
            base_key = k.removesuffix("_wear")
            vals[base_key] = vals[base_key] + v if k in added else v
        self._tools[p] = ToolOffset(vals["length"], vals["radius"], vals["x"], vals["z"])

    def _coordinate_set(self, blk: Block) -> None:
        words = blk.words
        if "S" in words:
            # G50 S / G92 S: the CSS speed limit, never above the spindle's own
            mx = self.params.max_spindle_rpm
            self._max_rpm = words["S"] if mx is None else min(words["S"], mx)
        named = [letter for letter in "XYZ" if letter in words]
        if self._rot is not None:
            self._rot.set_g92(blk, self)
        if not named:
            return
        if self._xf_on:
            raise self._err("G92 while mirror/scaling/rotation is active", blk, "G")
        w = self._wofs[self._wcs]
        c = self._wofs[0]
        t = self._tlo
        g92 = list(self._g92)
        for letter in named:
            i = _AXIS_OF[letter]
            val = self._dim(blk, letter) * (0.5 if letter == "X" and self._diam else 1.0)
            g92[i] = self._mach[i] - w[i] - c[i] - t[i] - val
        if self._md is not None:
            try:
                self._md.set_g92(g92)  # the shift outlives the program, as on a control
            except ValueError as e:
                raise self._err(f"G92 shift {e}", blk, "G") from None
        self._g92 = g92
        self._refresh_offsets(resync=True)

    # --- subprograms and macros ------------------------------------------------------

    def _open(self, number: int, blk: Block, letter: str, what: str):
        opened = self._lib.open(number)
        if opened is None:
            raise MacroAlarm(
                PS_PROGRAM_NOT_FOUND,
                f"{what}: program O{number} not found",
                blk.line,
                blk.col(letter),
                self._frames[-1].file,
            )
        return opened

    def _nesting(self, blk: Block) -> None:
        limit = self._call_nesting
        if len(self._frames) > limit:
            raise MacroAlarm(
                PS_NESTING,
                f"subprogram nesting deeper than {limit} levels (recursion?)",
                blk.line,
                blk.col("M") if blk.m else blk.col("G"),
                self._frames[-1].file,
            )

    def _call(self, blk: Block) -> None:
        words = blk.words
        cur = self._frames[-1]
        if "P" not in words:
            if "Q" not in words:
                raise self._err("M98 needs P (program number) or Q (sequence number)", blk, "M")
            # M98 Q: call a part of the current program, from sequence number Q
            self._nesting(blk)
            q = self._int_word(blk, "Q")
            fr = _Frame(iter(()), cur.file, cur.number, 1, blk.line, cur.src, cur.start)
            line = self._find_seq(fr, q, 0, blk, PS_SEQUENCE_NOT_FOUND, "M98 Q", "Q")
            self._frames.append(fr)
            self._jump(fr, line, blk)
            return
        p = self._int_word(blk, "P")
        if p > MAX_PROGRAM_NUMBER or p < 1:
            raise self._err(f"M98 P{p}: program number outside 1..{MAX_PROGRAM_NUMBER}", blk, "P")
        if "L" in words:
            reps = self._int_word(blk, "L")
            number = p
        elif p >= 10000 and self._lib.open(p) is None:
            # Fanuc's 4-digit format M98 Pxxxxnnnn: repeats xxxx, program Onnnn. An O number
            # of 5 to 8 digits that exists is called as such (8-digit option: repeats by L).
            reps, number = p // 10000, p % 10000
        else:
            reps, number = 1, p
        if reps > MAX_REPEAT:
            raise self._err(f"M98 repeat count above {MAX_REPEAT}", blk, "L")
        if reps == 0:
            return
        self._nesting(blk)
        it, file, src, start = self._open(number, blk, "P", "M98")
        fr = _Frame(it, file, number, reps, blk.line, src, start)
        if "Q" in words:
            q = self._int_word(blk, "Q")
            line = self._find_seq(fr, q, 0, blk, PS_SEQUENCE_NOT_FOUND, "M98 Q", "Q")
            self._frames.append(fr)
            self._jump(fr, line, blk)
            return
        self._frames.append(fr)
        self._switch = True

    def _return(self, blk: Block) -> None:
        words = blk.words
        fr = self._frames[-1]
        if len(self._frames) == 1:
            if "P" in words:  # M99 P in the main program: jump to the sequence number
                p = self._int_word(blk, "P")
                line = self._find_seq(fr, p, blk.line, blk, PS_SEQUENCE_NOT_FOUND, "M99 P", "P")
                self._jump(fr, line, blk)
                return
            if self.subprogram or (self.subprogram is None and self._rest_is_empty(fr, blk)):
                self._ended = self._switch = True  # a subprogram on its own: it ends here
                return
            raise self._err(
                "M99 in the main program would repeat it for ever (no caller to return to)",
                blk,
                "M",
            )
        self._frames.pop()
        self._switch = True
        if fr.macro:
            self.vars.pop()
        if fr.repeats > 1:
            opened = self._lib.open(fr.number)  # type: ignore[arg-type]
            assert opened is not None
            nf = _Frame(opened[0], opened[1], fr.number, fr.repeats - 1, fr.call_line,
                        opened[2], opened[3])  # fmt: skip
            if fr.macro:
                nf.macro, nf.modal_call, nf.args = True, fr.modal_call, fr.args
                self.vars.push(fr.args or {})
            self._frames.append(nf)
            return
        if "P" in words:
            p = self._int_word(blk, "P")
            caller = self._frames[-1]
            line = self._find_seq(caller, p, fr.call_line, blk, PS_SEQUENCE_NOT_FOUND, "M99 P", "P")
            self._jump(caller, line, blk)

    def _rest_is_empty(self, fr: _Frame, blk: Block) -> bool:
        """Whether nothing but blanks, comments and '%' follow `blk` in the main program."""
        seq = self._lines_of(fr)
        if seq is None:
            return False
        for i in range(blk.line, len(seq)):
            text = _COMMENT.sub("", seq[i]).strip()
            if not text or text.startswith("%"):
                continue
            return bool(_O_AT.match(text))  # the next program of the file starts
        return True

    def _macro_call(self, blk: Block, row) -> None:
        """G65 (call now) and G66 (call after every move until G67), with arguments.

        Other G codes before it in the block (`G54 G65 P...`) and M codes before it take
        effect first, as a block of their own; every word is an argument of the call.
        """
        words = blk.words
        at = blk.g.index(row.number)
        if len(blk.g) > at + 1:
            raise MacroAlarm(
                "PS0129",
                f"G{fmt_g(blk.g[at + 1])[1:]} after {row.name} (G is not a macro argument)",
                blk.line,
                blk.col("G", at + 2),
                self._frames[-1].file,
            )
        others = blk.g[:at]
        if others or blk.m:
            self._block(Block(blk.line, blk.text, {}, others, list(blk.m)), self._frames[-1])
        if "N" in words:
            self._nword = int(words["N"])
        if "P" not in words:
            raise self._err(f"{row.name} needs P (program number)", blk, "G")
        number = self._int_word(blk, "P")
        reps = self._int_word(blk, "L") if "L" in words else 1
        if reps > MAX_REPEAT:
            raise self._err(f"{row.name} repeat count above {MAX_REPEAT}", blk, "L")
        try:
            args = arguments(words, blk.col("G"))
        except MacroAlarm as err:
            err.line, err.file = blk.line, self._frames[-1].file
            raise
        if row.name == "G66":
            self._lib_check(number, blk)
            self._g66 = (number, args, reps)
            self._update_simple()
            return
        if reps:
            self._push_macro(number, args, reps, blk)

    def _lib_check(self, number: int, blk: Block) -> None:
        self._open(number, blk, "P", "G66")

    def _push_macro(
        self, number: int, args: dict[int, float], reps: int, blk: Block, modal_call: bool = False
    ) -> None:
        if self.vars.depth >= self._macro_nesting:
            raise MacroAlarm(
                PS_MACRO_NESTING,
                f"macro calls nested deeper than {self._macro_nesting} levels (recursion?)",
                blk.line,
                blk.col("G"),
                self._frames[-1].file,
            )
        self._nesting(blk)
        it, file, src, start = self._open(number, blk, "P", "G66" if modal_call else "G65")
        fr = _Frame(it, file, number, reps, blk.line, src, start)
        fr.macro, fr.modal_call, fr.args = True, modal_call, args
        self.vars.push(args)
        self._frames.append(fr)
        self._switch = True

    def _macro_modal_cancel(self) -> None:
        self._g66 = None
        self._update_simple()

    # --- macro statements -------------------------------------------------------------

    def _macro(self, mb: MacroBlock, fr: _Frame) -> Block | None:
        """Execute a macro statement; a words block comes back as the plain Block it means."""
        self._line = mb.line
        if mb.seq is not None:
            self._nword = mb.seq
        kind = mb.kind
        env = self.vars
        try:
            if kind == WORDS:
                return build_block(mb, env, fr.file, self._li)
            self._executed += 1
            if self.max_blocks is not None and self._executed > self.max_blocks:
                raise MacroAlarm("", f"program executes more than {self.max_blocks} blocks")
            self._mrun += 1
            if self._mrun > self.macro_budget:
                raise MacroAlarm(
                    "",
                    f"endless loop? {self.macro_budget} macro statements in a row without "
                    "a move or any other command (macro budget)",
                )
            args = mb.args
            if kind == ASSIGN:
                self._assign(args, mb, fr)
            elif kind == IF_GOTO:
                if args[0](env):
                    self._goto(fr, args[1](env), mb)
            elif kind == IF_THEN:
                if args[0](env):
                    self._assign(args[1], mb, fr)
            elif kind == WHILE:
                self._while(fr, mb, bool(args[0](env)), args[1])
            elif kind == DO:
                self._while(fr, mb, True, args[0])
            elif kind == END:
                self._end(fr, mb, args[0])
            elif kind == GOTO:
                self._goto(fr, args[0](env), mb)
        except MacroAlarm as err:
            if err.line == 0:
                err.line = mb.line
                err.col = err.col or mb.col0
            if err.file == "<program>":
                err.file = fr.file
            raise
        return None

    def _assign(self, assigns, mb: MacroBlock, fr: _Frame) -> None:
        env = self.vars
        for target, expr, col in assigns:
            n = target if type(target) is int else target(env)
            v = expr(env)
            if n == 3000:
                number = alarm_number(v, col)
                raise MacroAlarm(str(number), f"macro alarm: {mb.comment or '(no message)'}",
                                 mb.line, col, fr.file)  # fmt: skip
            if n == 3006:
                self.messages.append((mb.line, mb.comment))
                self._emit(ProgramStop(mb.line, StopKind.PROGRAM_STOP))
                continue
            env.set(n, v, col)

    def _lines_of(self, fr: _Frame) -> list[str] | None:
        src = fr.src
        if src is None or not isinstance(src, str):
            return src
        lines = self._loaded.get(src)
        if lines is None:
            with open(src, encoding="latin-1", newline=None) as fh:
                lines = fh.read().split("\n")
            self._loaded[src] = lines
        return lines

    def _jump(self, fr: _Frame, line: int, blk: Block) -> None:
        """Go on in frame `fr` at `line` (1-based; past the end: the program's end)."""
        seq = self._lines_of(fr)
        if seq is None:
            raise MacroAlarm(
                PS_DNC_JUMP,
                "GOTO, WHILE/END and M99 P need the program in memory or in a file "
                "(a streamed program cannot jump back)",
                blk.line,
                1,
                fr.file,
            )
        fr.it = ((i + 1, seq[i]) for i in range(line - 1, len(seq)))
        self._switch = True
        if line <= blk.line:
            self._jumps += 1
            if self._jumps > LOOP_WATCH_AFTER:
                self._watch_loop(fr, line, blk)

    def _watch_loop(self, fr: _Frame, line: int, blk: Block) -> None:
        """A loop that comes back to a line with everything as it was the time before can
        never end (the interpreter is deterministic): an alarm now, not after the budget.

        Compared: the variables (local, common, kept, signals), the positions, the modes
        and offsets that decide what the next blocks do. Checked only once a program has
        jumped back LOOP_WATCH_AFTER times, so short loops pay nothing.
        """
        env = self.vars
        clock = env.clock() if env.clock is not None else None
        state = (
            len(self._frames),
            tuple(env.loc.items()),
            tuple(env.common.items()),
            tuple(env.persistent.items()),
            tuple(env.signals.items()),
            clock,
            self._pos,
            self._mach,
            self._off,
            self._motion,
            self._cycle,
            self._abs,
            self._inch,
            self._wcs,
            self._tool,
            self._f,
            self._s,
        )
        key = (id(fr), line)
        if self._loop_seen.get(key) == state:
            raise MacroAlarm(
                "",
                f"endless loop: the jump back to line {line} finds every variable, "
                "position and mode as the time before, so the program can never end",
                blk.line,
                getattr(blk, "col0", 1),
                fr.file,
            )
        if len(self._loop_seen) > 1000:
            self._loop_seen.clear()
        self._loop_seen[key] = state

    def _seq_index(self, fr: _Frame, seq: list[str]) -> dict[int, list[int]]:
        """Sequence number -> lines of the frame's program (from its first line to its end)."""
        key = (id(seq), fr.start)
        idx = self._nindex.get(key)
        if idx is None:
            idx = {}
            header = body = False
            for i in range(fr.start - 1, len(seq)):
                text = seq[i]
                if _O_AT.match(text):
                    if header or body:
                        break
                    header = True
                    continue
                stripped = text.strip()
                if stripped.startswith("%"):
                    if body:
                        break
                    continue
                if stripped:
                    body = True
                m = _N_AT.match(text)
                if m:
                    idx.setdefault(int(m.group(1)), []).append(i + 1)
            self._nindex[key] = idx
        return idx

    def _find_seq(
        self, fr: _Frame, n, cur: int, blk: Block, alarm: str, what: str, letter: str
    ) -> int:
        """The line of sequence number `n` in the frame's program: the first after `cur`,
        else the first from the program's start (Fanuc searches on, then from the top)."""
        col = blk.col(letter) if letter else getattr(blk, "col0", 1)
        if n is None or n != int(n) or not 1 <= n <= 99999:
            shown = "vacant" if n is None else f"{n:g}"
            raise MacroAlarm(alarm, f"{what} {shown}: not a sequence number 1..99999",
                             blk.line, col, fr.file)  # fmt: skip
        seq = self._lines_of(fr)
        if seq is None:
            raise MacroAlarm(
                PS_DNC_JUMP,
                f"{what}: a streamed program cannot search sequence numbers",
                blk.line,
                col,
                fr.file,
            )
        lines = self._seq_index(fr, seq).get(int(n))
        if not lines:
            raise MacroAlarm(alarm, f"{what} {int(n)}: sequence number N{int(n)} not found",
                             blk.line, col, fr.file)  # fmt: skip
        for ln in lines:
            if ln > cur:
                return ln
        return lines[0]

    def _goto(self, fr: _Frame, n, mb: MacroBlock) -> None:
        line = self._find_seq(fr, n, mb.line, mb, PS_GOTO_NOT_FOUND, "GOTO", "")
        # loops left by the jump: started after the target, or ended before it
        loops = fr.loops
        while loops:
            ident, start, end = loops[-1]
            if start <= line and line <= (end or self._find_end(fr, ident, start) or line):
                break  # the target is inside this loop: it stays open
            loops.pop()
        self._jump(fr, line, mb)

    def _while(self, fr: _Frame, mb: MacroBlock, true: bool, ident: int) -> None:
        loops = fr.loops
        if not (loops and loops[-1][0] == ident and loops[-1][1] == mb.line):
            for rec in loops:
                if rec[0] == ident:
                    raise MacroAlarm(
                        PS_LOOP_NUMBER,
                        f"DO {ident} inside the open loop DO {ident} of line {rec[1]} "
                        "(nested loops need different numbers 1..3)",
                        mb.line, mb.col0, fr.file,
                    )  # fmt: skip
            if len(loops) >= MAX_LOOPS:
                raise MacroAlarm(
                    PS_LOOP_NUMBER,
                    f"DO {ident}: loops nested deeper than {MAX_LOOPS}",
                    mb.line,
                    mb.col0,
                    fr.file,
                )
            loops.append([ident, mb.line, 0])
        if true:
            return
        rec = loops.pop()
        end = rec[2] or self._find_end(fr, ident, mb.line)
        if end is None:
            raise MacroAlarm(
                PS_MISSING_END, f"WHILE ... DO {ident} without END {ident}", mb.line, mb.col0,
                fr.file,
            )  # fmt: skip
        if fr.src is None:
            return  # streamed: _find_end consumed the lines up to the END
        self._jump(fr, end + 1, mb)

    def _find_end(self, fr: _Frame, ident: int, line: int) -> int | None:
        seq = self._lines_of(fr)
        if seq is None:
            for lineno, text in fr.it:  # a stream: skip forward (no way back needed)
                m = _END_OF.search(_COMMENT.sub("", text).upper())
                if m and int(m.group(1)) == ident:
                    return lineno
            return None
        key = (id(seq), line, ident)
        if key in self._ends:
            return self._ends[key]
        found = None
        for i in range(line, len(seq)):
            text = seq[i]
            if _O_AT.match(text):
                break
            m = _END_OF.search(_COMMENT.sub("", text).upper())
            if m and int(m.group(1)) == ident:
                found = i + 1
                break
        self._ends[key] = found
        return found

    def _end(self, fr: _Frame, mb: MacroBlock, ident: int) -> None:
        loops = fr.loops
        if not loops or loops[-1][0] != ident:
            inner = f" (loop DO {loops[-1][0]} is still open)" if loops else ""
            raise MacroAlarm(
                PS_LOOP_NUMBER, f"END {ident} without a matching DO {ident}{inner}", mb.line,
                mb.col0, fr.file,
            )  # fmt: skip
        rec = loops[-1]
        rec[2] = mb.line
        self._jump(fr, rec[1], mb)


CHECK_MAX_ERRORS = 1000


def check(
    lines: Iterable[str] | str,
    params: MachineParams,
    *,
    file: str = "<program>",
    programs: Mapping[int, str | Iterable[str]] | None = None,
    tools: Mapping[int, ToolOffset] | None = None,
    work_offsets: Mapping[int, tuple[float, ...]] | None = None,
    max_blocks: int = 5_000_000,
    block_delete: bool = False,
    machine_data: MachineData | None = None,
    macro_variables: MutableMapping[int, float] | None = None,
    macro_budget: int = MACRO_BUDGET,
    subprogram: bool | None = None,
    rotary_named: set[str] | None = None,
) -> list[NcError]:
    """Interpret a whole program and return ALL its errors (at most CHECK_MAX_ERRORS).

    After an error the checker carries on with the next block, with the modal state as the
    failed block left it. Nothing is kept of the canonical commands. `rotary_named`, if
    given, receives the rotary axes (A, B, C) the program's blocks move or set (a macro
    call's argument A is none), its called programs' included.
    """
    interp = Interpreter(
        params,
        programs=programs,
        tools=tools,
        file=file,
        work_offsets=work_offsets,
        max_blocks=max_blocks,
        block_delete=block_delete,
        machine_data=machine_data,
        macro_variables=macro_variables,
        macro_budget=macro_budget,
        subprogram=subprogram,
    )
    errors = interp.check_all(lines)
    if rotary_named is not None:
        rotary_named.update(interp.rotary_named)
    return errors
