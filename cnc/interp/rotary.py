"""Rotary axis words (A, B, C) for the machines that configure rotary axes (mill4, mill5).

A rotary word is an angle in degrees. It is read absolute (G90) or incremental (G91), with
the decimal-point rule of the machine (least-increment style: A90 = 0.090 deg), never
scaled by G20/G21 and never touched by the work-offset transforms (G68 rotation, G51
scaling, G51.1 mirror, G16 polar act on X Y Z only). The work offsets and G92 do get a
rotary component: program angle = machine angle - (work offset + EXT + G92), each
rotary component 0 unless set (`G92 A0` makes the current table angle program zero).

The interpreter keeps its X Y Z world; this object holds the rotary part of the machine
position and stamps it onto every motion command of a block (canonical poses are X Y Z
followed by the rotary axes in configured order, `MachineParams.pose_axes`). A rotary
word moves the table with the block's G0/G1 (with or without X Y Z), its G53 or its G28/
G30; the rotary axes are limited by their soft limits unless configured continuous.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from cnc.canon import ArcFeed, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.params import MachineParams

if TYPE_CHECKING:
    from cnc.gcode.lexer import Block

ROTARY_LIMIT_SLACK = 1e-9  # degrees, as the linear axes' check


class RotaryAxes:
    """The rotary axes of one interpreter: machine angles, offsets and limits."""

    __slots__ = ("names", "letters", "index", "mach", "g92", "wofs", "lo", "hi", "home")

    def __init__(
        self,
        params: MachineParams,
        start: tuple[float, ...] | None,
        work_offsets: dict[int, tuple[float, ...]] | None,
        n_wofs: int,
    ) -> None:
        axes = params.rotary_axes
        self.names = tuple(a.name for a in axes)
        self.letters = frozenset(self.names)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.home = [a.home_mm for a in axes]
        n = len(axes)
        if start is not None and len(start) >= 3 + n:
            self.mach = [float(v) for v in start[3 : 3 + n]]
        else:
            self.mach = list(self.home)
        self.lo = [(-float("inf") if a.continuous else a.min_mm) for a in axes]
        self.hi = [(float("inf") if a.continuous else a.max_mm) for a in axes]
        self.g92 = [0.0] * n
        # work offsets: a vector longer than X Y Z carries the rotary components
        self.wofs = [[0.0] * n for _ in range(n_wofs)]
        for k, v in (work_offsets or {}).items():
            if 0 <= k < n_wofs and len(v) > 3:
                for i, x in enumerate(v[3 : 3 + n]):
                    self.wofs[k][i] = float(x)

    def offset(self, i: int, wcs: int) -> float:
        return self.wofs[wcs][i] + self.wofs[0][i] + self.g92[i]

    def program(self, wcs: int) -> tuple[float, ...]:
        """The program angles (machine angle minus the offsets), degrees."""
        return tuple(m - self.offset(i, wcs) for i, m in enumerate(self.mach))

    def words_in(self, blk: Block) -> list[str]:
        return [k for k in blk.words if k in self.letters]

    def move(self, ip, blk: Block, absolute: bool, machine: bool = False) -> bool:
        """Apply the block's rotary words; True when an angle changed. `machine`: G53
        (machine angles, offsets ignored)."""
        changed = False
        for letter in self.words_in(blk):
            i = self.index[letter]
            v = ip._plain(blk, letter)  # degrees: never scaled by G20
            if machine:
                target = v
            elif absolute:
                target = v + self.offset(i, ip._wcs)
            else:
                target = self.mach[i] + v
            self.check(i, target, blk, ip)
            if target != self.mach[i]:
                self.mach[i] = target
                changed = True
        return changed

    def home_named(self, blk: Block, ref: list[float] | None = None) -> bool:
        """G28/G30: the named rotary axes go to their reference angle."""
        changed = False
        for letter in self.words_in(blk):
            i = self.index[letter]
            target = self.home[i] if ref is None else ref[i]
            if target != self.mach[i]:
                self.mach[i] = target
                changed = True
        return changed

    def set_g92(self, blk: Block, ip) -> None:
        """G92 A..: the current angle becomes the programmed one."""
        for letter in self.words_in(blk):
            i = self.index[letter]
            v = ip._plain(blk, letter)
            self.g92[i] = self.mach[i] - self.wofs[ip._wcs][i] - self.wofs[0][i] - v

    def check(self, i: int, target: float, blk: Block, ip) -> None:
        lo, hi = self.lo[i], self.hi[i]
        if target < lo - ROTARY_LIMIT_SLACK or target > hi + ROTARY_LIMIT_SLACK:
            name = self.names[i]
            raise NcError(
                f"axis {name} move to {target:.4f} deg is beyond the soft limit "
                f"[{lo:g}, {hi:g}] deg (machine coordinates)",
                blk.line,
                blk.col(name),
                ip._frames[-1].file if ip._frames else ip.file,
            )

    def stamp(self, out: list) -> None:
        """Extend every motion command's X Y Z end (and arc centre) by the rotary angles."""
        rot = tuple(self.mach)
        for k, cmd in enumerate(out):
            if isinstance(cmd, (StraightTraverse, StraightFeed)):
                if len(cmd.end) == 3:
                    out[k] = replace(cmd, end=(*cmd.end, *rot))
            elif isinstance(cmd, ArcFeed) and len(cmd.end) == 3:
                out[k] = replace(cmd, end=(*cmd.end, *rot), center=(*cmd.center, *rot))
