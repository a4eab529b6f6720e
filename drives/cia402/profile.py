"""Set-point generators shared by the modes: trapezoid to a target, velocity ramp, stop ramp.

All generators work in motor radians (the encoder frame) on a `Demand` (position, velocity)
and advance it by one sub-step h. They are pure arithmetic, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(slots=True)
class Demand:
    """The drive's internal set-point: position (rad) and velocity (rad/s) at the motor."""

    pos: float = 0.0
    vel: float = 0.0


def ramp_velocity(dem: Demand, target: float, acc: float, dec: float, h: float) -> None:
    """Move dem.vel toward target: `acc` while speeding up, `dec` while slowing down."""
    v = dem.vel
    speeding_up = (target > v >= 0.0) or (target < v <= 0.0)
    rate = (acc if speeding_up else dec) * h
    if v < target:
        v_new = min(target, v + rate)
    else:
        v_new = max(target, v - rate)
    dem.pos += 0.5 * (v + v_new) * h
    dem.vel = v_new


def stop_step(dem: Demand, dec: float, h: float) -> bool:
    """Decelerate to standstill at `dec`; True once the demand velocity is zero."""
    ramp_velocity(dem, 0.0, dec, dec, h)
    return dem.vel == 0.0


def trapezoid_step(
    dem: Demand, target: float, vmax: float, acc: float, dec: float, h: float
) -> bool:
    """One sub-step of an online trapezoidal move to `target`; True when it has arrived.

    The demand may start moving (even away from the target): it brakes with `dec`, turns and
    runs at most `vmax`, and brakes so that it lands on the target. The last sub-step snaps
    onto the target once the remaining speed is below what one sub-step of braking removes.
    """
    pos, vel = dem.pos, dem.vel
    d = target - pos
    if d == 0.0 and vel == 0.0:
        return True
    direction = 1.0 if d > 0.0 else -1.0 if d < 0.0 else (-1.0 if vel > 0.0 else 1.0)
    v_goal = direction * min(vmax, math.sqrt(2.0 * dec * abs(d)))
    ramp_velocity(dem, v_goal, acc, dec, h)
    if (target - dem.pos) * direction <= 0.0 and abs(dem.vel) <= 2.0 * dec * h:
        dem.pos, dem.vel = target, 0.0
        return True
    return False
