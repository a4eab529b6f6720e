"""Programs across files: the calls a program makes (cnc.gcode.calls), resolution by O number
from a folder, the program memory and a subprogram file checked on its own; the nesting
limits; a missing subprogram at the machine is a program alarm naming PS0076 and the line."""

from __future__ import annotations

import dataclasses

import pytest

from cnc.canon import MOTION_TYPES
from cnc.errors import NcError
from cnc.gcode.calls import Call, program_calls
from cnc.gcode.source import ends_with_m99
from cnc.interp import MAX_SUB_NESTING, Interpreter, check
from cnc.interp.interpreter import MAX_MACRO_NESTING
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1e6, 1e6, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)


# --- which programs a program calls ---------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "calls"),
    [
        ("M98 P1002 L4 (Run subroutine 4 times)", [("M98", 1002, 5, False)]),
        ("M98 P1002", [("M98", 1002, 5, True)]),  # no L: may be the packed 4-digit form
        ("G90G65P9001 A1.", [("G65", 9001, 7, False)]),
        ("G54 G65 P140001 X180.95 I155.000", [("G65", 140001, 9, False)]),
        ("G66 P9100 Z-5. R1.", [("G66", 9100, 5, False)]),
        ("P7 M98", [("M98", 7, 1, True)]),  # P before the code
        ("m098 p0012 l2", [("M98", 12, 6, False)]),  # lower case, leading zeros
        ("N10 G98 G81 Z-1. R1. P2", []),  # G98: return level, not a call
        ("M980 P5", []),
        ("G65 P#1 A2.", []),  # a variable: known only when it runs
        ("(M98 P5) G0 X1", []),  # in a comment
        ("G0 X1 ; M98 P5", []),
        ("#1=#2M98", []),
        ("M99 P10", []),  # a return, not a call
    ],
)
def test_calls_read_off_a_line(line, calls) -> None:
    got = program_calls(["O1", line]).calls
    assert [(c.code, c.number, c.col, c.packed) for c in got] == calls
    assert all(c.line == 2 for c in got)


def test_calls_to_o_blocks_of_the_same_file_are_not_dependencies() -> None:
    text = "O1\nM98 P1000\nG65 P2000\nM98 P21000\nM30\nO1000\nM99\n"
    found = program_calls(text.splitlines())
    assert found.defined == {1, 1000}
    # P21000 without L: repeat 2 times O1000 (in the file); G65 P2000 is another file's
    assert [(c.number, c.line) for c in found.calls] == [(2000, 3)]
    assert found.numbers == [2000]


@pytest.mark.parametrize(
    ("call", "exists", "reaches"),
    [
        (Call("M98", 51000, 1, 1, packed=True), {51000}, 51000),  # an 8-digit O number
        (Call("M98", 51000, 1, 1, packed=True), {1000}, 1000),  # repeat 5, O1000
        (Call("M98", 51000, 1, 1, packed=True), set(), None),
        (Call("M98", 51000, 1, 1, packed=False), {1000}, None),  # with L: the number itself
        (Call("G65", 9001, 1, 1), {9001}, 9001),
    ],
)
def test_a_call_resolves_as_the_interpreter_does(call, exists, reaches) -> None:
    assert call.resolve(exists.__contains__) == reaches
    if reaches is None:
        assert call.named() == (1000 if call.packed else call.number)


@pytest.mark.parametrize(
    ("text", "sub"),
    [
        ("%\nO1002\nG1 X1\nM99 (Return)\n%\n", True),
        ("O1002\nG1 X1\nM99\n\n\n", True),
        ("O1\nG1 X1\nM99 P10\n", True),
        ("O1\nM98 P5\nM30\n", False),
        ("O1\nM99\nG0 X1\n", False),
        ("O1\nM199\n", False),
        ("", False),
    ],
)
def test_a_file_ending_in_m99_is_a_subprogram(tmp_path, text, sub) -> None:
    assert ends_with_m99(text.splitlines()) is sub
    p = tmp_path / "p.nc"
    p.write_text(text)
    assert ends_with_m99(str(p)) is sub


def test_a_subprogram_checked_alone_takes_its_callers_feed() -> None:
    sub = "%\nO1002\nG91 G01 Z-.08\nG90\nG01 X1 Y1\nF100\nG1 X2\nM99\n%\n"
    interp = Interpreter(MILL, subprogram=None)
    assert interp.check_all(sub) == []
    assert interp.checked_alone and interp.caller_feed_line == 3
    # the same moves in a main program have no feed
    main = sub.replace("M99", "M30")
    errs = check(main, MILL)
    assert [(e.line, e.message) for e in errs] == [(3, "feed move without F"),
                                                    (5, "feed move without F")]  # fmt: skip
    # called, the subprogram takes the caller's feed: nothing is assumed
    interp = Interpreter(MILL, programs={1002: sub})
    cmds = list(interp.run("G1 F50 X0\nM98 P1002\nM30\n"))
    assert interp.caller_feed_line is None
    assert [c.feed for c in cmds if hasattr(c, "feed")][:3] == [50.0, 50.0, 50.0]


# --- nesting ---------------------------------------------------------------------------------


def chain(code: str, depth: int) -> dict[int, str]:
    """Programs O1..O<depth>, each calling the next with `code`; the last one moves."""
    progs = {n: f"O{n}\n{code} P{n + 1}\nM99\n" for n in range(1, depth)}
    progs[depth] = f"O{depth}\nG91 G0 X1\nM99\n"
    return progs


# a Fanuc 0i-C, 16i/18i/21i: 4 program levels, 4 macro levels (machine config call_nesting,
# macro_nesting); the 0i-D/F (the default): 10 and 5
OLD_FANUC = dataclasses.replace(MILL, call_nesting=4, macro_nesting=4)


@pytest.mark.parametrize(
    ("params", "code", "depth", "alarm"),
    [
        (MILL, "M98", MAX_SUB_NESTING, None),
        (MILL, "M98", MAX_SUB_NESTING + 1, "PS0077"),
        (MILL, "G65", MAX_MACRO_NESTING, None),
        (MILL, "G65", MAX_MACRO_NESTING + 1, "PS0122"),
        (OLD_FANUC, "M98", 4, None),
        (OLD_FANUC, "M98", 5, "PS0077"),
        (OLD_FANUC, "G65", 4, None),
        (OLD_FANUC, "G65", 5, "PS0122"),
    ],
)
def test_nesting_limits(params, code, depth, alarm) -> None:
    progs = chain(code, depth)
    run = Interpreter(params, programs=progs).run(f"{code} P1\nM30\n")
    if alarm is None:
        assert len([c for c in run if isinstance(c, MOTION_TYPES)]) == 1
        return
    with pytest.raises(NcError) as ei:
        list(run)
    assert ei.value.message.startswith(alarm)
    # the call one level too deep: in the deepest program that still runs
    assert (ei.value.file, ei.value.line) == (f"O{depth - 1}", 2)


def test_nesting_limits_come_from_the_machine_config() -> None:
    from cnc.config import load_machine_config

    params = load_machine_config({"base": "mill3", "call_nesting": 4, "macro_nesting": 4}).params
    assert (params.call_nesting, params.macro_nesting) == (4, 4)
    with pytest.raises(NcError, match="PS0077 subprogram nesting deeper than 4 levels"):
        list(Interpreter(params, programs=chain("M98", 5)).run("M98 P1\nM30\n"))


def test_recursion_is_stopped_by_the_nesting_limit() -> None:
    with pytest.raises(NcError, match="PS0077") as ei:
        list(Interpreter(MILL, programs={5: "O5\nM98 P6\nM99\n", 6: "O6\nM98 P5\nM99\n"})
             .run("M98 P5\n"))  # fmt: skip
    assert ei.value.file in ("O5", "O6") and ei.value.line == 2


# --- the program memory ----------------------------------------------------------------------


def test_programs_mapping_is_read_only_when_a_call_needs_it() -> None:
    """A program memory or a library database is asked for a program's text at the call,
    not every program's text when the run starts."""

    class Memory(dict):
        asked: list[int] = []

        def __getitem__(self, number):
            self.asked.append(number)
            return super().__getitem__(number)

    memory = Memory({2: "O2\nG91 G0 X1\nM99\n", 3: "O3\nM99\n", 4: "O4\nM99\n"})
    list(Interpreter(MILL, programs=memory).run("M98 P2\nM30\n"))
    assert memory.asked == [2]


@pytest.fixture(scope="module")
def machine():
    from cnc.config import load_machine_config
    from cnc.machine import Machine

    cfg = load_machine_config({"base": "mill3", "machine_data": None})
    m = Machine(cfg, "mill1", ideal=True)
    m.step(50)
    m.command("mode", mode="REF")
    m.command("home")
    assert m.run_until(lambda mm: all(mm.controller.referenced.values()), 5.0)
    m.command("mode", mode="AUTO")
    yield m
    m.close()


def run(m, number: int) -> None:
    m.command("select_program", number=number)
    m.command("cycle_start")
    m.step(5)
    assert m.run_until(lambda mm: mm.status.execution != "ACTIVE", 30.0)


def test_memory_resolves_m98_g65_and_g66_to_other_programs(machine) -> None:
    machine.load_program("O2001\nG91 G1 X-5 F3000\nG90\nM99\n")
    machine.load_program("O9011\nG91 G1 Y[-#1] F3000\nG90\nM99\n")  # G65 A: #1
    machine.load_program("O9012\nG91 G1 Z-1 F3000\nG90\nM99\n")  # G66: after every move
    machine.load_program(
        "O2000\nG90 G0 X-10 Y-10 Z-10\nM98 P2001 L2\nG65 P9011 A4.\n"
        "G66 P9012\nG0 X-30\nG67\nG0 X-40\nM30\n"
    )
    run(machine, 2000)
    assert machine.status.execution == "PROGRAM_COMPLETED", machine.alarms
    pos = machine.axes.feedback().actual
    assert pos == pytest.approx({"X": -40.0, "Y": -14.0, "Z": -11.0})


def test_a_missing_subprogram_is_a_program_alarm_with_ps0076_at_the_call(machine) -> None:
    machine.command("reset")
    machine.step(5)
    machine.load_program("O2100\nG90 G0 X-10 Y-10 Z-10\nG0 X-12\nM98 P2199\nM30\n")
    run(machine, 2100)
    (alarm,) = [a for a in machine.alarms if a.number == 3020]
    # the line in the stored form (the tape's leading % is its line 1)
    assert machine.memory.get(2100).splitlines()[4] == "M98 P2199"
    assert "O2100:5:5: PS0076 M98: program O2199 not found" in alarm.text
    machine.command("reset")
    machine.step(5)
    # stored later (as a Fanuc: storing never checks the calls), the program runs
    machine.load_program("O2199\nG91 G0 X-1\nG90\nM99\n")
    run(machine, 2100)
    assert machine.status.execution == "PROGRAM_COMPLETED", machine.alarms
    assert machine.axes.feedback().actual["X"] == pytest.approx(-13.0)


def test_m99_p_returns_from_memory_to_a_sequence_number_of_the_caller(machine) -> None:
    machine.command("reset")
    machine.step(5)
    machine.load_program("O2202\nG91 G0 X-2\nG90\nM99 P50\n")
    machine.load_program(
        "O2200\nG90 G0 X-10 Y-10 Z-10\nM98 P2202\nG0 X-99 (skipped)\nN50 G0 Y-3\nM30\n"
    )
    run(machine, 2200)
    assert machine.status.execution == "PROGRAM_COMPLETED", machine.alarms
    pos = machine.axes.feedback().actual
    assert (pos["X"], pos["Y"]) == pytest.approx((-12.0, -3.0))
