"""Subprograms (M98/M99, in-file O blocks and programs in memory) and streaming."""

import itertools
import tracemalloc

import pytest

from cnc.canon import MOTION_TYPES, ProgramStop, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import MAX_SUB_NESTING, Interpreter
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1e6, 1e6, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
T, F = StraightTraverse, StraightFeed

IN_FILE = """%
O0001 (MAIN)
G0 X0 Y0
M98 P1000 L2
M98 P21000
G0 X100
M30
O1000 (SUB: one step in X)
G91 G0 X1
G90
M99
%
"""


def xs(cmds) -> list[float]:
    return [c.end[0] for c in cmds if isinstance(c, MOTION_TYPES)]


def test_in_file_subprogram_from_a_list_and_a_str() -> None:
    for src in (IN_FILE, IN_FILE.splitlines()):
        cmds = list(Interpreter(MILL).run(src))
        assert xs(cmds) == [0.0, 1.0, 2.0, 3.0, 4.0, 100.0]
        assert [c.line for c in cmds if isinstance(c, T)][1:5] == [9, 9, 9, 9]


def test_in_file_subprogram_from_a_real_file(tmp_path) -> None:
    p = tmp_path / "prog.nc"
    p.write_text(IN_FILE)
    it = Interpreter(MILL, file=str(p))
    with open(p) as fh:
        cmds = list(it.run(fh))
    assert xs(cmds) == [0.0, 1.0, 2.0, 3.0, 4.0, 100.0]
    assert isinstance(cmds[-1], ProgramStop)


def test_generator_source_uses_programs_mapping_only() -> None:
    gen = (line for line in IN_FILE.splitlines())
    with pytest.raises(NcError, match="O1000 not found") as ei:
        list(Interpreter(MILL).run(gen))
    assert (ei.value.line, ei.value.col) == (4, 5)
    gen = (line for line in IN_FILE.splitlines())
    sub = "O1000\nG91 G0 X1\nG90\nM99\n"
    assert xs(Interpreter(MILL, programs={1000: sub}).run(gen)) == [0, 1, 2, 3, 4, 100]


def test_programs_mapping_with_tape_marks_and_nesting() -> None:
    progs = {
        10: "%\nO10\nG0 X10\nM98 P11\nM99\n%\n",
        11: ["O11", "G0 Y11", "M99"],
    }
    it = Interpreter(MILL, programs=progs)
    cmds = list(it.run("M98 P10\nG0 Z1\n"))
    assert [c.end for c in cmds] == [(10.0, 0.0, 0.0), (10.0, 11.0, 0.0), (10.0, 11.0, 1.0)]


def test_state_reports_subprogram_depth_and_file() -> None:
    it = Interpreter(MILL, programs={5: "O5\nG0 X5\nM99\n"}, file="main.nc")
    gen = it.run("M98 P5\nG0 X1\n")
    next(gen)
    s = it.state
    assert (s.subprogram_depth, s.file, s.line) == (1, "O5", 2)
    rest = list(gen)
    assert it.state.subprogram_depth == 0 and rest[-1].end[0] == 1.0


@pytest.mark.parametrize(
    ("prog", "programs", "fragment", "line", "col"),
    [
        ("G0 X1\nM98 P77\n", {}, "O77 not found", 2, 5),
        ("G0 X1\nM99\n", {}, "M99 in the main program", 2, 1),
        ("M98 P5\n", {5: "O5\nM98 P5\nM99\n"}, "nesting deeper", 2, 1),
        ("M98 P5\n", {5: "O5\nG0 X1\n"}, "ends without M99", 2, 1),
        ("M98\n", {}, "M98 needs P", 1, 1),
        ("M98 P5\n", {5: "O5\nM99 P10\n"}, "M99 P", 2, 5),
        ("M98 P5 L99999\n", {5: "O5\nM99\n"}, "repeat count", 1, 8),
    ],
)
def test_subprogram_errors(prog, programs, fragment, line, col) -> None:
    with pytest.raises(NcError) as ei:
        list(Interpreter(MILL, programs=programs).run(prog))
    assert fragment in ei.value.message
    assert (ei.value.line, ei.value.col) == (line, col)


@pytest.mark.parametrize(
    ("main", "programs", "called"),
    [
        # an O number of 5 to 8 digits that exists is called as such
        ("M98 P80000001\n", {80000001: "O80000001\nG91 G0 X1\nM99\n"}, [80000001]),
        ("M98 P410000 L2\n", {410000: "O410000\nG91 G0 X1\nM99\n"}, [410000, 410000]),
        # Fanuc's 4-digit format: P<repeats><O number> when no such long O number exists
        ("M98 P20010\n", {10: "O10\nG91 G0 X1\nM99\n"}, [10, 10]),
    ],
)
def test_m98_calls_eight_digit_programs(main, programs, called) -> None:
    cmds = list(Interpreter(MILL, programs=programs).run(main))
    # each call of the subprogram steps X by 1 (G91): one step per call
    assert xs(cmds) == [float(i + 1) for i in range(len(called))]


def test_m98_program_number_beyond_eight_digits_is_refused() -> None:
    with pytest.raises(NcError, match=r"M98 P123456789: program number outside 1\.\.99999999"):
        list(Interpreter(MILL).run("M98 P123456789\n"))


def test_nesting_limit_allows_exactly_the_limit() -> None:
    progs = {n: f"O{n}\nM98 P{n + 1}\nM99\n" for n in range(1, MAX_SUB_NESTING)}
    progs[MAX_SUB_NESTING] = f"O{MAX_SUB_NESTING}\nG0 X1\nM99\n"
    assert len(list(Interpreter(MILL, programs=progs).run("M98 P1\n"))) == 1


def test_max_blocks_bounds_runaway_repeats() -> None:
    progs = {1: "O1\nM98 P2 L9999\nM99\n", 2: "O2\nG91 G0 X1\nM99\n"}
    with pytest.raises(NcError, match="more than 1000 blocks"):
        list(Interpreter(MILL, programs=progs, max_blocks=1000).run("M98 P1 L9999\n"))


def test_main_program_ends_at_the_next_o_block_and_percent() -> None:
    assert xs(Interpreter(MILL).run("O1\nG0 X1\nO2\nG0 X2\n")) == [1.0]
    assert xs(Interpreter(MILL).run("%\nG0 X1\n%\nG0 X2\n")) == [1.0]


def _endless_lines():
    yield "%"
    yield "O0001"
    for i in itertools.count():
        yield f"G1 X{i % 100} Y{i % 37} F1000"


def test_streaming_is_lazy_on_an_endless_source() -> None:
    gen = Interpreter(MILL).run(_endless_lines())
    first = next(gen)
    assert isinstance(first, F) and first.line == 3
    # memory does not grow with the number of blocks consumed
    tracemalloc.start()
    for _ in itertools.islice(gen, 1000):
        pass
    base, _ = tracemalloc.get_traced_memory()
    for _ in itertools.islice(gen, 5000):
        pass
    now, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert now - base < 64 * 1024


def test_first_move_of_a_large_file_comes_before_the_file_is_read(tmp_path) -> None:
    p = tmp_path / "big.nc"
    with open(p, "w") as fh:
        fh.write("%\nO1\nG21 G90\n")
        fh.write("G1 X1 Y1 F100\n" * 200_000)  # 2.8 MB
    with open(p) as fh:
        cmd = next(Interpreter(MILL).run(fh))
        assert isinstance(cmd, F) and cmd.line == 4
        assert fh.buffer.tell() < 100_000  # only the first buffer was read (file: 2.8 MB)


@pytest.mark.parametrize(
    ("prog", "ends"),
    [
        ("PART 4711 REV B\n\n%\nG0 X1\nM30\n%\n", [1.0]),  # leader before '%' is ignored
        ("G0 X1\nM30\n%\n", [1.0]),  # no leader: the first line is a block
        ("(header)\n%\nG0 X2\n", [2.0]),
        ("%\nG0 X3\n%\nG0 X9\n", [3.0]),
    ],
)
def test_tape_leader_before_percent_is_ignored(prog, ends) -> None:
    assert xs(Interpreter(MILL).run(prog)) == ends


def test_bad_first_line_without_percent_is_still_an_error() -> None:
    with pytest.raises(NcError) as ei:
        list(Interpreter(MILL).run("PART 4711\nG0 X1\n"))
    assert ei.value.line == 1
