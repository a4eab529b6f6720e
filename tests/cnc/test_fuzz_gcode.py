"""Fuzz: random text and random valid-looking programs give canonical commands or NcError,
and `Interpreter.run()` agrees with `check()` on where the first error is.

Nothing else may escape (no IndexError, ZeroDivisionError, RecursionError...), and every
example finishes in bounded time (pytest-timeout guards the whole test; the interpreter is
run with a block budget so runaway subprogram repeats end with an NcError).
"""

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.errors import NcError
from cnc.interp import Interpreter, ToolOffset, check
from cnc.params import AxisParams, DecimalStyle, MachineParams

BIG = tuple(AxisParams(a, -500, 500, 30000, 3000, 5e4) for a in "XYZ")
PARAMS = [
    MachineParams(axes=BIG),
    MachineParams(axes=BIG, decimal_style=DecimalStyle.LEAST_INCREMENT),
    MachineParams(
        kind="lathe",
        axes=(AxisParams("X", -500, 500, 1, 1, 1), AxisParams("Z", -500, 500, 1, 1, 1)),
    ),
]
TOOLS = {1: ToolOffset(10.0, 3.0, 0.5, -0.5), 2: ToolOffset(-5.0, 0.0)}

G_CODES = ["0", "1", "2", "3", "4", "9", "10", "15", "16", "17", "18", "19", "20", "21", "28",
           "30", "40", "41", "42", "43", "44", "49", "50", "50.1", "51", "51.1", "53", "54", "55",
           "59", "61", "64", "65", "68", "69", "73", "74", "76", "80", "81", "82", "83", "84",
           "85", "86", "87", "88", "89", "90", "90.1", "91", "91.1", "92", "94", "95", "96",
           "97", "98", "99", "5", "33"]  # fmt: skip
M_CODES = ["0", "1", "2", "3", "4", "5", "6", "7", "8", "9", "19", "30", "98", "99", "60"]
LETTERS = "XYZIJKRFSTPQLHDUWEAN"

number = st.one_of(
    st.integers(-2000, 2000).map(str),
    st.floats(-600, 600, allow_nan=False, allow_infinity=False).map(lambda v: f"{v:.3f}"),
    st.sampled_from(["0", ".5", "-.5", "1.", "0000", "+3", "1e5", "--1", "1.2.3", ""]),
    st.integers(-(10**40), 10**40).map(str),
)
word = st.one_of(
    st.builds(lambda g: "G" + g, st.sampled_from(G_CODES)),
    st.builds(lambda m: "M" + m, st.sampled_from(M_CODES)),
    st.builds(lambda a, n: a + n, st.sampled_from(LETTERS), number),
    st.sampled_from(["(comment)", "(open", ")", ";x", "/", "%", "#1", "[", "O12", ":7", "\t"]),
)
block = st.lists(word, min_size=0, max_size=7).map(" ".join)
program = st.lists(block, min_size=1, max_size=25).map("\n".join)
coord = st.integers(-3000, 3000).map(lambda v: f"{v / 10}")
structured_block = st.one_of(
    st.builds(lambda g, x, y, z: f"{g} X{x} Y{y} Z{z} F300",
              st.sampled_from(["G0", "G1", "G90 G1", "G91 G1"]), coord, coord, coord),
    st.builds(lambda g, x, y, r: f"{g} X{x} Y{y} R{r} F200",
              st.sampled_from(["G2", "G3"]), coord, coord, coord),
    st.builds(lambda g, x, y, i, j: f"{g} X{x} Y{y} I{i} J{j} F200",
              st.sampled_from(["G2", "G3", "G17 G2", "G18 G3", "G19 G2"]), coord, coord, coord,
              coord),
    st.builds(lambda c, x, z, r, q, k: f"{c} X{x} Z{z} R{r} Q{q} K{k} F100 P100",
              st.sampled_from(["G73", "G74", "G76", "G81", "G82", "G83", "G84", "G85", "G86",
                               "G87", "G88", "G89", "G98 G81", "G99 G83"]),
              coord, coord, coord, st.integers(0, 50).map(str), st.integers(0, 5).map(str)),
    st.sampled_from(["G80", "G40", "G41 D1", "G42 D1", "G43 H1", "G49", "G51 P2", "G50",
                     "G68 R30", "G69", "G51.1 X0", "G50.1", "G16", "G15", "G54", "G55",
                     "G10 L2 P2 X5", "G92 X0", "G28 Z0", "G53 G0 X0", "M98 P1", "M98 P3 L2",
                     "S500 M3", "M8", "M9", "T1 M6", "G95", "G94", "G96 S100", "G97 S200",
                     "G20", "G21", "G61", "G64 P0.1", "G4 P10", "M0", "M1", "M60", "M99"]),
)  # fmt: skip
structured = st.lists(structured_block, min_size=1, max_size=30).map("\n".join)
SUBS = {
    1: "O1\nG91 G1 X1 F100\nG90\nM99\n",
    2: "O2\nM98 P2\nM99\n",
    3: ["O3", "G0 X5", "M98 P1 L3", "M99"],
}


def _where(err: NcError) -> tuple[str, int, int, str]:
    return (err.file, err.line, err.col, err.message)


def _run_all(text: str, params: MachineParams) -> None:
    """Run the program, then check it, and hold the two to each other: `run()` stops at
    exactly the first error `check()` reports (same file, line, column and message), and a
    program `run()` completes is one `check()` finds nothing wrong with. The checker is the
    interpreter in recovery mode, so up to the first error the two must agree block for
    block; a difference is a state the recovery path leaks backwards or a run that stops
    (or carries on) where the checker does not."""
    interp = Interpreter(params, programs=SUBS, tools=TOOLS, max_blocks=20_000)
    stopped: NcError | None = None
    commands = []
    try:
        for cmd in interp.run(text):
            commands.append(cmd)
    except NcError as err:
        assert err.line >= 0 and err.col >= 0 and err.message
        stopped = err
    _ = interp.state  # the snapshot works in any state
    # the checker set up as the run: an M99 in the main program is refused (subprogram=False,
    # the interpreter's default; `check` alone decides that by the file)
    errs = check(text, params, programs=SUBS, tools=TOOLS, max_blocks=20_000, subprogram=False)
    assert all(isinstance(e, NcError) for e in errs)
    if stopped is None:
        assert errs == [], f"run() completed, check() reports {errs[0]}"
    else:
        assert errs, f"run() stopped at {stopped}, check() reports nothing"
        assert _where(errs[0]) == _where(stopped), (
            f"run() stopped at {stopped}, check() reports {errs[0]} first"
        )
    # a second run of the same text on a fresh interpreter gives the same commands and stop
    again = Interpreter(params, programs=SUBS, tools=TOOLS, max_blocks=20_000)
    replay = []
    try:
        for cmd in again.run(text):
            replay.append(cmd)
    except NcError as err:
        assert stopped is not None and _where(err) == _where(stopped)
    else:
        assert stopped is None
    assert replay == commands


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program, st.sampled_from(PARAMS))
def test_fuzz_valid_looking_programs(text: str, params: MachineParams) -> None:
    _run_all(text, params)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(structured, st.sampled_from(PARAMS))
def test_fuzz_structured_programs(text: str, params: MachineParams) -> None:
    _run_all(text, params)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=400), st.sampled_from(PARAMS))
def test_fuzz_random_text(text: str, params: MachineParams) -> None:
    _run_all(text, params)


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_random_bytes_as_latin1(data: bytes) -> None:
    _run_all(data.decode("latin-1"), PARAMS[0])
