"""IPO-cycle interpolator: samples the look-ahead plan, one `Motion.step()` per cycle."""

from cnc.interpolator.motion import Motion, Sample

__all__ = ["Motion", "Sample"]
