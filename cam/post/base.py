"""The Fanuc-dialect post-processor core shared by every machine kind.

Rules (seed 004 §6 and candidate requirements C13-C15):
* `%` tape, `O<n> (PARTNO text)`; the O number from the option, else the digits ending the
  PARTNO text, else 1.
* The unit in its own block before any motion: `G20` unless `UNITS/MM` (then `G21`), with
  the kind's modal defaults (mill `G90 G94`). UNITS after motion is refused.
* `RAPID` makes the next motion only `G00`; later motions are `G01` at the current FEDRAT.
* `FEDRAT/f[,IPM|IPR|MMPM|MMPR]` -> `F` on the next cutting block (per minute or per rev).
* `LOADTL/n` -> `T<n> M06` (lathe: `T<nn><nn>`), `SPINDL/n,CLW|CCLW` -> `S<n> M03|M04`,
  `SPINDL/OFF` -> `M05`, `COOLNT/ON|FLOOD` -> `M08`, `MIST` -> `M07`, `OFF` -> `M09`,
  `CUTCOM/LEFT|RIGHT|OFF` -> `G41|G42|G40` on the next motion, `DELAY/s` -> `G04 X<s>`,
  `STOP` -> `M00`, `OPSTOP` -> `M01`, `END` -> `M02`, `FINI` -> `M30` and `%`.
* Coordinates are modal: a block carries only the words that change.

A post is a generator over CL records (memory flat in the program's length) yielding
`NcBlock`s that remember the CL line they came from, so a later check of the NC program
can point back into the CL data.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

from cam.cl import ClRecord
from cam.errors import CamError, CamWarning

POST_VERSION = "1.0"
SINGULAR_LIST_MAX = 1000  # summary lists stay bounded: memory flat in the program's length
WARNINGS_MAX = 1000
INCH = 25.4


@dataclass(frozen=True, slots=True)
class NcBlock:
    text: str
    cl_line: int = 0


@dataclass(slots=True)
class PostOptions:
    tolerance_mm: float | None = None  # T, mm (None: the machine's, else 0.01)
    program_number: int | None = None
    merge: bool = False  # merge collinear blocks within T
    max_depth: int | None = None  # linearisation: bisections of one segment (None: the machine's)
    trace: list | None = None  # 5-axis: (CL pose, joints) of every point sent (tests, tools)


@dataclass(slots=True)
class PostSummary:
    blocks_in: int = 0  # CL records read
    blocks_out: int = 0  # NC blocks written (without the `%` lines)
    points_inserted: int = 0  # by linearisation
    blocks_merged: int = 0  # CL points dropped by merging collinear blocks
    arc_points: int = 0  # 5-axis: CL arcs cut into chords within T (points added)
    peak_deviation: float = 0.0  # largest tool-tip midpoint deviation left, program units
    singular: list[int] = field(default_factory=list)  # CL lines of singular orientations
    singular_count: int = 0  # all of them (the list keeps the first SINGULAR_LIST_MAX)
    warnings: list[CamWarning] = field(default_factory=list)
    units: str = "INCHES"

    def as_dict(self) -> dict:
        mm = INCH if self.units == "INCHES" else 1.0
        return {
            "blocks_in": self.blocks_in,
            "blocks_out": self.blocks_out,
            "points_inserted": self.points_inserted,
            "blocks_merged": self.blocks_merged,
            "arc_points": self.arc_points,
            "peak_midpoint_deviation_mm": round(self.peak_deviation * mm, 9),
            "singular_records": list(self.singular),
            "singular_count": self.singular_count,
            "units": "mm" if self.units == "MM" else "inch",
            "warnings": [str(w) for w in self.warnings],
        }


def fmt(v: float, decimals: int) -> str:
    """Fanuc style: `2.` for whole numbers, trailing zeros dropped, never `-0.`."""
    s = f"{v:.{decimals}f}".rstrip("0")
    if s in ("-0.", "-."):
        return "0."
    return s


MERGE_RUN_MAX = 1000  # CL points merged into one block at most (bounded memory)


def _collinear(
    a: tuple[float, ...], b: tuple[float, ...], pts: list[tuple[float, ...]], tol: float
) -> bool:
    """Every point of `pts` within tol of the segment a-b, in order along it, with the tool
    axis of a (and of b) unchanged."""
    if any(abs(p - q) > 1e-9 for p, q in zip(a[3:], b[3:], strict=False)):
        return False
    dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    L2 = dx * dx + dy * dy + dz * dz
    if L2 == 0:
        return False
    last = 0.0
    for p in pts:
        if any(abs(u - v) > 1e-9 for u, v in zip(p[3:], a[3:], strict=False)):
            return False
        t = ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy + (p[2] - a[2]) * dz) / L2
        if t < last or t > 1:
            return False
        last = t
        ex, ey, ez = a[0] + t * dx - p[0], a[1] + t * dy - p[1], a[2] + t * dz - p[2]
        if ex * ex + ey * ey + ez * ez > tol * tol:
            return False
    return True


_DIGITS_END = re.compile(r"(\d{1,8})\s*$")


class FanucPost:
    """The 3-axis mill post; the lathe and 5-axis posts derive from it."""

    kind = "mill"
    name = "fanuc-mill"
    version = POST_VERSION
    axes: tuple[str, ...] = ("X", "Y", "Z")
    header_feed_mode: bool | None = False  # the unit block sets G94 (feed per minute)

    def __init__(self, machine, options: PostOptions | None = None, file: str = "<cl>") -> None:
        self.machine = machine
        self.opt = options or PostOptions()
        self.file = file
        self.summary = PostSummary()
        self.units = "INCHES"
        self.partno: str | None = None
        self.header_done = False
        self.moved = False
        self.rapid_next = False
        self.feed: float | None = None
        self.feed_per_rev = False
        self.feed_out: tuple[float, bool] | None = None  # what the NC has (F, per rev)
        self.feed_mode_out: bool | None = None
        self.motion_out: str | None = None  # G00 / G01 modal in the NC
        self.pending_g: list[str] = []
        self.last: dict[str, float] = {}  # axis words the NC has, program units
        self.pos: tuple[float, ...] | None = None  # CL tool tip (and axis)
        self.tool_axis = (0.0, 0.0, 1.0)
        self.arc: ClRecord | None = None
        self.plane_out: str | None = None
        self.spindle_speed: float | None = None
        self.spindle_dir = "M03"
        self.last_text = ""
        self.tool: int | None = None
        self.ended = False
        self.anchor: tuple[float, ...] | None = None  # the CL pose of the last block sent
        self.held: tuple[tuple[float, ...], ClRecord] | None = None
        self.merge_run: list[tuple[float, ...]] = []

    # --- plumbing ---------------------------------------------------------------------------

    def err(self, msg: str, rec: ClRecord | None) -> CamError:
        return CamError(msg, rec.line if rec else 0, 1, self.file)

    def warn(self, msg: str, rec: ClRecord | None) -> None:
        if len(self.summary.warnings) >= WARNINGS_MAX:
            return
        self.summary.warnings.append(CamWarning(msg, rec.line if rec else 0, 1, self.file))

    @property
    def decimals(self) -> int:
        return 4 if self.units == "INCHES" else 3

    def unit_block(self) -> str:
        return ("G20" if self.units == "INCHES" else "G21") + " G90 G94"

    def header(self, rec: ClRecord | None) -> Iterator[NcBlock]:
        if self.header_done:
            return
        self.header_done = True
        number = self.opt.program_number
        if number is None and self.partno:
            m = _DIGITS_END.search(self.partno)
            number = int(m.group(1)) if m and int(m.group(1)) > 0 else None
        number = number or 1
        if not 1 <= number <= 99_999_999:
            raise self.err(f"program number O{number} out of range (1 ... 99999999)", rec)
        comment = ""
        if self.partno:
            text = re.sub(r"[()%]", "", self.partno).strip()
            comment = f" ({text})" if text else ""
        yield NcBlock("%", 0)
        yield NcBlock(f"O{number:04d}{comment}", rec.line if rec else 0)
        yield NcBlock(self.unit_block(), rec.line if rec else 0)
        self.feed_mode_out = self.header_feed_mode

    def block(self, text: str, rec: ClRecord | None) -> Iterator[NcBlock]:
        if self.ended:
            raise self.err("output after the end of the program (FINI or END)", rec)
        yield from self.header(rec)
        self.summary.blocks_out += 1
        self.last_text = text
        yield NcBlock(text, rec.line if rec else 0)

    # --- the record loop ---------------------------------------------------------------------

    def run(self, records: Iterable[ClRecord]) -> Iterator[NcBlock]:
        handlers: dict = {}
        for rec in records:
            self.summary.blocks_in += 1
            if self.arc is not None and rec.word != "GOTO":
                raise self.err(
                    f"CIRCLE (line {self.arc.line}) must be followed by the GOTO that ends the arc",
                    rec,
                )
            handler = handlers.get(rec.word)
            if handler is None:
                handler = handlers[rec.word] = getattr(self, "do_" + rec.word, None)
            if handler is None:
                raise self.err(f"the {self.name} post cannot execute CL word {rec.word}", rec)
            yield from handler(rec)
        yield from self.flush(None)
        if not self.ended and self.header_done:
            self.ended = True
            yield NcBlock("%", 0)
        self.summary.units = self.units

    # --- post-processor words ------------------------------------------------------------------

    def do_PARTNO(self, rec: ClRecord) -> Iterator[NcBlock]:
        if self.header_done:
            self.warn("PARTNO after the program start: ignored", rec)
        else:
            self.partno = rec.text or ""
        return iter(())

    def do_PPRINT(self, rec: ClRecord) -> Iterator[NcBlock]:
        text = re.sub(r"[()%]", "", rec.text or "").strip()
        yield from self.flush(rec)
        if text:
            yield from self.block(f"({text})", rec)

    def do_INSERT(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        if rec.text:
            yield from self.block(rec.text, rec)

    def _noop(self, rec: ClRecord) -> Iterator[NcBlock]:
        return iter(())

    do_REMARK = _noop
    do_MACHIN = _noop  # the machine is chosen by the dispatch, not by the CL data
    do_CUTTER = _noop  # the NC uses its own tool table
    do_INDIRV = _noop
    do_INTOL = _noop
    do_OUTTOL = _noop

    def do_UNITS(self, rec: ClRecord) -> Iterator[NcBlock]:
        u = rec.words[0] if rec.words else ""
        if u not in ("MM", "INCHES"):
            raise self.err("UNITS/MM or UNITS/INCHES", rec)
        if u == self.units:
            return
        if self.moved:
            raise self.err(
                "UNITS changed after motion (the unit goes in its own block before any motion)", rec
            )
        self.units = u
        if self.header_done:
            yield from self.block("G21" if u == "MM" else "G20", rec)

    def do_MULTAX(self, rec: ClRecord) -> Iterator[NcBlock]:
        return iter(())

    def do_TLAXIS(self, rec: ClRecord) -> Iterator[NcBlock]:
        vec = tuple(float(v) for v in rec.numbers[:3])
        self.check_axis(vec, rec)
        self.tool_axis = vec  # type: ignore[assignment]
        return iter(())

    def check_axis(self, vec: tuple[float, ...], rec: ClRecord) -> None:
        if abs(vec[0]) > 1e-6 or abs(vec[1]) > 1e-6 or vec[2] < 0:
            raise self.err(
                f"5-axis CL data (tool axis {vec[0]:.6g}, {vec[1]:.6g}, {vec[2]:.6g}) cannot be"
                f" posted to a 3-axis machine (kind {self.kind}): it can only hold the tool along +Z",
                rec,
            )

    def do_LOADTL(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        n = rec.numbers
        if not n or n[0] < 0 or n[0] != int(n[0]):
            raise self.err("LOADTL needs a tool number", rec)
        self.tool = int(n[0])
        yield from self.block(self.tool_change(self.tool, rec), rec)

    do_TURRET = do_LOADTL

    def tool_change(self, tool: int, rec: ClRecord) -> str:
        return f"T{tool} M06"

    def do_SPINDL(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        words, nums = rec.words, rec.numbers
        if "OFF" in words:
            yield from self.block("M05", rec)
            return
        if "CCLW" in words:
            self.spindle_dir = "M04"
        elif "CLW" in words:
            self.spindle_dir = "M03"
        if any(w in ("SFM", "SMM") for w in words):
            raise self.err(f"the {self.name} post takes spindle speeds in RPM only", rec)
        if nums:
            if not nums[0] > 0:
                raise self.err("SPINDL needs a speed > 0", rec)
            self.spindle_speed = nums[0]
        if self.spindle_speed is None:
            raise self.err("SPINDL/ON with no speed programmed before", rec)
        sp = self.spindle_speed
        speed = str(int(sp)) if sp == int(sp) else fmt(sp, 1)
        yield from self.block(f"{self.speed_prefix()}S{speed} {self.spindle_dir}", rec)

    def speed_prefix(self) -> str:
        return ""

    def do_COOLNT(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        w = rec.words[0] if rec.words else ""
        code = {"ON": "M08", "FLOOD": "M08", "MIST": "M07", "OFF": "M09"}.get(w)
        if code is None:
            raise self.err(f"COOLNT/{w}: not ON, FLOOD, MIST or OFF", rec)
        yield from self.block(code, rec)

    def do_CUTCOM(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        w = rec.words[0] if rec.words else ""
        if w == "OFF":
            self.pending_g = ["G40"]
        elif w in ("LEFT", "RIGHT"):
            g = "G41" if w == "LEFT" else "G42"
            self.pending_g = [g + self.comp_register(rec)]
        else:
            raise self.err("CUTCOM/LEFT, RIGHT or OFF", rec)

    def comp_register(self, rec: ClRecord) -> str:
        n = rec.numbers
        d = int(n[0]) if n else self.tool
        if d is None:
            raise self.err("CUTCOM needs a radius register (CUTCOM/LEFT,n) or a LOADTL before", rec)
        return f" D{d}"

    def do_FEDRAT(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        n, w = rec.numbers, rec.words
        if not n or not n[0] > 0:
            raise self.err("FEDRAT needs a feed rate > 0", rec)
        mode = w[0] if w else ("MMPM" if self.units == "MM" else "IPM")
        if (
            mode in ("IPM", "IPR")
            and self.units == "MM"
            or mode in ("MMPM", "MMPR")
            and self.units == "INCHES"
        ):
            raise self.err(f"FEDRAT/{mode} does not match the program's unit ({self.units})", rec)
        self.feed = n[0]
        self.feed_per_rev = mode in ("IPR", "MMPR")
        return

    def do_RAPID(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        self.rapid_next = True

    def do_DELAY(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        n = rec.numbers
        if not n or n[0] < 0:
            raise self.err("DELAY needs seconds >= 0", rec)
        yield from self.block(f"G04 X{fmt(n[0], 3)}", rec)

    def do_STOP(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        yield from self.block("M00", rec)

    def do_OPSTOP(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        yield from self.block("M01", rec)

    def do_END(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        yield from self.block("M02", rec)

    def do_FINI(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        if self.last_text not in ("M02", "M30"):
            yield from self.block("M30", rec)
        self.ended = True
        yield NcBlock("%", 0)

    # --- motion --------------------------------------------------------------------------------

    def cl_pose(self, rec: ClRecord) -> tuple[float, ...]:
        v = rec.args  # GOTO and FROM hold numbers only (the reader and processor see to it)
        n = len(v)
        if n == 6:
            return v  # type: ignore[return-value]
        if n > 6:
            return v[:6]  # type: ignore[return-value]
        return (*v[:3], *self.tool_axis)  # type: ignore[misc]

    def do_FROM(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        pose = self.cl_pose(rec)
        self.check_axis(pose[3:], rec)
        self.pos = pose
        return

    def do_CIRCLE(self, rec: ClRecord) -> Iterator[NcBlock]:
        yield from self.flush(rec)
        self.arc = rec
        return

    def feed_words(self, rec: ClRecord) -> str:
        """`F` (and the feed mode) when the NC does not have them yet."""
        if self.feed is None:
            raise self.err("a cutting move without a feed rate (FEDRAT before it)", rec)
        words = ""
        if self.feed_mode_out != self.feed_per_rev:
            words += " " + self.feed_mode_code(self.feed_per_rev)
            self.feed_mode_out = self.feed_per_rev
        if self.feed_out != (self.feed, self.feed_per_rev):
            dec = 4 if self.feed_per_rev else (1 if self.units == "INCHES" else 0)
            words += " F" + fmt(self.feed, max(dec, 1))
            self.feed_out = (self.feed, self.feed_per_rev)
        return words

    def feed_mode_code(self, per_rev: bool) -> str:
        return "G95" if per_rev else "G94"

    def axis_words(self, target: dict[str, float], decimals: dict[str, int] | None = None) -> str:
        out = []
        for a, v in target.items():
            dec = decimals.get(a, self.decimals) if decimals else self.decimals
            s = fmt(v, dec)
            if self.last.get(a) != s:
                out.append(a + s)
                self.last[a] = s  # type: ignore[assignment]
        return " ".join(out)

    def machine_target(self, pose: tuple[float, ...], rec: ClRecord) -> dict[str, float]:
        self.check_axis(pose[3:], rec)
        return {"X": pose[0], "Y": pose[1], "Z": pose[2]}

    def motion_text(self, words: str, rec: ClRecord, rapid: bool) -> str:
        """The text of a motion block (after the header): pending G words, G00/G01 when it
        changes, the axis words, the feed when it changes."""
        g = "G00" if rapid else "G01"
        parts = self.pending_g
        if parts:
            self.pending_g = []
        else:
            parts = []
        if self.motion_out != g:
            parts.append(g)
            self.motion_out = g
        parts.append(words)
        feed = "" if rapid else self.feed_words(rec)
        return " ".join(parts) + feed

    def motion_block(self, words: str, rec: ClRecord, rapid: bool) -> Iterator[NcBlock]:
        if not words:
            return  # already there: nothing to move (a pending RAPID is used up all the same)
        yield from self.header(rec)  # before the feed words: the header sets the feed mode
        yield from self.block(self.motion_text(words, rec, rapid), rec)

    def do_GOTO(self, rec: ClRecord) -> Iterator[NcBlock]:
        pose = self.cl_pose(rec)
        rapid = self.rapid_next
        self.rapid_next = False
        if self.arc is not None:
            arc, self.arc = self.arc, None
            yield from self.flush(rec)
            yield from self.arc_move(arc, pose, rec)
            self.anchor = pose
        elif rapid or not self.opt.merge or self.anchor is None:
            if self.held is not None:
                yield from self.flush(rec)
            yield from self.emit_linear(pose, rec, rapid)
            self.anchor = pose
        else:
            yield from self.merge(pose, rec)
        self.pos = pose
        self.moved = True

    # --- merging collinear blocks (seed 002 §2.3) -------------------------------------------------

    def merge(self, pose: tuple[float, ...], rec: ClRecord) -> Iterator[NcBlock]:
        """Hold a cutting move back while the moves since the last block stay on one straight
        line within T with the same tool axis; emit the held move when the line breaks."""
        if self.held is not None:
            run = [*self.merge_run, self.held[0]]
            if len(run) < MERGE_RUN_MAX and _collinear(self.anchor, pose, run, self.merge_tol()):
                self.merge_run = run
                self.held = (pose, rec)
                self.summary.blocks_merged += 1
                return
            yield from self.flush(rec)
        self.held = (pose, rec)
        self.merge_run = []

    def merge_tol(self) -> float:
        t = self.opt.tolerance_mm if self.opt.tolerance_mm is not None else 0.01
        return t / INCH if self.units == "INCHES" else t

    def flush(self, rec: ClRecord | None) -> Iterator[NcBlock]:
        """Emit the move held back by merging (any record other than a cutting move ends a
        run)."""
        if self.held is None:
            return
        pose, hrec = self.held
        self.held = None
        self.merge_run = []
        yield from self.emit_linear(pose, hrec, False)
        self.anchor = pose

    def emit_linear(self, pose: tuple[float, ...], rec: ClRecord, rapid: bool) -> Iterator[NcBlock]:
        words = self.axis_words(self.machine_target(pose, rec))
        yield from self.motion_block(words, rec, rapid)

    def arc_plane(
        self, axis: tuple[float, float, float], rec: ClRecord
    ) -> tuple[str, str, str, int, int, int]:
        """(plane code, first axis, second axis, index u, index v, index w) and the sign."""
        i, j, k = axis
        if abs(abs(k) - 1) < 1e-6:
            return ("G17", "I", "J", 0, 1, 2)
        if abs(abs(j) - 1) < 1e-6:
            return ("G18", "I", "K", 0, 2, 1)
        if abs(abs(i) - 1) < 1e-6:
            return ("G19", "J", "K", 1, 2, 0)
        raise self.err(f"CIRCLE axis ({i:.6g}, {j:.6g}, {k:.6g}) is not along X, Y or Z", rec)

    def arc_move(self, arc: ClRecord, pose: tuple[float, ...], rec: ClRecord) -> Iterator[NcBlock]:
        if self.pos is None:
            raise self.err("an arc needs a known start (a GOTO or FROM before the CIRCLE)", arc)
        c = arc.numbers
        centre, axis, r = c[0:3], c[3:6], c[6]
        plane, wa, wb, u, v, w = self.arc_plane(axis, arc)  # type: ignore[arg-type]
        start, end = self.pos, pose
        ra = math.hypot(start[u] - centre[u], start[v] - centre[v])
        rb = math.hypot(end[u] - centre[u], end[v] - centre[v])
        tol = 1e-4 * (1 + abs(r)) + (0.0002 if self.units == "INCHES" else 0.005)
        if abs(ra - r) > tol or abs(rb - r) > tol:
            raise self.err(
                f"arc end points are not on the circle of radius {r:.6g} (start {ra:.6g}, end {rb:.6g})",
                rec,
            )
        sign = axis[w]
        # counter-clockwise about +axis; G18's ZX plane: counter-clockwise about +Y is G03
        g = "G03" if sign > 0 else "G02"
        target = self.machine_target(pose, rec)
        words = self.axis_words(target)
        names = self.axes
        if not words:  # a full circle: the end words must be there
            words = " ".join(n + self.last[n] for n in names if n in target)  # type: ignore[operator]
        off_u = centre[u] - start[u]
        off_v = centre[v] - start[v]
        ij = f"{wa}{fmt(self.arc_scale(wa) * off_u, self.decimals)} {wb}{fmt(off_v, self.decimals)}"
        yield from self.header(rec)
        parts = list(self.pending_g)
        self.pending_g = []
        if self.plane_out != plane:
            parts.append(plane)
            self.plane_out = plane
        parts += [g, words, ij]
        self.motion_out = g
        yield from self.block(" ".join(parts) + self.feed_words(rec), rec)

    def arc_scale(self, word: str) -> float:
        return 1.0
