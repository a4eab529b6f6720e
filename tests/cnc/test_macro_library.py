"""Programs across files: `nc check --library DIR` resolves M98 P / G65 P by O number, a
file ending in M99 is checked as a subprogram; the corpus Macro B programs that call each
other (../shared/reference/corpus/gcode, SOURCES.md)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cnc.gcode.source import library_programs
from cnc.interp import Interpreter, check
from cnc.params import AxisParams, MachineParams
from server.cli import app
from tests.reference import GCODE_CORPUS, MISSING

runner = CliRunner()
BIG = tuple(AxisParams(a, -1e6, 1e6, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
corpus = pytest.mark.skipif(not GCODE_CORPUS.is_dir(), reason=MISSING)


def errors_of(res) -> list[str]:
    """The error lines of `nc check` (its warnings, e.g. the power-on unit, go to stderr)."""
    return [ln for ln in res.output.splitlines() if ": warning: " not in ln]


def write(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.write_text(text)
    return p


def test_library_resolves_m98_and_g65_by_o_number(tmp_path: Path) -> None:
    lib = tmp_path / "lib"
    lib.mkdir()
    write(lib, "drill.nc", "%\nO1000 (DRILL)\nG91 G0 X1\nG90\nM99\n%\n")
    write(lib, "calc.nc", "%\nO9001\n#100=#1*2\nG0 X#100\nM99\n%\n")
    main = write(tmp_path, "main.nc", "%\nO1\nG0 X0 Y0\nM98 P1000 L2\nG65 P9001 A5\nM30\n%\n")
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(main)])
    assert res.exit_code == 1 and "PS0076 M98: program O1000 not found" in res.output
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", "--library", str(lib), str(main)])
    assert res.exit_code == 0, res.output
    programs, warnings = library_programs(str(lib))
    assert sorted(programs) == [1000, 9001] and warnings == []


def test_error_inside_a_library_program_names_that_file(tmp_path: Path) -> None:
    lib = tmp_path / "lib"
    lib.mkdir()
    sub = write(lib, "sub.nc", "O2000\nG0 X1\n#1=1/0\nM99\n")
    main = write(tmp_path, "main.nc", "O1\nM98 P2000\nM30\n")
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", "--library", str(lib), str(main)])
    assert res.exit_code == 1
    assert errors_of(res) == [f"{sub}:3:5: PS0112 division by zero"]


def test_a_subprogram_file_is_checked_in_subprogram_mode(tmp_path: Path) -> None:
    sub = write(tmp_path, "o1000.nc", "%\nO1000\nG0 X-1\nM99\n%\n")
    res = runner.invoke(app, ["nc", "check", str(sub)])
    assert res.exit_code == 0, res.output
    main = write(tmp_path, "bad.nc", "%\nO1\nG0 X-1\nM99\nG0 X-2\nM30\n%\n")
    res = runner.invoke(app, ["nc", "check", str(main)])
    assert res.exit_code == 1 and "M99 in the main program" in res.output


def test_duplicate_o_numbers_warn_and_the_first_file_wins(tmp_path: Path) -> None:
    write(tmp_path, "a.nc", "O5\nM99\n")
    write(tmp_path, "b.nc", "O5\nM99\n")
    programs, warnings = library_programs(str(tmp_path))
    assert programs[5].name.endswith("a.nc")
    assert len(warnings) == 1 and "O5 is also in" in warnings[0] and "b.nc:1:1" in warnings[0]


def test_library_must_be_a_folder(tmp_path: Path) -> None:
    main = write(tmp_path, "m.nc", "G0 X-1\n")
    res = runner.invoke(app, ["nc", "check", "--library", str(tmp_path / "nope"), str(main)])
    assert res.exit_code == 2


# --- the corpus ----------------------------------------------------------------------------------


@corpus
def test_payne_o2001_calls_o9001_across_files() -> None:
    """G65 P9001 A.125 C.625 V10100.: O9001 stores SQRT[C*C - A*A] in #[V] (#10100)."""
    programs, _ = library_programs(str(GCODE_CORPUS))
    store: dict[int, float] = {}
    path = GCODE_CORPUS / "payne-o2001-arcs.nc"
    with open(path, encoding="latin-1") as fh:
        errs = check(fh, MILL, file=str(path), programs=programs, macro_variables=store)
    assert store[10100] == pytest.approx(math.sqrt(0.625**2 - 0.125**2))
    # what is left is not Macro B: a ':' line with no program number (line 23), Fanuc PS0005
    assert [(e.line, e.message) for e in errs] == [
        (23, "PS0005 program number ':' (the ISO form of O) needs digits")
    ]
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(path)])
    assert "PS0076 G65: program O9001 not found" in res.output


@corpus
def test_payne_o9001_alone_is_a_subprogram_whose_v_argument_is_vacant() -> None:
    path = GCODE_CORPUS / "payne-o9001-macro.nc"
    res = runner.invoke(app, ["nc", "check", str(path)])
    # checked on its own, V (#22) is vacant: #[#22] is #0, which cannot be written
    assert errors_of(res) == [f"{path}:7:1: PS0116 #0 is always vacant (read only)"]


@corpus
def test_moji_tool_measuring_calls_o919100_across_files() -> None:
    path = GCODE_CORPUS / "moji-o917100-toolmeas.nc"
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(path)])
    assert errors_of(res)[0] == f"{path}:8:5: PS0076 G65: program O919100 not found"
    res = runner.invoke(
        app, ["nc", "check", "--no-soft-limits", "--library", str(GCODE_CORPUS), str(path)]
    )
    lines = [ln for ln in errors_of(res) if "warning" not in ln]
    # O919100 runs, reads the 30i-B added common variable #901064 (vacant here) and moves
    # G91 G53 by the increment; its first refusal, in its own file: the feed #650 that only
    # its shop presets is vacant
    callee = GCODE_CORPUS / "moji-o919100-macro.nc"
    assert lines[0] == f"{callee}:11:1: feed move without F"


class _Writes(dict):
    """A tool memory that notes the offset numbers written."""

    written: list[int]

    def __setitem__(self, key, value) -> None:
        self.written.append(key)
        super().__setitem__(key, value)


@corpus
def test_moji_tool_measuring_on_the_kitamura_stores_the_length_in_its_tool_memory() -> None:
    """On the shop's Kitamura (corpus_setups/moji-kitamura-toolsetter.yaml, its variable map
    `kitamura`) O917100 measures T02 through O919100: #4012 is G54, so #[5223+[#4012-54]*20]
    is the G54 Z (-300 on mill3) and the length written to #10002 (the tool memory, not a
    common variable) is the tool's own 120 mm; #11002=0 clears the wear."""
    from cnc.cli_setup import machine_setup  # deferred: the configuration is heavy to load

    setup = machine_setup(
        config=Path(__file__).with_name("corpus_setups") / "moji-kitamura-toolsetter.yaml"
    )
    programs, _ = library_programs(str(GCODE_CORPUS))
    md = setup.machine_data
    ip = Interpreter(setup.params, machine_data=md, macro_variables=md.macro_variables,
                     programs=programs)  # fmt: skip
    tools = _Writes(ip._tools)
    tools.written = []
    ip._tools = tools
    path = GCODE_CORPUS / "moji-o917100-toolmeas.nc"
    with open(path, encoding="latin-1") as fh:
        assert ip.check_all(fh) == []
    assert tools.written == [2] and tools[2].length == pytest.approx(120.0)
    assert 10002 not in md.macro_variables


@corpus
def test_moji_o410000_alone_stops_at_its_own_argument_alarm() -> None:
    path = GCODE_CORPUS / "moji-o410000-sub.nc"
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(path)])
    assert errors_of(res) == [f"{path}:122:1: 3100 macro alarm: are the arguments OK?"]


@corpus
def test_versa_programs() -> None:
    wait = GCODE_CORPUS / "versa-haasngc-o9001.nc"
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(wait)])
    # the robot handshake polls #10000 for ever when no robot writes it: found at once
    assert f"{wait}:33:1: endless loop: the jump back to line 29" in res.output
    focas = GCODE_CORPUS / "versa-focas-o9000.nc"
    res = runner.invoke(app, ["nc", "check", str(focas)])
    assert errors_of(res) == [
        f"{focas}:24:1: 3015 macro alarm: User Cycle Start, Do not manually push cycle start"
    ]
    table = GCODE_CORPUS / "versa-o8000-tablewash.nc"
    res = runner.invoke(app, ["nc", "check", str(table)])
    assert errors_of(res)[0] == f"{table}:3:1: 3001 macro alarm: LOAD POSITION NOT SET"


@corpus
def test_sprayer_7997a_macro_lines_parse_and_its_unbracketed_arithmetic_is_refused() -> None:
    path = GCODE_CORPUS / "sprayer-7997a-plasma.nc"
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(path)])
    lines = errors_of(res)
    # IF [...] AND [...] GOTO and two assignments in a block are read; `X#114-#136` is not
    # Fanuc (an expression needs brackets: X[#114-#136])
    assert not any("PS0125" in ln for ln in lines)
    assert f"{path}:87:11: PS0114 unexpected '-'" in lines
