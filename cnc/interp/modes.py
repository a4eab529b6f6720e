"""Modal settings: units, feed mode, F, spindle mode, S, plane, distance, path control.

Code handlers of cnc.interp.codes: `handler(ip, run)` with the interpreter context `ip`
(cnc.interp.context.Context) and the block in execution `run`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.canon import PathMode, SetPathMode
from cnc.interp.gnum import G61, G90, G90_1, G95, G96, G99

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

INCH = 25.4
MAX_LOOKAHEAD_LIMIT = 15  # G103 P0..P15 (Haas)
# G187 P1 rough / P2 medium / P3 finish without E: the path tolerance as a multiple of the
# machine's default (default_path_tolerance, Haas setting 85); E gives it outright
ACCURACY_FACTORS = {1: 4.0, 2: 1.0, 3: 0.25}


def units(ip: Context, run: BlockRun) -> None:
    ip.units_programmed = True  # `nc check` warns about programs that never say G20/G21
    inch = run.rows["units"].name == "G20"  # lathe system C writes it G70
    if inch != ip._inch:
        if ip._moved:
            raise ip._err(
                "G20/G21 unit change after motion (use one unit per program)",
                run.blk,
                "G",
                run.gcol["units"],
            )
        ip._inch = inch
        ip._scale = INCH if inch else 1.0


def feed_mode(ip: Context, run: BlockRun) -> None:
    ip._per_rev = run.g["feed_mode"] in (G95, G99)  # lathe G99: per revolution


def feed_word(ip: Context, run: BlockRun) -> None:
    ip._set_feed(run.blk, run.words["F"])


def _s_is_speed(run: BlockRun) -> bool:
    """Whether the block's S is the spindle speed: with G92 S / lathe G50 S it is the
    maximum spindle speed, set by that code."""
    if "S" not in run.words:
        return False
    nonmodal = run.rows.get("nonmodal")
    return nonmodal is None or "S" not in nonmodal.words


def spindle_mode(ip: Context, run: BlockRun) -> None:
    css = run.g["spindle_mode"] == G96
    if css != ip._css:
        ip._css = css
        run.spindle_changed = True
        if not css and not _s_is_speed(run):
            ip._s = ip._rpm_now_from(ip._s, True)  # G97 keeps the speed turning now


def speed_word(ip: Context, run: BlockRun) -> None:
    if not _s_is_speed(run):
        return  # G92 S / lathe G50 S: the clamp's word
    s = run.words["S"]
    if s < 0:
        raise ip._err("S must not be negative", run.blk, "S")
    ip._s = s * (0.3048 if ip._inch and ip._css else 1.0)  # G96 in inch: ft/min -> m/min
    run.spindle_changed = True


def plane(ip: Context, run: BlockRun) -> None:
    code = run.g["plane"]
    if code == ip._plane:
        return
    # the refusals point at the plane's own G word (`G0 X1 G19`: the G19)
    nth = run.gcol["plane"]
    if ip._comp_engaged():
        raise ip._err("plane change while cutter compensation is active", run.blk, "G", nth)
    if ip._xf.rot:
        raise ip._err("plane change while G68 rotation is active", run.blk, "G", nth)
    ip._set_plane(code)


def distance(ip: Context, run: BlockRun) -> None:
    g = run.g
    d = g.get("distance")
    if d is not None:
        ip._abs = d == G90


def arc_distance(ip: Context, run: BlockRun) -> None:
    ip._arc_abs = run.g["arc_distance"] == G90_1


def return_level(ip: Context, run: BlockRun) -> None:
    ip._retract = run.g["return_level"]


def path_mode(ip: Context, run: BlockRun) -> None:
    code = run.g["path_mode"]
    ip._path = code
    if code == G61:
        _emit_path_control(ip, run)
        return
    tol = ip.params.default_path_tolerance
    if "P" in run.words:
        tol = ip._dim(run.blk, "P")
        if tol < 0:
            raise ip._err("G64 P tolerance must not be negative", run.blk, "P")
    ip._tol = tol
    _emit_path_control(ip, run)


def accuracy(ip: Context, run: BlockRun) -> None:
    """Haas G187 [P1 rough | P2 medium | P3 finish] [E tolerance]: the path tolerance of the
    blocks that follow (G64 corner blending within it); G187 alone: the machine's default."""
    blk = run.blk
    tol = ip.params.default_path_tolerance
    if "P" in run.words:
        p = run.words["P"]
        if p not in ACCURACY_FACTORS:
            raise ip._err("G187 P must be 1 (rough), 2 (medium) or 3 (finish)", blk, "P")
        tol *= ACCURACY_FACTORS[int(p)]
    if "E" in run.words:
        tol = ip._dim(blk, "E")
        if tol <= 0.0:
            raise ip._err("G187 E (corner rounding tolerance) must be > 0", blk, "E")
    ip._tol = tol
    _emit_path_control(ip, run)


def lookahead_limit(ip: Context, run: BlockRun) -> None:
    """Haas G103 P0..P15: plan at most P blocks ahead (P0 or no P: the machine's look-ahead)."""
    n = 0
    if "P" in run.words:
        p = run.words["P"]
        if p != int(p) or not 0 <= p <= MAX_LOOKAHEAD_LIMIT:
            raise ip._err(
                f"G103 P (blocks of look-ahead) must be 0..{MAX_LOOKAHEAD_LIMIT}", run.blk, "P"
            )
        n = int(p)
    ip._lookahead = n
    _emit_path_control(ip, run)


def _emit_path_control(ip: Context, run: BlockRun) -> None:
    if ip._path == G61:
        ip._emit(SetPathMode(run.line, PathMode.EXACT_STOP, 0.0, ip._lookahead))
    else:
        ip._emit(SetPathMode(run.line, PathMode.CONTINUOUS, ip._tol, ip._lookahead))
