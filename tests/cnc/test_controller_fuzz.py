"""Random operator and PLC action sequences: the controller never crashes, refuses with a
reason, and its status always says what it is doing."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.controller import IN_CYCLE, CommandRefused
from cnc.status import EXECUTION
from tests.cnc.test_controller import SQUARE, Rig

COMMANDS = st.one_of(
    st.tuples(
        st.just("mode"),
        st.fixed_dictionaries(
            {"mode": st.sampled_from(["AUTO", "MDI", "JOG", "REF", "EDIT", "bogus"])}
        ),
    ),
    st.tuples(
        st.just("select_program"), st.fixed_dictionaries({"number": st.sampled_from([1000, 1234])})
    ),
    st.tuples(st.just("cycle_start"), st.just({})),
    st.tuples(st.just("feed_hold"), st.just({})),
    st.tuples(st.just("reset"), st.just({})),
    st.tuples(st.just("single_block"), st.fixed_dictionaries({"on": st.booleans()})),
    st.tuples(st.just("feed_override"), st.fixed_dictionaries({"pct": st.integers(-10, 250)})),
    st.tuples(st.just("home"), st.just({})),
    st.tuples(
        st.just("mdi"),
        st.fixed_dictionaries(
            {"text": st.sampled_from(["G90 G0 X-20 Y-20 Z-20", "G1 X-5", "G0 X99", "M3 S500"])}
        ),
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
@given(ACTIONS)
def test_random_actions_never_crash_and_status_stays_consistent(actions):
    rig = Rig(programs={1000: SQUARE})
    rig.step(10)
    for kind, action in actions:
        if kind == "cmd":
            name, args = action
            try:
                rig.cmd(name, **args)
            except CommandRefused as exc:
                assert exc.reason
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
