"""The declared G and M code table: one row per code, read by the interpreter and the docs.

Each row names the code, its modal group, the machine kinds that have it, the words it uses,
the words it needs, the step of the block's order of execution at which its handler runs,
and the handler (a function of a small family module taking the interpreter context and the
block being executed). The interpreter classifies a block's codes through this table (an
unknown code, a declared-but-refused code, two codes of one group), checks its words (a word
no code of the block uses is an error) and runs the handlers in `Step` order.

Adding a code is one row here and one handler in its family module; docs/gcode.md's code
tables are rendered from this table (`render_g_table`, `render_m_table`, `render_order`) and
a test keeps them equal.

G numbers are int(10 x value) throughout (G1 -> 10, G54.1 -> 541), as the lexer gives them.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from cnc.interp import (
    auxiliary,
    circle_pocket,
    compensation,
    engraving,
    flow,
    modes,
    motion,
    offsets,
    skip,
)
from cnc.interp import lathe_cycles as lc
from cnc.interp import transform_codes as xf
from cnc.interp.context import Step

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

__all__ = ["CODES", "Code", "Step", "for_kind", "fmt_g", "render_g_table", "render_m_table"]

Handler = Callable[["Context", "BlockRun"], None]


_STEP_TEXT = {
    Step.EXACT_STOP: "G9",
    Step.UNITS: "G20/G21 (they decide how the block's numbers are read)",
    Step.FEED_MODE: "feed mode (G94/G95, lathe G98/G99)",
    Step.FEED: "F",
    Step.SPINDLE_MODE: "G96/G97",
    Step.SPEED: "S",
    Step.TOOL_SELECT: "T",
    Step.TOOL_CHANGE: "M6",
    Step.SPINDLE: "M3/M4/M5/M19",
    Step.COOLANT: "M7/M8/M9",
    Step.AUX: "other M codes",
    Step.DWELL: "G4",
    Step.PLANE: "plane",
    Step.CUTTER_COMP: "cutter compensation (or D alone)",
    Step.LENGTH_COMP: "length compensation (or H alone)",
    Step.COORDINATE_SYSTEM: "coordinate system select",
    Step.PATH_CONTROL: "path control",
    Step.DISTANCE: "distance mode",
    Step.RETRACT: "retract mode",
    Step.POLAR: "G15/G16",
    Step.MIRROR: "G50.1/G51.1",
    Step.SCALING: "G50/G51",
    Step.ROTATION: "G68/G69",
    Step.NON_MODAL: "G10/G28/G30/G31/G53/G92",
    Step.MOTION: "motion (or the modal motion/cycle)",
    Step.STOP: "M0/M1/M2/M30",
    Step.SUBPROGRAM: "M98/M99, G65/G66/G67",
}

# Modal groups: table name -> Fanuc group number (for the docs; "" where Fanuc has none).
GROUPS = {
    "nonmodal": "00",
    "skip": "00",
    "motion": "01",
    "plane": "02",
    "distance": "03",
    "feed_mode": "05",
    "units": "06",
    "cutter_comp": "07",
    "length_comp": "08",
    "cycle": "09",
    "return_level": "10",
    "scaling": "11",
    "spindle_mode": "13",
    "work_offset": "14",
    "path_mode": "15",
    "lookahead": "",
    "accuracy": "",
    "rotation": "16",
    "polar": "17",
    "mirror": "22",
    "arc_distance": "",
    "macro_call": "00",
    "macro_modal": "12",
    "exact_stop": "00",
    "refused": "",
    "stop": "",
    "spindle": "",
    "tool": "",
    "coolant": "",
    "sub": "",
}

MILL = frozenset({"mill"})
LATHE = frozenset({"lathe"})
BOTH = MILL | LATHE
# Words of every block, whatever its codes: N sequence, F feed, S speed, T tool, and D / H
# (an offset number alone selects it for the next G41/G42 / G43/G44, or applies it at once
# when that compensation is on).
BLOCK_WORDS = frozenset("NFSTDH")
_AXES = {"mill": "XYZ", "lathe": "XZUW"}  # "@" in a row's words
_CENTRE = {"mill": "IJK", "lathe": "IK"}  # "%" in a row's words


@dataclass(frozen=True, slots=True)
class Code:
    """One G or M code.

    `words`: letters the code uses ("@" = the machine's axis words, "%" = its arc centre
    words); `needs`: each entry a set of alternatives, one of which the block must give;
    `owns_axes`: its axis words are not a motion target (G4, G10, G28, G92, transforms...);
    `default`: the group's power-on code; `refused`: the message of a code the interpreter
    knows and refuses (Macro B, lathe cycles), with `handler` None.
    """

    name: str
    group: str
    kinds: frozenset[str]
    step: Step
    handler: Handler | None
    words: str = ""
    needs: tuple[str, ...] = ()
    owns_axes: bool = False
    default: bool = False
    doc: str = ""
    refused: str = ""

    @property
    def letter(self) -> str:
        return self.name[0]

    @property
    def number(self) -> int:
        """The lexer's number: int(10 x G value) for G codes, the value for M codes."""
        if self.letter == "M":
            return int(self.name[1:])
        whole, _, frac = self.name[1:].partition(".")
        return int(whole) * 10 + (int(frac) if frac else 0)

    def words_for(self, kind: str) -> frozenset[str]:
        return frozenset(self.words.replace("@", _AXES[kind]).replace("%", _CENTRE[kind]))

    def needs_for(self, kind: str) -> tuple[str, ...]:
        letters = _AXES[kind] + _CENTRE[kind] + "FSTDHNPQRLE"
        return tuple("".join(c for c in alt if c in letters) for alt in self.needs)


def _g(name, group, step, handler, kinds=BOTH, **kw) -> Code:
    return Code(name, group, kinds, step, handler, **kw)


def _refused(name: str, kinds: frozenset[str], message: str) -> Code:
    return Code(name, "refused", kinds, Step.MOTION, None, refused=message, doc=message)


_MACRO_ARGS = "PLABCDEFHIJKMQRSTUVWXYZ"  # G65/G66: P L and the arguments (specification I)
_CYCLE_WORDS = "@RQPKL"

# fmt: off
CODES: tuple[Code, ...] = (
    # --- motion (01) ---
    _g("G0", "motion", Step.MOTION, motion.motion, words="@", default=True, doc="rapid"),
    _g("G1", "motion", Step.MOTION, motion.motion, words="@", doc="linear feed"),
    _g("G2", "motion", Step.MOTION, motion.motion, words="@%RP",
       doc="arc CW seen from the plane normal's + side: I/J/K centre or R radius; P turns"),
    _g("G3", "motion", Step.MOTION, motion.motion, words="@%RP", doc="arc CCW (as G2)"),
    # --- non-modal (00) ---
    _g("G4", "nonmodal", Step.DWELL, flow.dwell, words="PXU", needs=("PXU",), owns_axes=True,
       doc="dwell: P milliseconds, X (lathe also U) seconds"),
    _g("G9", "exact_stop", Step.EXACT_STOP, motion.exact_stop, doc="exact stop for this block's moves"),
    _g("G10", "nonmodal", Step.NON_MODAL, offsets.data_setting, words="LPRQXYZUW",
       needs=("P",), owns_axes=True,
       doc="data setting into the machine data: L2 P (G54-G59) / L20 P (G54.1 P1-P48) work"
           " offsets, L1/L10-L13 tool length and radius geometry/wear; lathe G10 P X Z R Q"),
    _g("G12", "nonmodal", Step.NON_MODAL, circle_pocket.circle_pocket, MILL, words="XYZIKQLD",
       needs=("I",), owns_axes=True,
       doc="circular pocket CW (Haas): I radius [K finished radius, Q step], L loops, Z"
           " depth (G91: per loop), D tool offset, X Y centre; lead-in/out half circles"),
    _g("G13", "nonmodal", Step.NON_MODAL, circle_pocket.circle_pocket, MILL, words="XYZIKQLD",
       needs=("I",), owns_axes=True, doc="circular pocket CCW (as G12)"),
    _g("G28", "nonmodal", Step.NON_MODAL, offsets.reference_return, words="@", owns_axes=True,
       doc="return to the reference point via the intermediate point"),
    _g("G30", "nonmodal", Step.NON_MODAL, offsets.reference_return, words="@P", owns_axes=True,
       doc="return to the second reference point (P2)"),
    _g("G31", "skip", Step.NON_MODAL, skip.skip_move, words="@P", needs=("XYZUW",),
       owns_axes=True,
       doc="skip: linear feed that stops at the skip signal (the tool setter, probe.tool_setter);"
           " skip position in #5061.. (work coordinates); P1..P4 multi-step skip; with G53:"
           " machine coordinates"),
    _g("G53", "nonmodal", Step.NON_MODAL, offsets.machine_move, words="@", owns_axes=True,
       doc="G0/G1 move in machine coordinates"),
    _g("G92", "nonmodal", Step.NON_MODAL, offsets.coordinate_set, MILL, words="XYZS",
       owns_axes=True, doc="coordinate system setting; S: maximum spindle speed for G96"),
    _g("G47", "nonmodal", Step.NON_MODAL, engraving.engrave, MILL, words="XYZPRIJE",
       needs=("P", "Z"), owns_axes=True,
       doc="text engraving (Haas): P0 the comment's text, P1 serial number #599, P32..126 one"
           " character; X Y start, Z depth, R return plane, I angle, J height, E plunge feed"),
    _g("G50", "nonmodal", Step.NON_MODAL, offsets.coordinate_set, LATHE, words="XZS",
       owns_axes=True, doc="coordinate system setting; S: maximum spindle speed for G96"),
    # --- plane (02) ---
    _g("G17", "plane", Step.PLANE, modes.plane, doc="XY plane (mill default)"),
    _g("G18", "plane", Step.PLANE, modes.plane, doc="ZX plane (lathe default)"),
    _g("G19", "plane", Step.PLANE, modes.plane, doc="YZ plane"),
    # --- distance (03) ---
    _g("G90", "distance", Step.DISTANCE, modes.distance, MILL, default=True, doc="absolute"),
    _g("G91", "distance", Step.DISTANCE, modes.distance, MILL, doc="incremental"),
    _g("G90.1", "arc_distance", Step.DISTANCE, modes.arc_distance, doc="absolute arc centres"),
    _g("G91.1", "arc_distance", Step.DISTANCE, modes.arc_distance, default=True,
       doc="arc centres incremental from the start"),
    # --- feed mode (05) ---
    _g("G94", "feed_mode", Step.FEED_MODE, modes.feed_mode, MILL, default=True, doc="feed per minute"),
    _g("G95", "feed_mode", Step.FEED_MODE, modes.feed_mode, MILL, doc="feed per revolution"),
    _g("G98", "feed_mode", Step.FEED_MODE, modes.feed_mode, LATHE, doc="feed per minute"),
    _g("G99", "feed_mode", Step.FEED_MODE, modes.feed_mode, LATHE, default=True,
       doc="feed per revolution"),
    # --- units (06) ---
    _g("G20", "units", Step.UNITS, modes.units, doc="inch"),
    _g("G21", "units", Step.UNITS, modes.units, default=True, doc="mm"),
    # --- cutter compensation (07) ---
    _g("G40", "cutter_comp", Step.CUTTER_COMP, compensation.cutter_comp, default=True,
       doc="cutter compensation cancel (with the next in-plane move)"),
    _g("G41", "cutter_comp", Step.CUTTER_COMP, compensation.cutter_comp, words="D",
       doc="cutter compensation left, radius of offset D"),
    _g("G42", "cutter_comp", Step.CUTTER_COMP, compensation.cutter_comp, words="D",
       doc="cutter compensation right"),
    # --- length compensation (08) ---
    _g("G43", "length_comp", Step.LENGTH_COMP, compensation.length_comp, words="H",
       doc="tool length compensation +, offset H"),
    _g("G44", "length_comp", Step.LENGTH_COMP, compensation.length_comp, words="H",
       doc="tool length compensation -"),
    _g("G49", "length_comp", Step.LENGTH_COMP, compensation.length_comp, default=True,
       doc="tool length compensation cancel"),
    # --- canned cycles (09) ---
    _g("G73", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="high-speed peck drilling"),
    _g("G74", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="left-hand tapping"),
    _g("G76", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="fine boring"),
    _g("G80", "cycle", Step.MOTION, motion.motion, default=True,
       doc="canned cycle cancel (lathe: also G32/G90/G92/G94; a no-op in a safe-start line)"),
    _g("G81", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="drilling"),
    _g("G82", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="spot drilling, dwell"),
    _g("G83", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="peck drilling"),
    _g("G84", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="tapping"),
    _g("G85", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="boring, feed out"),
    _g("G86", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="boring, spindle stop"),
    _g("G87", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="back boring"),
    _g("G88", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="boring, manual retract"),
    _g("G89", "cycle", Step.MOTION, motion.motion, MILL, words=_CYCLE_WORDS, doc="boring, dwell, feed out"),
    # --- return level (10) ---
    _g("G98", "return_level", Step.RETRACT, modes.return_level, MILL, default=True,
       doc="cycles return to the initial level"),
    _g("G99", "return_level", Step.RETRACT, modes.return_level, MILL, doc="cycles return to R"),
    # --- scaling (11), mirror (22), rotation (16), polar (17) ---
    _g("G50", "scaling", Step.SCALING, xf.scaling, MILL, owns_axes=True, default=True,
       doc="scaling cancel"),
    _g("G51", "scaling", Step.SCALING, xf.scaling, MILL, words="XYZPIJK", owns_axes=True,
       doc="scaling: X Y Z centre, P factor or I J K per axis"),
    _g("G50.1", "mirror", Step.MIRROR, xf.mirror, MILL, words="XYZ", owns_axes=True,
       default=True, doc="mirror cancel (the named axes, or all)"),
    _g("G51.1", "mirror", Step.MIRROR, xf.mirror, MILL, words="XYZ", owns_axes=True,
       doc="mirror about the given axis positions"),
    _g("G68", "rotation", Step.ROTATION, xf.rotation, MILL, words="XYZR", owns_axes=True,
       doc="rotation in the plane: centre, R degrees"),
    _g("G69", "rotation", Step.ROTATION, xf.rotation, MILL, owns_axes=True, default=True,
       doc="rotation cancel"),
    _g("G15", "polar", Step.POLAR, xf.polar, MILL, default=True, doc="polar coordinates off"),
    _g("G16", "polar", Step.POLAR, xf.polar, MILL,
       doc="polar coordinates: first plane axis radius, second angle"),
    # --- spindle mode (13) ---
    _g("G96", "spindle_mode", Step.SPINDLE_MODE, modes.spindle_mode,
       doc="constant surface speed, S in m/min; rpm clamped by G50 S / G92 S and the"
           " spindle's max_rpm"),
    _g("G97", "spindle_mode", Step.SPINDLE_MODE, modes.spindle_mode, default=True, doc="S in rpm"),
    # --- work offsets (14) ---
    *(
        _g(f"G{n}", "work_offset", Step.COORDINATE_SYSTEM, offsets.select_work_offset,
           default=n == 54, doc=f"work offset {n - 53}")
        for n in range(54, 60)
    ),
    _g("G54.1", "work_offset", Step.COORDINATE_SYSTEM, offsets.select_work_offset, words="P",
       needs=("P",), doc="extended work offset P1..P48"),
    # --- path mode (15) ---
    _g("G61", "path_mode", Step.PATH_CONTROL, modes.path_mode, doc="exact stop mode"),
    _g("G64", "path_mode", Step.PATH_CONTROL, modes.path_mode, words="P", default=True,
       doc="continuous path, P tolerance"),
    _g("G103", "lookahead", Step.PATH_CONTROL, modes.lookahead_limit, MILL, words="P",
       default=True,
       doc="look-ahead limit (Haas): plan at most P (1..15) blocks ahead; P0 or no P: the"
           " machine's look-ahead"),
    _g("G187", "accuracy", Step.PATH_CONTROL, modes.accuracy, MILL, words="PE", default=True,
       doc="accuracy (Haas): path tolerance E, or P1 rough (4 x default), P2 medium,"
           " P3 finish (default / 4); alone: the machine's default tolerance"),
    # --- declared and refused ---
    # --- Macro B calls (docs/gcode.md "Fanuc Macro B") ---
    _g("G65", "macro_call", Step.SUBPROGRAM, flow.macro_call, words=_MACRO_ARGS, needs=("P",),
       doc="macro call: program P, L times, arguments A..Z -> #1..#26 (a new local level)"),
    _g("G66", "macro_modal", Step.SUBPROGRAM, flow.macro_call, words=_MACRO_ARGS, needs=("P",),
       doc="modal macro call: program P is called after every block that moves"),
    _g("G67", "macro_modal", Step.SUBPROGRAM, flow.macro_modal_cancel, default=True,
       doc="modal macro call cancel"),
    # --- lathe cycles (Fanuc T, G-code system A; cnc.interp.lathe_cycles) ---
    _g("G70", "nonmodal", Step.NON_MODAL, lc.finishing, LATHE, words="PQUW", owns_axes=True,
       doc="finishing: the contour N P..N Q as programmed, then back to the start"),
    _g("G71", "nonmodal", Step.NON_MODAL, lc.stock_removal, LATHE, words="PQUWR",
       owns_axes=True,
       doc="stock removal in turning: U depth R retract; P Q U W F (D depth, R1 type II)"),
    _g("G72", "nonmodal", Step.NON_MODAL, lc.stock_removal, LATHE, words="PQUWR",
       owns_axes=True, doc="stock removal in facing: W depth R retract; P Q U W F (D depth)"),
    _g("G73", "nonmodal", Step.NON_MODAL, lc.pattern_repeating, LATHE, words="PQUWRIK",
       owns_axes=True, doc="pattern repeating: U W R divisions; P Q U W F (Haas I K D)"),
    _g("G74", "nonmodal", Step.NON_MODAL, lc.grooving, LATHE, words="@PQRIK", owns_axes=True,
       doc="face grooving / peck drilling: R retract; X Z P Q R F (Haas I K)"),
    _g("G75", "nonmodal", Step.NON_MODAL, lc.grooving, LATHE, words="@PQRIK", owns_axes=True,
       doc="OD grooving: R retract; X Z P Q R F (Haas I K)"),
    _g("G76", "nonmodal", Step.NON_MODAL, lc.multi_threading, LATHE, words="@PQRIKA",
       owns_axes=True,
       doc="multi-pass threading: P mmrraa Q R; X Z R P Q F (Haas X Z K D I A P F)"),
    _g("G32", "cycle", Step.MOTION, motion.motion, LATHE, words="@",
       doc="thread cutting, F lead; spindle-synchronised feed (modal)"),
    _g("G90", "cycle", Step.MOTION, motion.motion, LATHE, words="@R",
       doc="turning cycle (modal): X Z R taper F"),
    _g("G92", "cycle", Step.MOTION, motion.motion, LATHE, words="@R",
       doc="threading cycle (modal): X Z R taper F lead"),
    _g("G94", "cycle", Step.MOTION, motion.motion, LATHE, words="@R",
       doc="facing cycle (modal): X Z R taper F"),
    # --- M codes ---
    _g("M0", "stop", Step.STOP, flow.stop, doc="program stop"),
    _g("M1", "stop", Step.STOP, flow.stop, doc="optional stop (per the machine's switch)"),
    _g("M2", "stop", Step.STOP, flow.stop, doc="program end"),
    _g("M30", "stop", Step.STOP, flow.stop, doc="program end and rewind"),
    _g("M3", "spindle", Step.SPINDLE, auxiliary.spindle, doc="spindle CW"),
    _g("M4", "spindle", Step.SPINDLE, auxiliary.spindle, doc="spindle CCW"),
    _g("M5", "spindle", Step.SPINDLE, auxiliary.spindle, doc="spindle stop"),
    _g("M19", "spindle", Step.SPINDLE, auxiliary.spindle, doc="spindle orient"),
    _g("M6", "tool", Step.TOOL_CHANGE, auxiliary.tool_change, doc="tool change to the selected T"),
    _g("M7", "coolant", Step.COOLANT, auxiliary.coolant, doc="mist coolant on (may share a block with M8)"),
    _g("M8", "coolant", Step.COOLANT, auxiliary.coolant, doc="flood coolant on"),
    _g("M9", "coolant", Step.COOLANT, auxiliary.coolant, doc="coolant off"),
    _g("M98", "sub", Step.SUBPROGRAM, flow.call, words="PLQ", needs=("PQ",),
       doc="call program P, L times (or `P<rrrr><nnnn>`); Q: from sequence number Q "
           "(without P: of the current program)"),
    _g("M99", "sub", Step.SUBPROGRAM, flow.return_, words="P",
       doc="return to the caller; P: to the caller's sequence number P"),
)
# fmt: on

# Block steps that are not codes: a word's own step, the spindle re-issue and the modal
# motion run whether or not a code of their group is in the block (each handler decides).
WORD_STEPS: tuple[tuple[str, Step, Handler], ...] = (
    ("F", Step.FEED, modes.feed_word),
    ("S", Step.SPEED, modes.speed_word),
    ("T", Step.TOOL_SELECT, auxiliary.tool_word),
    ("D", Step.CUTTER_COMP, compensation.d_word),
    ("H", Step.LENGTH_COMP, compensation.h_word),
)
AUX_STEP: tuple[Step, Handler] = (Step.AUX, auxiliary.aux_functions)
ALWAYS_STEPS: tuple[tuple[Step, Handler], ...] = (
    (Step.SPINDLE, auxiliary.spindle_speed_change),
    (Step.MOTION, motion.motion),
)


def table(letter: str, kind: str) -> dict[int, Code]:
    """The codes a machine kind has, by the lexer's number ("G" or "M")."""
    out: dict[int, Code] = {}
    for row in CODES:
        if row.letter == letter and kind in row.kinds:
            assert row.number not in out, f"two {kind} rows for {row.name}"
            out[row.number] = row
    return out


# Fanuc T G-code systems B and C: number -> the row (by its system A name, or a mill row's
# name for the codes system A's lathe does not have) it stands for. A number not listed
# keeps its system A row; `None` removes it.
_LATHE_B = {
    "G50": None,  # coordinate setting is G92
    "G90": "mill:G90",  # absolute
    "G91": "mill:G91",  # incremental
    "G92": "lathe:G50",  # coordinate system setting, S maximum spindle speed
    "G33": "lathe:G32",  # thread cutting
    "G94": "mill:G94",  # feed per minute
    "G95": "mill:G95",  # feed per revolution
    "G98": "mill:G98",  # return to the initial level
    "G99": "mill:G99",  # return to the R level
    "G77": "lathe:G90",  # turning cycle
    "G78": "lathe:G92",  # threading cycle
    "G79": "lathe:G94",  # facing cycle
}
_LATHE_C = {
    **_LATHE_B,
    "G79": None,
    "G20": "lathe:G90",  # turning cycle
    "G21": "lathe:G92",  # threading cycle
    "G24": "lathe:G94",  # facing cycle
    "G70": "lathe:G20",  # inch
    "G71": "lathe:G21",  # mm
    "G72": "lathe:G70",  # finishing
    "G73": "lathe:G71",  # stock removal in turning
    "G74": "lathe:G72",  # stock removal in facing
    "G75": "lathe:G73",  # pattern repeating
    "G76": "lathe:G74",  # face grooving / peck drilling
    "G77": "lathe:G75",  # OD grooving
    "G78": "lathe:G76",  # multi-pass threading
}
GCODE_SYSTEMS = {"A": {}, "B": _LATHE_B, "C": _LATHE_C}


def _number(name: str) -> int:
    whole, _, frac = name[1:].partition(".")
    return int(whole) * 10 + (int(frac) if frac else 0)


def _renamed(kind: str, system: str) -> dict[int, Code]:
    """The lathe's G table under G-code system B or C (rows keep their system A names)."""
    base = table("G", kind)
    if kind != "lathe" or system == "A":
        return base
    tables = {"lathe": base, "mill": table("G", "mill")}
    out = dict(base)
    renames = GCODE_SYSTEMS[system]
    for name in renames:
        out.pop(_number(name), None)
    for name, target in renames.items():
        if target is not None:
            src, _, row = target.partition(":")
            out[_number(name)] = tables[src][_number(row)]
    return out


class KindTable:
    """The table as one machine kind reads it, resolved once (`for_kind`)."""

    __slots__ = ("g", "m", "g_words", "m_words", "g_needs", "m_needs")

    def __init__(self, kind: str, system: str = "A") -> None:
        if system not in GCODE_SYSTEMS:
            raise ValueError(f"G-code system {system!r} is not A, B or C")
        self.g = _renamed(kind, system)
        self.m = table("M", kind)
        self.g_words = {n: row.words_for(kind) for n, row in self.g.items()}
        self.m_words = {n: row.words_for(kind) for n, row in self.m.items()}
        self.g_needs = {n: row.needs_for(kind) for n, row in self.g.items() if row.needs}
        self.m_needs = {n: row.needs_for(kind) for n, row in self.m.items() if row.needs}


@functools.cache
def for_kind(kind: str, system: str = "A") -> KindTable:
    """The table of a machine kind; a lathe reads it in G-code system `system` (A, B, C)."""
    return KindTable(kind, system)


def fmt_g(code: int) -> str:
    """G code text from the lexer's number: 10 -> "G1", 541 -> "G54.1"."""
    return f"G{code // 10}" if code % 10 == 0 else f"G{code // 10}.{code % 10}"


# --- docs ---------------------------------------------------------------------------------


def _kinds_text(kinds: frozenset[str]) -> str:
    return "mill, lathe" if kinds == BOTH else next(iter(kinds))


def _group_text(group: str) -> str:
    num = GROUPS.get(group, "")
    name = group.replace("_", " ")
    return f"{name} ({num})" if num else name


def _words_text(row: Code) -> str:
    if row.refused:
        return ""
    kinds = sorted(row.kinds)
    texts = {" ".join(sorted(row.words_for(k), key=_word_order)) for k in kinds}
    if len(texts) == 1:
        return texts.pop()
    return "; ".join(f"{k}: {' '.join(sorted(row.words_for(k), key=_word_order))}" for k in kinds)


def _word_order(letter: str) -> tuple[int, str]:
    """Axes, centres, then the other words; letters outside that list (macro arguments)
    first, alphabetically (a frozenset's order is not stable between runs)."""
    return ("XYZUVWIJKRPQLDHS".find(letter), letter)


def _needs_text(row: Code) -> str:
    kinds = sorted(row.kinds)
    texts = {" and ".join(_alternatives(a) for a in row.needs_for(k)) for k in kinds}
    if len(texts) == 1:
        return texts.pop()
    return "; ".join(
        f"{k}: {' and '.join(_alternatives(a) for a in row.needs_for(k))}" for k in kinds
    )


def _alternatives(alt: str) -> str:
    """ "PX" -> "P or X", "PXU" -> "P, X or U" (also the interpreter's error wording)."""
    return " or ".join(alt) if len(alt) <= 2 else f"{', '.join(alt[:-1])} or {alt[-1]}"


def _sort_key(row: Code) -> tuple:
    return (row.number, sorted(row.kinds))


def render_g_table() -> str:
    """The G code table of docs/gcode.md (markdown), one line per row of CODES."""
    lines = [
        "| Code | Group | Machines | Words | Needs | Meaning |",
        "|---|---|---|---|---|---|",
    ]
    for row in sorted((r for r in CODES if r.letter == "G"), key=_sort_key):
        name = f"**{row.name}**" if row.default else row.name
        group = "refused" if row.refused else _group_text(row.group)
        lines.append(
            f"| {name} | {group} | {_kinds_text(row.kinds)} | {_words_text(row)} "
            f"| {_needs_text(row)} | {row.doc} |"
        )
    return "\n".join(lines) + "\n"


def render_m_table() -> str:
    """The M code table of docs/gcode.md (markdown)."""
    lines = ["| Code | Group | Words | Needs | Meaning |", "|---|---|---|---|---|"]
    for row in sorted((r for r in CODES if r.letter == "M"), key=_sort_key):
        lines.append(
            f"| {row.name} | {row.group} | {_words_text(row)} | {_needs_text(row)} | {row.doc} |"
        )
    lines.append(
        "| any other | | | | `AuxFunction(code)`, handed to the PLC with wait-for-finish; "
        "a word beside it is refused (no code uses it) |"
    )
    return "\n".join(lines) + "\n"


def render_order() -> str:
    """The order of execution within a block, as one markdown paragraph."""
    steps = ", ".join(_STEP_TEXT[s] for s in Step)
    return f"Order of execution within a block: {steps}.\n"
