"""Fanuc Macro B: every function and operator, #0 (vacant), control flow, calls, system
variables, the persistent store and the alarms, against values computed by hand."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.canon import MOTION_TYPES, ProgramStop, StopKind
from cnc.errors import NcError
from cnc.interp import Interpreter, ToolOffset, check
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1e6, 1e6, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)


def run(text: str, **kw) -> tuple[Interpreter, list]:
    ip = Interpreter(MILL, **kw)
    cmds = list(ip.run(text))
    return ip, cmds


def value(expr: str) -> float | None:
    ip, _ = run(f"#100={expr}\n")
    return ip.vars.common.get(100)


def ends(cmds) -> list[tuple[float, float, float]]:
    return [c.end for c in cmds if isinstance(c, MOTION_TYPES)]


# --- functions and operators (hand-computed) -------------------------------------------------

FUNCTIONS = [
    ("SIN[30]", 0.5),
    ("COS[60]", 0.5),
    ("TAN[45]", 1.0),
    ("ASIN[0.5]", 30.0),
    ("ACOS[0.5]", 60.0),
    ("ATAN[1]", 45.0),
    ("ATAN[1]/[1]", 45.0),
    ("ATAN[-1]/[-1]", 225.0),  # two-argument form: 0 <= angle < 360
    ("ATAN[-1]/[1]", 315.0),
    ("ATAN[1,-1]", 135.0),
    ("SQRT[16]", 4.0),
    ("SQRT[2]*SQRT[2]", 2.0),
    ("ABS[-2.5]", 2.5),
    ("ROUND[2.5]", 3.0),
    ("ROUND[-2.5]", -3.0),  # halves away from zero
    ("ROUND[1.4]", 1.0),
    ("FIX[1.7]", 1.0),
    ("FIX[-1.7]", -1.0),  # the fraction is dropped
    ("FUP[1.2]", 2.0),
    ("FUP[-1.2]", -2.0),  # any fraction raises the magnitude
    ("FUP[3]", 3.0),
    ("LN[1]", 0.0),
    ("LN[EXP[2]]", 2.0),
    ("EXP[0]", 1.0),
    ("POW[2,10]", 1024.0),
    ("POW[9,0.5]", 3.0),
    ("7 MOD 3", 1.0),
    ("-7 MOD 3", -1.0),  # the sign of the dividend
    ("12 AND 10", 8.0),  # 1100 & 1010
    ("12 OR 10", 14.0),
    ("12 XOR 10", 6.0),
    ("3 EQ 3", 1.0),
    ("3 NE 3", 0.0),
    ("3 GT 2", 1.0),
    ("2 GE 2", 1.0),
    ("2 LT 2", 0.0),
    ("2 LE 2", 1.0),
    ("BIN[4660]", 1234.0),  # 4660 = 0x1234
    ("BCD[1234]", 4660.0),
    ("BCD[99]", 153.0),  # 0x99
    ("2+3*4", 14.0),
    ("[2+3]*4", 20.0),
    ("10-2-3", 5.0),
    ("8/2/2", 2.0),
    ("-2*3", -6.0),
    ("2*-3", -6.0),
    ("1+2 EQ 3", 1.0),
    ("[[[[1+1]]]]", 2.0),  # 4 levels of brackets
    ("3.", 3.0),
    (".5+.5", 1.0),
]


@pytest.mark.parametrize("expr,expected", FUNCTIONS)
def test_function_and_operator_values(expr: str, expected: float) -> None:
    assert value(expr) == pytest.approx(expected, abs=1e-9)


VACANT = [
    ("#1", None),  # a plain reference keeps vacant
    ("[#1]", None),
    ("#0", None),
    ("#1*5", 0.0),  # arithmetic reads vacant as 0
    ("#1+#1", 0.0),
    ("-#1", 0.0),
    ("SQRT[#1]", 0.0),
    ("#1 EQ #0", 1.0),  # EQ/NE tell vacant from 0
    ("#1 EQ 0", 0.0),
    ("#1 NE 0", 1.0),
    ("#1 GE 0", 1.0),  # GT GE LT LE read vacant as 0
    ("#1 GT 0", 0.0),
    ("#1 LE 0", 1.0),
]


@pytest.mark.parametrize("expr,expected", VACANT)
def test_vacant_variable_rules(expr: str, expected: float | None) -> None:
    assert value(expr) == expected


def test_vacant_word_is_omitted_and_assignment_to_nothing_makes_vacant() -> None:
    ip, cmds = run("G0 X1 Y2\nG0 X#1 Y[#2] Z3\n#5=7\n#5=\nG0 X#5\n")
    assert ends(cmds) == [(1.0, 2.0, 0.0), (1.0, 2.0, 3.0)]  # X, Y omitted; no move at all
    assert 5 not in ip.vars.loc


# --- variables in words ------------------------------------------------------------------------


def test_variables_and_expressions_in_every_word() -> None:
    ip, cmds = run(
        "#10=1\n#2=250\n#24=-3\nG#10 X#24 Y[#24*2] Z-[1+1] F[#2*2]\n#3=2\nG#3 X3 Y-6 R3\nM#3\n"
    )
    lines = [c for c in cmds if isinstance(c, MOTION_TYPES)]
    assert lines[0].end == (-3.0, -6.0, -2.0)
    assert lines[0].feed == 500.0
    assert type(lines[1]).__name__ == "ArcFeed"
    assert isinstance(cmds[-1], ProgramStop) and cmds[-1].kind is StopKind.PROGRAM_END


def test_g_value_must_be_a_g_code() -> None:
    with pytest.raises(NcError, match=r"G1\.25 is not a G code") as ei:
        run("#1=1.25\nG#1 X1\n")
    assert (ei.value.line, ei.value.col) == (2, 1)


def test_n_cannot_be_a_variable() -> None:
    with pytest.raises(NcError, match="N .sequence number. cannot be a variable"):
        run("N#1 G0 X1\n")


# --- control flow ------------------------------------------------------------------------------


def test_while_loop_sums_one_to_ten() -> None:
    ip, _ = run("#1=1\n#100=0\nWHILE [#1 LE 10] DO1\n#100=#100+#1\n#1=#1+1\nEND1\nM30\n")
    assert ip.vars.common[100] == 55.0


def test_three_nested_loops() -> None:
    prog = """#100=0
#1=0
WHILE [#1 LT 2] DO1
#2=0
WHILE [#2 LT 3] DO2
#3=0
WHILE [#3 LT 4] DO3
#100=#100+1
#3=#3+1
END3
#2=#2+1
END2
#1=#1+1
END1
"""
    ip, _ = run(prog)
    assert ip.vars.common[100] == 24.0


def test_while_false_skips_to_after_end() -> None:
    ip, cmds = run("#1=5\nWHILE [#1 LT 3] DO1\nG0 X99\nEND1\nG0 X1\n")
    assert ends(cmds) == [(1.0, 0.0, 0.0)]


def test_if_goto_if_then_and_goto_with_an_expression() -> None:
    prog = """#1=3
IF [#1 EQ 3] GOTO 20
G0 X99
N20 IF [#1 GT 2] THEN #2=7
IF [#1 LT 2] THEN #3=7
#5=40
GOTO #5-10
N40 G0 X98
N30 G0 X1
IF [#1 GT 0] AND [#2 EQ 7] GOTO 50
G0 X97
N50 G0 X2
"""
    ip, cmds = run(prog)
    assert ends(cmds) == [(1.0, 0.0, 0.0), (2.0, 0.0, 0.0)]
    assert ip.vars.loc.get(2) == 7.0 and 3 not in ip.vars.loc


def test_goto_backward_loop_and_do_without_while() -> None:
    ip, cmds = run("#1=0\nN5 #1=#1+1\nG0 X#1\nIF [#1 LT 3] GOTO5\nM30\n")
    assert [e[0] for e in ends(cmds)] == [1.0, 2.0, 3.0]
    ip, cmds = run("#1=0\nDO1\n#1=#1+1\nIF [#1 GE 4] GOTO9\nEND1\nN9 G0 X#1\n")
    assert ends(cmds) == [(4.0, 0.0, 0.0)]


def test_goto_out_of_a_loop_then_the_same_loop_number_again() -> None:
    prog = """#1=0
WHILE [1 EQ 1] DO1
#1=#1+1
IF [#1 EQ 2] GOTO 10
END1
N10 #2=0
WHILE [#2 LT 3] DO1
#2=#2+1
END1
G0 X#1 Y#2
"""
    _, cmds = run(prog)
    assert ends(cmds) == [(2.0, 3.0, 0.0)]


def test_loops_in_a_real_file_and_in_a_list(tmp_path) -> None:
    text = "#1=0\nWHILE [#1 LT 3] DO1\nG0 X#1\n#1=#1+1\nEND1\nM30\n"
    p = tmp_path / "loop.nc"
    p.write_text(text)
    with open(p) as fh:
        a = ends(Interpreter(MILL, file=str(p)).run(fh))
    b = ends(Interpreter(MILL).run(text.splitlines()))
    assert a == b == [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0)]


# --- calls ----------------------------------------------------------------------------------------

ARGS_SUB = """O9010
#33=1
WHILE [#33 LE 26] DO1
#[100+#33]=#[#33]
#33=#33+1
END1
M99
"""


def test_g65_argument_specification_i() -> None:
    prog = (
        "#1=99\nG65 P9010 A1 B2 C3 I4 J5 K6 D7 E8 F9 H11 M13 Q17 R18 S19 T20 U21 V22 "
        "W23 X24 Y25 Z26\nG0 X#1\nM30\n" + ARGS_SUB
    )
    ip, cmds = run(prog)
    got = {k - 100: v for k, v in ip.vars.common.items() if 101 <= k <= 126}
    want = {n: float(n) for n in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 13, 17, 18, 19, 20, 21, 22,
                                  23, 24, 25, 26)}  # fmt: skip
    assert got == want
    assert ends(cmds) == [(99.0, 0.0, 0.0)]  # the caller's #1 is its own again
    assert ip.vars.depth == 0


def test_g65_repeats_and_m98_shares_locals() -> None:
    prog = """#100=0
G65 P9011 L3 A2
#1=5
M98 P9012
G0 X#1
M30
O9011
#100=#100+#1
M99
O9012
#1=#1*2
M99
"""
    ip, cmds = run(prog)
    assert ip.vars.common[100] == 6.0
    assert ends(cmds) == [(10.0, 0.0, 0.0)]  # M98 has no local level of its own


def test_g66_calls_after_every_move_until_g67() -> None:
    prog = """#100=0
G66 P9020 A1
G0 X1
G0 X2
G67
G0 X3
M30
O9020
#100=#100+#1
#101=#5001
M99
"""
    ip, cmds = run(prog)
    assert ip.vars.common[100] == 2.0
    assert ip.vars.common[101] == 2.0
    assert [e[0] for e in ends(cmds)] == [1.0, 2.0, 3.0]


def test_m99_p_returns_to_a_sequence_number_and_m98_q_enters_at_one() -> None:
    prog = """M98 P9030 Q5
N10 G0 X1
N20 G0 X2
M30
O9030
G0 X50
N5 G0 X51
M99 P20
"""
    _, cmds = run(prog)
    assert [e[0] for e in ends(cmds)] == [51.0, 2.0]


def test_g54_before_g65_and_m_as_argument() -> None:
    prog = "G55 G65 P9040 M0.07 T13.5\nM30\nO9040\n#100=#13\n#101=#20\n#102=#4014\nM99\n"
    ip, _ = run(prog)
    assert (ip.vars.common[100], ip.vars.common[101], ip.vars.common[102]) == (0.07, 13.5, 55.0)


def test_subprogram_file_checked_alone_ends_at_m99() -> None:
    sub = "%\nO9050\nG0 X1\nM99\n%\n"
    assert check(sub, MILL) == []
    errs = check("O1\nG0 X1\nM99\nG0 X2\nM30\n", MILL)
    assert "M99 in the main program" in errs[0].message


# --- system variables -----------------------------------------------------------------------------


def test_position_and_modal_variables() -> None:
    prog = """G54 G90 G1 X10 Y20 Z-5 F300
T5
#100=#5001
#101=#5022
#102=#4001
#103=#4003
#104=#4006
#105=#4120
#106=#4109
G91
#107=#4003
"""
    ip, _ = run(prog, work_offsets={1: (-100.0, -200.0, -300.0)})
    c = ip.vars.common
    assert (c[100], c[101], c[102], c[103], c[104], c[105], c[106], c[107]) == (
        10.0, -180.0, 1.0, 90.0, 21.0, 5.0, 300.0, 91.0
    )  # fmt: skip


def test_tool_and_work_offset_variables_read_and_write() -> None:
    prog = "#100=#2001\n#2001=50\n#101=#2401\n#100=#100+#5221\n#5221=-100\nG0 X0\n"
    ip, cmds = run(
        prog,
        tools={1: ToolOffset(length=120.0, radius=4.0)},
        work_offsets={1: (-10.0, 0.0, 0.0)},
    )
    assert ip.vars.common[100] == 110.0
    assert ip.vars.common[101] == 4.0
    assert ip._tools[1].length == 50.0
    assert ends(cmds) == [(-100.0, 0.0, 0.0)]  # machine X of work X0 under the new G54


def test_haas_tool_timers_read_zero_and_are_read_only() -> None:
    # Haas #5401-#5500 feed time / #5501-#5600 total time of tool 1..100, seconds: a
    # tool-life check (gcw-haas: IF [#5405 GE 6000] THEN #3000=15) sees fresh tools.
    ip, _ = run("#100=#5405\n#101=#5600\nIF [#5405 GE 6000] THEN #3000=15\n")
    assert (ip.vars.common[100], ip.vars.common[101]) == (0.0, 0.0)
    with pytest.raises(NcError, match="#5405"):
        run("#5405=1\n")
    with pytest.raises(NcError, match="PS0115 variable #5601 does not exist"):
        run("#100=#5601\n")


def test_timers_from_the_injected_clock() -> None:
    now = [100.0]
    prog = "#3001=0\n#3002=1\n#100=#3001\n#101=#3002\n"
    ip = Interpreter(MILL, clock=lambda: now[0])
    gen = ip.run(prog)
    list(gen)
    assert ip.vars.common[100] == 0.0 and ip.vars.common[101] == 1.0
    now[0] = 102.5
    assert ip.vars.get(3001) == pytest.approx(2500.0)


def test_persistent_variables_survive_a_new_interpreter_common_ones_do_not() -> None:
    store: dict[int, float] = {}
    run("#500=7\n#100=3\n#10100=2\n", macro_variables=store)
    assert store == {500: 7.0, 10100: 2.0}
    ip, _ = run("#1=#500\n#2=#100\n", macro_variables=store)
    assert ip.vars.loc == {1: 7.0}  # #100 is vacant after the "power cycle"
    run("#500=#0\n", macro_variables=store)
    assert 500 not in store  # vacant is an absent key
    common: dict[int, float] = {}
    run("#100=3\n", common_variables=common)
    ip, _ = run("#1=#100\n", common_variables=common)
    assert ip.vars.loc == {1: 3.0} and common == {100: 3.0}


def test_fanuc_30i_added_common_variables() -> None:
    # A Kitamura HMC's macros (O919100) read sensor data from #901057..#901064: the 30i-B
    # added common variables, #100000-#199999 cleared like #100-#499, #500000-#999999 kept.
    store: dict[int, float] = {}
    common: dict[int, float] = {}
    run("#100000=1\n#199999=2\n#500000=3\n#901064=-412.5\n#999999=5\n",
        macro_variables=store, common_variables=common)  # fmt: skip
    assert common == {100000: 1.0, 199999: 2.0}
    assert store == {500000: 3.0, 901064: -412.5, 999999: 5.0}
    ip, _ = run("#26=#901064\n#1=#100000\n", macro_variables=store)
    assert ip.vars.loc == {26: -412.5}  # #100000 vacant after the "power cycle"
    for n in (200000, 499999, 1000000):  # between and beyond the added ranges
        with pytest.raises(NcError, match=f"PS0115 variable #{n} does not exist"):
            run(f"#1=#{n}\n")
    from cnc.machine_data import MachineData

    md = MachineData.from_dict({"macro_variables": {"901064": -412.5}})
    assert md.macro_variables[901064] == -412.5  # kept in the machine data too


def test_3006_stops_with_a_message() -> None:
    ip, cmds = run("G0 X1\n#3006=1 (CHECK THE PART)\nG0 X2\n")
    stops = [c for c in cmds if isinstance(c, ProgramStop)]
    assert stops[0].kind is StopKind.PROGRAM_STOP and stops[0].line == 2
    assert ip.messages == [(2, "CHECK THE PART")]


# --- bad input: each a clear error with line, column and alarm ---------------------------------

BAD = [
    ("#1=1/0\n", 1, 5, "PS0112 division by zero"),
    ("#1=5 MOD 0\n", 1, 6, "PS0112 MOD by zero"),
    ("#0=1\n", 1, 1, "PS0116 #0 is always vacant"),
    ("#5001=1\n", 1, 1, "PS0116 #5001 is read only"),
    ("#1=#9999\n", 1, 4, "PS0115 variable #9999 does not exist"),
    ("#1=SQRT[-1]\n", 1, 4, "PS0119 SQRT[-1]: argument out of range"),
    ("#1=ASIN[2]\n", 1, 4, "PS0119"),
    ("#1=LN[0]\n", 1, 4, "PS0119"),
    ("#1=[[[[[[1]]]]]]\n", 1, 9, "PS0118 more than 5 levels"),
    ("#1=2+\n", 1, 6, "PS0114 expression expected"),
    ("#1=FOO[1]\n", 1, 4, "PS0114 unknown function"),
    ("G0 X1 #1=2\n", 1, 7, "PS0127"),
    ("GOTO 50\nN40 G0 X1\n", 1, 1, "PS0128 GOTO 50: sequence number N50 not found"),
    ("GOTO #1\n", 1, 1, "PS0128 GOTO vacant"),
    ("WHILE [1 EQ 2] DO1\nG0 X1\n", 1, 1, "PS0124 WHILE ... DO 1 without END 1"),
    ("WHILE [#1 LT 1] DO1\n#1=#1+1\n", 1, 1, "PS0124 DO 1 without END 1"),
    ("END1\n", 1, 1, "PS0126 END 1 without a matching DO 1"),
    ("DO4\n", 1, 3, "PS0126 loop number 4 is not 1, 2 or 3"),
    (
        "DO1\nDO2\nDO3\nDO1\nEND1\nEND3\nEND2\nEND1\n",
        4,
        1,
        "PS0126 DO 1 inside the open loop DO 1 of line 1",
    ),
    ("G65 P9999 A1\n", 1, 5, "PS0076 G65: program O9999 not found"),
    ("M98 P9999\n", 1, 5, "PS0076 M98: program O9999 not found"),
    ("M99 P77\n", 1, 5, "PS0078 M99 P 77: sequence number N77 not found"),
    ("#3000=15 (SPINDLE NOT READY)\n", 1, 1, "3015 macro alarm: SPINDLE NOT READY"),
    ("#3000=201\n", 1, 1, "PS0119 #3000 = 201"),
    ("G65 P9000 G1\nM30\nO9000\nM99\n", 1, 11, "PS0129 G1 after G65 (G is not a macro argument)"),
]


@pytest.mark.parametrize("text,line,col,fragment", BAD)
def test_bad_macro_input_names_line_column_and_alarm(
    text: str, line: int, col: int, fragment: str
) -> None:
    with pytest.raises(NcError) as ei:
        list(Interpreter(MILL, file="bad.nc").run(text))
    err = ei.value
    assert fragment in err.message
    assert (err.file, err.line, err.col) == ("bad.nc", line, col), str(err)


def test_bad_macro_input_through_check_is_reported_once_never_hangs() -> None:
    for text, line, col, fragment in BAD:
        errs = check(text, MILL, file="bad.nc", max_blocks=100_000)
        assert errs, text
        assert fragment in errs[0].message and (errs[0].line, errs[0].col) == (line, col)


def test_endless_loops_are_alarms_with_their_line() -> None:
    # no variable or position ever changes: found by the repeated state
    errs = check("N1 #1=1\nGOTO1\n", MILL, file="loop.nc")
    assert len(errs) == 1 and "endless loop: the jump back to line 1" in errs[0].message
    assert (errs[0].line, errs[0].col) == (2, 1)
    errs = check("WHILE [1 EQ 1] DO1\nG4 P1\nEND1\n", MILL)
    assert "endless loop" in errs[0].message and errs[0].line == 3
    # a variable that keeps counting: the macro budget
    errs = check("#1=0\nWHILE [1 EQ 1] DO1\n#1=#1+1\nEND1\n", MILL, macro_budget=5000)
    assert "macro budget" in errs[0].message and errs[0].line in (2, 3, 4)
    # moves that keep going: the block budget
    errs = check("G91\nWHILE [1 EQ 1] DO1\nG0 X1\nEND1\n", MILL, max_blocks=5000)
    assert "more than 5000 blocks" in errs[0].message


def test_macro_recursion_is_refused_at_the_nesting_limit() -> None:
    errs = check("G65 P9000\nM30\nO9000\nG65 P9000\nM99\n", MILL)
    assert errs[0].message.startswith("PS0122 macro calls nested deeper than 5")
    assert errs[0].line == 4


def test_goto_in_a_streamed_program_is_ps0123() -> None:
    gen = (ln for ln in ["N1 G0 X1", "GOTO1"])
    with pytest.raises(NcError, match="PS0123") as ei:
        list(Interpreter(MILL).run(gen))
    assert ei.value.line == 2
    # a WHILE whose condition is false skips forward even in a stream
    gen = (ln for ln in ["WHILE [1 EQ 2] DO1", "G0 X9", "END1", "G0 X1"])
    assert ends(Interpreter(MILL).run(gen)) == [(1.0, 0.0, 0.0)]


def test_macro_lines_are_parsed_once() -> None:
    from cnc.gcode.lexer import parse_line

    a = parse_line("#1=#1+1", 7, "x.nc")
    b = parse_line("#1=#1+1", 7, "x.nc")
    assert a is b


def test_the_docs_bolt_hole_example_runs() -> None:
    import re
    from pathlib import Path

    doc = (Path(__file__).parents[2] / "docs" / "gcode.md").read_text()
    body = re.search(r"```\n(O9001 \(BOLT HOLE CIRCLE.*?)```", doc, re.S).group(1)
    call = re.search(r"called by `(G65 P9001[^`]*)`", doc).group(1)
    ip, cmds = run(f"G90 G17 G54\nG0 Z50\n{call}\nM30\n{body}")
    holes = [c.end for c in cmds if isinstance(c, MOTION_TYPES) and c.end[2] == -10.0]
    want = [
        (50 + 30 * math.cos(math.radians(a)), 40 + 30 * math.sin(math.radians(a)), -10.0)
        for a in range(0, 360, 60)
    ]
    assert len(holes) == 6
    for got, exp in zip(holes, want, strict=True):
        assert got == pytest.approx(exp, abs=1e-9)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(
        st.sampled_from(
            [
                "#1",
                "#2",
                "#0",
                "#100",
                "#[#1]",
                "=",
                "[",
                "]",
                "+",
                "-",
                "*",
                "/",
                "1",
                "2.5",
                "0",
                " ",
                "IF",
                "GOTO",
                "WHILE",
                "DO1",
                "END1",
                "THEN",
                "EQ",
                "LT",
                "SIN",
                "ATAN",
                "POW",
                ",",
                "G1",
                "X",
                "N1",
                "M99",
                "G65",
                "P9",
                "MOD",
                "AND",
                "#3000",
                "(A)",
            ]
        ),
        max_size=12,
    ),
    st.integers(1, 4),
)
def test_random_macro_programs_end_with_an_error_or_normally(parts, lines) -> None:
    """Never a crash (only NcError) and never a hang (the budgets), whatever the text."""
    text = "\n".join("".join(parts[i::lines]) for i in range(lines)) + "\nN9 M30\n"
    errs = check(text, MILL, max_blocks=20_000, macro_budget=20_000)
    assert all(isinstance(e, NcError) for e in errs)


def test_lathe_positions_in_diameter_and_tool_geometry() -> None:
    axes = (
        AxisParams("X", -1e6, 1e6, 30000, 3000, 5e4),
        AxisParams("Z", -1e6, 1e6, 30000, 3000, 5e4),
    )
    lathe = MachineParams(kind="lathe", axes=axes)
    ip = Interpreter(lathe, tools={1: ToolOffset(x=2.0, z=-3.0, radius=0.4)})
    list(ip.run("G0 X40 Z5\n#100=#5001\n#101=#5003\n#102=#2701\n#103=#2801\n#104=#2901\n"))
    c = ip.vars.common
    assert (c[100], c[101], c[102], c[103], c[104]) == (40.0, 5.0, 4.0, -3.0, 0.4)


# --- the builder's variable map (macro_variable_map) ------------------------------------------

KITAMURA = MachineParams(axes=BIG, macro_variable_map="kitamura")


@pytest.mark.parametrize(
    ("params", "prog", "common"),
    [
        # Haas NGC map (default): #10002 is a kept common variable, #4012 the G66/G67 group
        (MILL, "#10002=7\n#100=#10002\n#101=#4012\n", {100: 7.0, 101: 67.0}),
        # Kitamura (the shop's note): #4012 the work coordinate system, #10000+n the length
        # of tool offset n, #11000+n its wear (reads 0)
        (KITAMURA, "G55\n#100=#4012\n#101=#10002\n#102=#11002\n", {100: 55.0, 101: 120.0,
                                                               102: 0.0}),
        (KITAMURA, "G54.1 P3\n#100=#4012\n", {100: 54.1}),
        (KITAMURA, "#10002=98.5\n#11002=0\n#100=#10002\n#101=#2002\n", {100: 98.5,
                                                                      101: 98.5}),
        # a wear variable takes 0 on either map (the offset keeps one value)
        (MILL, "#2202=0\n#100=#2002\n", {100: 120.0}),
    ],
)  # fmt: skip
def test_builder_variable_maps(params: MachineParams, prog: str, common: dict) -> None:
    tools = {2: ToolOffset(length=120.0, radius=40.0)}
    store: dict[int, float] = {}
    ip = Interpreter(params, tools=tools, macro_variables=store)
    list(ip.run(prog))
    assert dict(ip.vars.common) == common
    assert ip._tools[2].radius == 40.0  # a length write leaves the radius
    if params is MILL and "#10002" in prog:
        assert store == {10002: 7.0}  # kept across power cycles (Haas NGC)
    if params is KITAMURA:
        assert store == {}  # tool memory, not common variables


@pytest.mark.parametrize(
    ("params", "prog", "alarm"),
    [
        (KITAMURA, "#11002=0.1\n", "PS0116 #11002: wear offsets are not kept"),
        (MILL, "#2202=0.1\n", "PS0116 #2202: wear offsets are not kept"),
        (MILL, "#11002=0\n", "PS0115 variable #11002 does not exist"),
        (KITAMURA, "#4012=54\n", "PS0116 #4012 is read only"),
    ],
)
def test_builder_variable_map_refusals(params: MachineParams, prog: str, alarm: str) -> None:
    with pytest.raises(NcError, match=alarm):
        list(Interpreter(params).run(prog))
