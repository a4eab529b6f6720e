"""Homing mode (6): the CiA 402 methods with limit switches, home switch, index pulse.

Numbering follows CiA 402-2 (IEC 61800-7-201), as `canopen.profiles.p402.Homing` does:

======  ========================================================================
method  home position
======  ========================================================================
1 / 2   first index pulse after leaving the negative / positive limit switch
3 / 4   index pulse after the falling / rising edge of a positive home switch
5 / 6   index pulse after the falling / rising edge of a negative home switch
17/18   the negative / positive limit switch edge (no index)
19/20   falling / rising edge of a positive home switch (active above its edge)
21/22   falling / rising edge of a negative home switch (active below its edge)
33/34   first index pulse moving negative / positive
35/37   the current position (37 is the newer number for 35)
======  ========================================================================

The home-switch methods follow the reference-point approach of the NC book (000 §8): search
the dog at the switch-search speed 0x6099:1; the final approach to the edge is always made in
the SAME direction at the creep speed 0x6099:2 (backing off first when the axis starts on the
wrong side or has crossed the edge at search speed); with an index, the zero mark after the
edge is latched while creeping on. Edges and index marks are latched by interpolation inside
the sub-step (a hardware latch), so the result does not depend on the IPO cycle.

At the latch the position is set so that 0x6064 = home offset 0x607C there; the axis then
brakes with 0x609A and stops a few micrometres further on (the creep overshoot).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from drives.cia402.profile import ramp_velocity, stop_step

NEG_LIMIT, POS_LIMIT, HOME = 1, 2, 4

SUPPORTED_METHODS = frozenset({1, 2, 3, 4, 5, 6, 17, 18, 19, 20, 21, 22, 33, 34, 35, 37})


@dataclass(frozen=True, slots=True)
class Segment:
    direction: int  # +1 / -1
    creep: bool  # False: 0x6099:1 switch search speed, True: 0x6099:2 creep (zero search)
    until: tuple  # ("sw", bit, active) or ("index",)
    latch: bool = False


class HomingStatus(Enum):
    """Statusword bits 13, 12, 10 (mask 0x3400) of the homing mode."""

    NOT_STARTED = 0x0400  # "interrupted or not started"
    IN_PROGRESS = 0x0000
    INTERRUPTED = 0x0400
    ATTAINED = 0x1000  # home found, axis still braking
    DONE = 0x1400  # attained and target reached
    ERROR = 0x2000  # error, velocity not zero
    ERROR_STOPPED = 0x2400  # error, velocity zero


def plan(method: int, inputs: int) -> list[Segment] | None:
    """The segment list for a method given the switch inputs (0x60FD bits) at the start.

    Returns [] for methods 35/37 (home here) and None for an unsupported method.
    """
    if method in (35, 37):
        return []
    if method in (33, 34):
        return [Segment(-1 if method == 33 else 1, True, ("index",), True)]
    if method in (1, 2, 17, 18):
        bit, d = (NEG_LIMIT, 1) if method in (1, 17) else (POS_LIMIT, -1)
        segs = []
        if not inputs & bit:
            segs.append(Segment(-d, False, ("sw", bit, True)))
        segs.append(Segment(d, True, ("sw", bit, False), latch=method >= 17))
        if method < 17:
            segs.append(Segment(d, True, ("index",), True))
        return segs
    if method in (3, 4, 5, 6, 19, 20, 21, 22):
        base = method if method < 17 else method - 16
        # (state before the edge, final approach direction)
        s_before, d = {3: (True, -1), 4: (False, 1), 5: (True, 1), 6: (False, -1)}[base]
        index = method < 17
        s0 = bool(inputs & HOME)
        segs = []
        if s0 == s_before:
            segs.append(Segment(d, False, ("sw", HOME, not s_before)))
            if not index:
                segs.append(Segment(-d, True, ("sw", HOME, s_before)))
                segs.append(Segment(d, True, ("sw", HOME, not s_before), True))
        else:
            segs.append(Segment(-d, False, ("sw", HOME, s_before)))
            segs.append(Segment(d, True, ("sw", HOME, not s_before), latch=not index))
        if index:
            segs.append(Segment(d, True, ("index",), True))
        return segs
    return None


class HomingRun:
    """One homing procedure in progress, advanced sub-step by sub-step."""

    def __init__(
        self,
        segments: list[Segment],
        fast: float,
        creep: float,
        acc: float,
        max_travel: float,
        start_pos: float,
    ) -> None:
        self.segments = segments
        self.i = 0
        self.fast, self.creep, self.acc = fast, creep, acc
        self.max_travel = max_travel
        self.start_pos = start_pos
        self.latched: float | None = None  # measured angle of the home position
        self.error = False
        self.braking = not segments
        self.standstill = True  # the axis' actual speed is below the standstill threshold

    def drive(self, dem, h: float) -> bool:
        """Advance the demand one sub-step; True once the axis has stopped after the latch."""
        if self.braking or self.error:
            return stop_step(dem, self.acc, h) and self.standstill
        seg = self.segments[self.i]
        speed = self.creep if seg.creep else self.fast
        ramp_velocity(dem, seg.direction * speed, self.acc, self.acc, h)
        if abs(dem.pos - self.start_pos) > self.max_travel:
            self.error = True
        return False

    def observe(self, inputs: int, edges: dict[int, float], index_at: float | None) -> None:
        """Feed the switch state after the sub-step, the latched angle of each input that
        changed during it, and the angle of an index mark passed (or None)."""
        if self.braking or self.error:
            return
        seg = self.segments[self.i]
        if seg.until[0] == "index":
            hit, at = index_at is not None, index_at
        else:
            _, bit, active = seg.until
            hit, at = bool(inputs & bit) == active and bit in edges, edges.get(bit)
        if not hit:
            return
        if seg.latch:
            self.latched = at
            self.braking = True
        else:
            self.i += 1
