"""Random operator and PLC action sequences: the controller never crashes, refuses with a
reason, and its status always says what it is doing. Its program errors are the NC checker's:
an MDI block or a part program it refuses with a program error is refused with exactly the
first error `check` reports for that text (file, line, column, message), a text `check`
passes is never refused with one, and a program with an error never completes."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.controller import IN_CYCLE, CommandRefused
from cnc.controller.alarms import PROGRAM_ERROR
from cnc.status import EXECUTION
from tests.cnc.test_controller import SQUARE, Rig

# an arc without R or centre at line 7, after the first moves have run
BROKEN = """%
O2000
G90 G17 G21 G54
G0 X-100 Y-100 Z-50
G1 Z-60 F600
G1 X-120 F1200
G2 X-130 Y-100 F600
G0 Z-50
M30
%
"""
PROGRAMS = {1000: SQUARE, 2000: BROKEN}
MDI_TEXTS = ["G90 G0 X-20 Y-20 Z-20", "G1 X-5", "G0 X99", "M3 S500", "G1 X-5 Q", "G2 X-30 F100"]

COMMANDS = st.one_of(
    st.tuples(
        st.just("mode"),
        st.fixed_dictionaries(
            {"mode": st.sampled_from(["AUTO", "MDI", "JOG", "REF", "EDIT", "bogus"])}
        ),
    ),
    st.tuples(
        st.just("select_program"),
        st.fixed_dictionaries({"number": st.sampled_from([1000, 1234, 2000])}),
    ),
    st.tuples(st.just("cycle_start"), st.just({})),
    st.tuples(st.just("feed_hold"), st.just({})),
    st.tuples(st.just("reset"), st.just({})),
    st.tuples(st.just("single_block"), st.fixed_dictionaries({"on": st.booleans()})),
    st.tuples(st.just("feed_override"), st.fixed_dictionaries({"pct": st.integers(-10, 250)})),
    st.tuples(st.just("home"), st.just({})),
    st.tuples(
        st.just("mdi"),
        st.fixed_dictionaries({"text": st.sampled_from(MDI_TEXTS)}),
    ),
    st.tuples(
        st.just("jog"),
        st.fixed_dictionaries(
            {
                "axis": st.sampled_from(["X", "Z"]),
                "direction": st.sampled_from([-1, 0, 1]),
                "increment": st.sampled_from([None, 1.0, 700.0]),
            }
        ),
    ),
)
PLC_FLIPS = st.tuples(
    st.sampled_from(
        ["EStopActive", "FeedHold", "DoorClosed", "SpindleAtSpeed", "CycleStart", "NcReset"]
    ),
    st.booleans(),
)
ACTIONS = st.lists(
    st.one_of(
        st.tuples(st.just("cmd"), COMMANDS),
        st.tuples(st.just("plc"), PLC_FLIPS),
        st.tuples(st.just("step"), st.integers(1, 200)),
    ),
    min_size=1,
    max_size=25,
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ACTIONS, st.sampled_from([None, 1000, 2000]))
def test_random_actions_never_crash_and_status_stays_consistent(actions, selected):
    rig = Rig(programs=PROGRAMS)
    # what the NC checker says of each text, with the controller's own interpreter set-up
    first_error = {}
    for number, text in PROGRAMS.items():
        errs = rig.ctl._interpreter(f"O{number:04d}").check_all(text.splitlines())
        first_error[f"O{number:04d}"] = errs[0] if errs else None
    assert first_error["O1000"] is None and first_error["O2000"].line == 7
    rig.step(10)
    if selected is not None:  # start where a program can run: referenced, AUTO, selected
        rig.home()
        rig.cmd("mode", mode="AUTO")
        rig.cmd("select_program", number=selected)
    seen_alarms = set()
    for kind, action in actions:
        if kind == "cmd":
            name, args = action
            try:
                rig.cmd(name, **args)
            except CommandRefused as exc:
                assert exc.reason
                if name == "mdi":
                    errs = rig.ctl._interpreter("MDI").check_all(args["text"].splitlines())
                    if exc.reason.startswith("MDI refused: MDI:"):  # a program error
                        assert errs, f"{exc.reason}, but check() passes {args['text']!r}"
                        assert exc.reason == f"MDI refused: {errs[0]}"
            else:
                if name == "mdi":
                    errs = rig.ctl._interpreter("MDI").check_all(args["text"].splitlines())
                    assert not errs, f"MDI {args['text']!r} taken, check() reports {errs[0]}"
        elif kind == "plc":
            name, value = action
            rig.plc.out[name] = value
            if name == "EStopActive":
                rig.plc.out["AxisEnable"] = not value
        else:
            for _ in range(action):
                rig.step()
                st_ = rig.outputs.status
                assert st_.execution in EXECUTION
                if st_.execution in IN_CYCLE:
                    assert rig.outputs.plc["NcInCycle"] is True
                if st_.execution in ("READY", "PROGRAM_COMPLETED"):
                    assert rig.outputs.plc["NcInCycle"] is False
                assert all(math.isfinite(v) for v in rig.outputs.targets.values())
                if rig.ctl._estop:
                    assert st_.emergency_stop == "TRIGGERED"
                    assert st_.execution not in IN_CYCLE
                for alarm in rig.ctl.alarms:
                    if alarm.number != PROGRAM_ERROR or alarm.text in seen_alarms:
                        continue
                    seen_alarms.add(alarm.text)
                    program = alarm.text.removeprefix("program error: ").split(":", 1)[0]
                    want = first_error.get(program)
                    assert want is not None, f"{alarm.text}: check() passes {program}"
                    assert alarm.text == f"program error: {want}"
            completed = [text for _, text in rig.ctl.events if text.startswith("O2000 completed")]
            assert not completed, "O2000 ran past its program error to the end"


def test_the_program_error_alarm_is_the_checkers_first_error():
    """The fuzz above reaches a program error only in some sequences: here always."""
    rig = Rig(programs=PROGRAMS)
    want = rig.ctl._interpreter("O2000").check_all(BROKEN.splitlines())[0]
    rig.home()
    rig.cmd("mode", mode="AUTO")
    rig.run_program(2000)
    assert rig.ctl.execution == "STOPPED"
    assert [a.text for a in rig.ctl.alarms if a.number == PROGRAM_ERROR] == [
        f"program error: {want}"
    ]
    assert not [t for _, t in rig.ctl.events if t.startswith("O2000 completed")]
    rig.cmd("reset")
    rig.run_program(1000)
    assert rig.ctl.execution == "PROGRAM_COMPLETED"


@pytest.mark.parametrize("text", MDI_TEXTS)
def test_mdi_is_refused_with_the_checkers_first_error(text):
    rig = Rig(programs=PROGRAMS)
    rig.home()
    rig.cmd("mode", mode="MDI")
    errs = rig.ctl._interpreter("MDI").check_all(text.splitlines())
    if errs:
        with pytest.raises(CommandRefused) as refused:
            rig.cmd("mdi", text=text)
        assert refused.value.reason == f"MDI refused: {errs[0]}"
    else:
        rig.cmd("mdi", text=text)  # taken (it may stop later on a soft limit: not a check)
