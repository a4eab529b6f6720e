"""End to end: seed 004's synthetic program (req 15) processed, posted for mill3 and run on
the complete simulated mill (CiA 402 drives, PLC) in lockstep: it ends at (4, 8, 6) in, with
the PLC's trace of tool, spindle and coolant in the right order."""

from __future__ import annotations

import pytest

from cam.apt import process
from cam.post import PostOptions, load_machine, post
from cnc.config import builtin_machine
from cnc.machine import Machine

from .test_post import SEED15

INCH = 25.4
G54_MM = -300.0  # the part zero of this setup, machine coordinates (mill3 travel is negative)


def _posted() -> str:
    _, blocks = post(process(SEED15, "seed15.apt"), load_machine("mill3"), PostOptions())
    lines = [b.text for b in blocks]
    # the setup sheet's work offset, as an operator would set it (inch: the program is G20)
    offset = f"{G54_MM / INCH:.4f}"
    lines.insert(3, f"G10 L2 P1 X{offset} Y{offset} Z{offset}")
    return "\n".join(lines) + "\n"


def test_seed15_runs_on_the_simulated_mill() -> None:
    text = _posted()
    m = Machine(builtin_machine("mill3"), "mill3")
    try:
        number = m.load_program(text)
        m.run_until(lambda mm: mm.axes.feedback().enabled or bool(mm.alarms), 2.0)
        m.step(2)
        m.command("mode", mode="REF")
        m.command("home")
        assert m.run_until(
            lambda mm: all(mm.controller.referenced.values()) or bool(mm.alarms), 120.0
        )
        assert not m.alarms
        m.command("mode", mode="AUTO")
        final_in, trace, cycle = run_seed15(m, number, (G54_MM,) * 3)
    finally:
        m.close()
    assert final_in == (4.0, 8.0, 6.0)
    check_seed15_trace(text.splitlines(), trace, cycle)


def run_seed15(m: Machine, number: int, g54_mm: tuple[float, ...]):
    """Run program `number` on a homed machine in AUTO: (final position in inches in the
    work frame of G54 `g54_mm`, the trace of (t, line, tool, spindle at speed, coolant) at
    every change, cycle time s)."""
    trace: list[tuple[float, int, int, bool, bool]] = []
    m.command("select_program", number=number)
    m.command("cycle_start")
    t0 = m.t

    def sample(mm) -> bool:
        row = (
            mm.status.line,
            mm.io.state.tool_in_spindle,
            mm.status.spindle_speed > 900.0,
            bool(mm.io.output("CoolantPump")),
        )
        if not trace or trace[-1][1:] != row:
            trace.append((round(mm.t - t0, 3), *row))
        return bool(mm.alarms) or (
            mm.status.execution in ("PROGRAM_COMPLETED", "READY") and mm.t > t0 + 0.05
        )

    assert m.run_until(sample, 300.0)
    assert not m.alarms, m.alarms
    m.run_until(
        lambda mm: all(
            abs(mm.axes.feedback().actual[a] - mm.last_targets[a]) < 0.005 for a in "XYZ"
        ),
        1.0,
    )
    cycle = m.t - t0
    actual = m.axes.feedback().actual
    final_in = tuple(round((actual[a] - g) / INCH, 3) for a, g in zip("XYZ", g54_mm, strict=True))
    return final_in, trace, cycle


def check_seed15_trace(lines: list[str], trace: list, cycle: float) -> None:
    """Seed 004 req 15's PLC trace: tool 1, spindle and coolant on before the first motion,
    coolant off after the last, then the spindle; the cycle no shorter than the feed time."""
    line_of = {t: n for n, t in enumerate(lines, 1)}

    def first(pred) -> int:
        return next(i for i, row in enumerate(trace) if pred(row))

    g00, m09, m05 = line_of["G00 X2. Y3. Z4."], line_of["M09"], line_of["M05"]
    # tool 1 in the spindle, spindle at speed and coolant on before the first motion
    at_motion = trace[first(lambda r: r[1] == g00)]
    assert at_motion[2:] == (1, True, True)
    # coolant off at M09 (after the last motion), then the spindle off at M05
    coolant_off = first(lambda r: r[1] >= m09 and not r[4])
    spindle_off = first(lambda r: r[1] >= m05 and not r[3])
    assert coolant_off <= spindle_off
    assert all(r[4] for r in trace if g00 <= r[1] < m09)  # coolant on through every motion
    # feed time 6.1644/10 + 1/10 min = 42.99 s (seed 004 req 15) plus the rapid leg, the
    # tool change and the spindle run-up: the cycle can only be longer
    assert cycle == pytest.approx(47.0, abs=3.0) and cycle > 42.99
