"""G32 / G76 thread lead measured against the spindle's encoder.

What is coupled (docs/gcode.md, "Thread cutting"): the interpreter turns a thread move into
a feed of lead x rpm along the thread's long axis, at the spindle speed programmed for the
pass; the planner runs it exact-stop. These tests run the canonical moves through the
planner/interpolator (cnc.interpolator.Motion, one setpoint per IPO cycle) next to a
spindle turning at the programmed speed with a 4096-count encoder, and measure the lead as
Z travel per encoder revolution over the pass's constant-velocity part: the error must be
below 0.1 % of the lead. The acceleration and deceleration at the ends of a pass are not
synchronised (a real control needs run-in and run-out distances there too), which is why
the thread's approach and overrun must lie outside the part.
"""

from __future__ import annotations

import math

import pytest

from cnc.canon import StraightFeed, StraightTraverse
from cnc.interp import Interpreter
from cnc.interpolator.motion import Motion
from cnc.params import AxisParams, MachineParams

LATHE = MachineParams(
    kind="lathe",
    axes=(
        AxisParams("X", -1000, 1000, 20000, 4000, 60000),
        AxisParams("Z", -1000, 1000, 24000, 3000, 50000),
    ),
)
COUNTS_PER_REV = 4096


def encoder_leads(prog: str, rpm: float, line: int) -> list[float]:
    """The lead (mm per spindle revolution, from encoder counts) of each thread pass of
    `line`, over its constant-velocity part."""
    cmds = [
        c for c in Interpreter(LATHE).run(prog) if isinstance(c, StraightFeed | StraightTraverse)
    ]
    threads = {i for i, c in enumerate(cmds) if isinstance(c, StraightFeed) and c.line == line}
    m = Motion(LATHE, start=(0.0, 0.0, 0.0))
    samples = []
    pending = list(cmds)
    while pending or not m.idle:
        while pending and m.space() > 0:
            m.push(pending.pop(0))
        if not pending:
            m.end_of_program()
        s = m.step()
        samples.append(s)
        if len(samples) > 5_000_000:
            raise AssertionError("motion never finished")
    assert threads
    leads = []
    run: list = []
    for s in samples + [None]:
        feeding = s is not None and s.line == line and s.velocity > 0
        if feeding:
            run.append(s)
            continue
        if run:
            vmax = max(r.velocity for r in run)
            flat = [r for r in run if abs(r.velocity - vmax) <= 1e-9 * vmax]
            if len(flat) > 100:
                a, b = flat[0], flat[-1]
                counts = math.floor(b.t * rpm / 60.0 * COUNTS_PER_REV) - math.floor(
                    a.t * rpm / 60.0 * COUNTS_PER_REV
                )
                leads.append(abs(b.pose[2] - a.pose[2]) / (counts / COUNTS_PER_REV))
            run = []
    return leads


@pytest.mark.parametrize(("rpm", "lead"), [(500.0, 1.5), (300.0, 2.0), (800.0, 1.0)])
def test_g32_lead_on_the_encoder(rpm: float, lead: float) -> None:
    prog = f"G97 S{rpm:g} M3\nG0 X20 Z5\nG32 Z-60 F{lead:g}\nG0 X30\n"
    leads = encoder_leads(prog, rpm, 3)
    assert len(leads) == 1
    assert abs(leads[0] - lead) < 0.001 * lead


def test_g76_every_pass_has_the_lead() -> None:
    prog = "G97 S600 M3\nG0 X25 Z5\nG76 P010060 Q100 R0.05\nG76 X18.2 Z-60 P900 Q400 F1.5\n"
    leads = encoder_leads(prog, 600.0, 4)
    assert len(leads) == 6  # one per infeed (see test_lathe_cycles)
    for got in leads:
        assert abs(got - 1.5) < 0.001 * 1.5


def test_g32_lead_on_the_controllers_spindle_in_lockstep() -> None:
    """The same measurement on the controller in lockstep (ideal axes, a PLC that reports
    the spindle at speed): Z's commanded position per IPO cycle against the spindle speed
    the controller reports (status.spindle_speed, the speed it commanded through the PLC),
    integrated into encoder counts."""
    from tests.cnc.test_controller import Rig

    prog = (
        "%\nO7100\nG18 G21 G97 G99 S500 M3\nG0 X-100 Z-20\nG32 Z-120 F1.5\nG0 X-120\nM5\nM30\n%\n"
    )
    rig = Rig("lathe2", programs={7100: prog})
    rig.home()
    rig.run_program(7100, limit_s=120)
    assert rig.ex == "PROGRAM_COMPLETED"
    dt = rig.dt
    run = [s for s in rig.trace if s.line == 5]
    z = [s.axes["Z"].commanded for s in run]
    v = [abs(b - a) / dt for a, b in zip(z, z[1:], strict=False)]
    vmax = max(v)
    flat = [i for i, vi in enumerate(v) if abs(vi - vmax) <= 1e-6 * vmax]
    i0, i1 = flat[0], flat[-1] + 1
    counts = 0.0
    for s in run[i0 + 1 : i1 + 1]:
        counts += s.spindle_speed / 60.0 * dt * COUNTS_PER_REV
    lead = abs(z[i1] - z[i0]) / (math.floor(counts) / COUNTS_PER_REV)
    assert run[i0].spindle_speed == pytest.approx(500.0)
    assert abs(lead - 1.5) < 0.001 * 1.5


def _controller_lead(spindle_pct: int, feed_pct: int) -> tuple[float, float]:
    """(lead measured on the controller's spindle speed, that spindle speed) for a G32 pass
    with the PLC's spindle and feed override switches at the given percentages."""
    from tests.cnc.test_controller import Rig

    prog = (
        "%\nO7100\nG18 G21 G97 G99 S500 M3\nG0 X-100 Z-20\nG32 Z-120 F1.5\nG0 X-120\nM5\nM30\n%\n"
    )
    rig = Rig("lathe2", programs={7100: prog})
    rig.plc.out.update(SpindleOverride=spindle_pct, FeedOverride=feed_pct)
    rig.plc_in = rig.plc.outputs()
    rig.home()
    rig.run_program(7100, limit_s=120)
    assert rig.ex == "PROGRAM_COMPLETED"
    dt = rig.dt
    run = [s for s in rig.trace if s.line == 5]
    z = [s.axes["Z"].commanded for s in run]
    v = [abs(b - a) / dt for a, b in zip(z, z[1:], strict=False)]
    vmax = max(v)
    flat = [i for i, vi in enumerate(v) if abs(vi - vmax) <= 1e-6 * vmax]
    i0, i1 = flat[0], flat[-1] + 1
    counts = sum(s.spindle_speed / 60.0 * dt * COUNTS_PER_REV for s in run[i0 + 1 : i1 + 1])
    return abs(z[i1] - z[i0]) / (math.floor(counts) / COUNTS_PER_REV), run[i0].spindle_speed


@pytest.mark.parametrize(("spindle_pct", "feed_pct"), [(80, 100), (120, 100), (100, 50)])
def test_the_lead_holds_under_spindle_and_feed_overrides(spindle_pct, feed_pct) -> None:
    # spindle override 80 %: the spindle runs 400 rpm and the thread feeds 1.5 x 400; a
    # feed override is out of effect while threading
    lead, rpm = _controller_lead(spindle_pct, feed_pct)
    assert rpm == pytest.approx(500.0 * spindle_pct / 100.0)
    assert abs(lead - 1.5) < 0.001 * 1.5


def test_every_g76_pass_starts_at_the_same_spindle_angle() -> None:
    """The passes are phase-locked: the spindle angle (integrated from the controller's
    spindle speed) at which the tool crosses Z-40 is the same on every pass, within the
    rotation of one IPO cycle (500 rpm x 2 ms = 1/60 rev); without the index wait the
    passes land anywhere."""
    from tests.cnc.test_controller import Rig

    prog = (
        "%\nO7200\nG18 G21 G97 G99 S500 M3\nG0 X-100 Z-10\n"
        "G76 X-97.4 Z-60 K1.3 D0.5 F2\nG0 X-120\nM5\nM30\n%\n"
    )
    rig = Rig("lathe2", programs={7200: prog})
    rig.home()
    rig.run_program(7200, limit_s=300)
    assert rig.ex == "PROGRAM_COMPLETED"
    dt = rig.dt
    revs = 0.0
    prev_z = None
    phases = []
    for s in rig.trace:
        revs += s.spindle_speed / 60.0 * dt
        z = s.axes["Z"].commanded
        if s.line == 5 and prev_z is not None and prev_z > -40.0 >= z:
            # interpolate the crossing within the cycle
            frac = (prev_z + 40.0) / (prev_z - z)
            phases.append((revs - (1 - frac) * s.spindle_speed / 60.0 * dt) % 1.0)
        prev_z = z
    assert len(phases) == len(lg_depths(1.3, 0.5))
    spread = max(phases) - min(phases)
    spread = min(spread, 1 - spread)
    assert spread <= 500 / 60 * dt + 1e-9


def lg_depths(height: float, first: float) -> list[float]:
    from cnc.interp import lathe_geometry as lg

    return lg.thread_depths(height, first, 0.0, 0.0, 0)
