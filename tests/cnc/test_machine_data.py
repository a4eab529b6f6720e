"""Machine data: the pure core, G10 writing it for good, the store, the operator files."""

from __future__ import annotations

import json
import os
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cnc.canon import Spindle, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter, check
from cnc.machine_data import (
    FileErrors,
    MachineData,
    MachineDataError,
    ToolData,
    apply_files,
    load,
    offsets_csv,
    parse_offsets,
    parse_tools,
    save,
    tools_csv,
    work_offset_index,
    work_offset_name,
    write_atomically,
)
from cnc.params import AxisParams, MachineParams

BIG = 1e6
MILL = MachineParams(
    axes=tuple(AxisParams(n, -BIG, BIG, 30000.0, 3000.0, 50000.0) for n in "XYZ"),
)
LATHE = MachineParams(
    kind="lathe",
    axes=(AxisParams("X", -BIG, BIG, 2e4, 4e3, 6e4), AxisParams("Z", -BIG, BIG, 2e4, 4e3, 6e4)),
)


def run(text: str, md: MachineData, params: MachineParams = MILL) -> list:
    return list(Interpreter(params, machine_data=md).run(text))


# --- names and indices -----------------------------------------------------------------


@pytest.mark.parametrize(
    "name,index",
    [("EXT", 0), ("G54", 1), ("G59", 6), ("G54.1P1", 7), ("G54.1 P48", 54), ("P3", 9)],
)
def test_work_offset_names_and_indices(name, index) -> None:
    assert work_offset_index(name) == index
    assert work_offset_index(work_offset_name(index)) == index


@pytest.mark.parametrize("name", ["G53", "G60", "G54.1P49", "P0x", "G54.1P0 X", "foo"])
def test_bad_work_offset_names_refused(name) -> None:
    with pytest.raises(MachineDataError):
        work_offset_index(name)


# --- G10 writes the machine data ------------------------------------------------------

G10_CASES = [
    # program, what to read, expected
    ("G90 G10 L2 P1 X-300 Y-200 Z-400\n", lambda m: m.work_offsets[1], (-300, -200, -400)),
    ("G90 G10 L2 P0 Z-5\n", lambda m: m.work_offsets[0], (0, 0, -5)),
    ("G90 G10 L2 P6 X1\nG91 G10 L2 P6 X2\n", lambda m: m.work_offsets[6], (3, 0, 0)),
    ("G90 G10 L20 P1 X7\n", lambda m: m.work_offsets[7], (7, 0, 0)),
    ("G90 G10 L20 P48 Y-9\n", lambda m: m.work_offsets[54], (0, -9, 0)),
    ("G90 G10 L10 P7 R120.5\n", lambda m: m.tools[7].length, 120.5),
    ("G90 G10 L11 P7 R-0.02\n", lambda m: m.tools[7].length_wear, -0.02),
    ("G90 G10 L12 P3 R5\n", lambda m: m.tools[3].radius, 5.0),
    ("G90 G10 L13 P3 R0.01\n", lambda m: m.tools[3].radius_wear, 0.01),
    ("G90 G10 L10 P2 R100\nG91 G10 L10 P2 R-1.5\n", lambda m: m.tools[2].length, 98.5),
    ("G90 G10 L1 P4 R50\n", lambda m: (m.tools[4].length, m.tools[4].length_wear), (50, 0)),
    ("G20 G90 G10 L10 P5 R1\n", lambda m: m.tools[5].length, 25.4),
    ("G90 G10 L10 P999 R1\n", lambda m: m.tools[999].length, 1.0),
]


@pytest.mark.parametrize("prog,read,want", G10_CASES)
def test_g10_writes_machine_data(prog, read, want) -> None:
    md = MachineData()
    run(prog, md)
    got = read(md)
    if isinstance(want, tuple):
        assert tuple(got) == pytest.approx(want)
    else:
        assert got == pytest.approx(want)
    assert md.revision > 0


G10_REFUSED = [
    ("G10 P1 X1\n", "needs L"),
    ("G10 L2 X1\n", "needs P"),
    ("G10 L2 P7 X1\n", "P0..P6"),
    ("G10 L2 P1\n", "needs X, Y or Z"),
    ("G10 L20 P0 X1\n", "1 .. 48"),
    ("G10 L20 P49 X1\n", "1 .. 48"),
    ("G10 L10 P0 R1\n", "1..999"),
    ("G10 L10 P1000 R1\n", "1..999"),
    ("G10 L10 P1\n", "needs R"),
    ("G10 L5 P1 X1\n", "not supported"),
    ("G10 L10 P1 R5000\n", "within"),
    ("G10 L2 P1 X99999\n", "within"),
]


@pytest.mark.parametrize("prog,fragment", G10_REFUSED)
def test_g10_refusals_leave_machine_data_unchanged(prog, fragment) -> None:
    md = MachineData({1: ToolData(length=10.0)}, {1: (1.0, 2.0, 3.0)})
    before = md.to_dict()
    with pytest.raises(NcError) as ei:
        run(prog, md)
    assert fragment in ei.value.message
    assert ei.value.line == 1 and ei.value.col >= 1
    assert md.to_dict() == before


def test_lathe_g10_sets_tip_offsets_in_diameter_and_nose_radius() -> None:
    md = MachineData()
    run("G10 L10 P1 X40 Z-150 R0.8 Q3\nG10 L11 P1 X0.02\n", md, LATHE)
    t = md.tools[1]
    assert (t.x, t.z, t.radius, t.tip, t.x_wear) == pytest.approx((20.0, -150.0, 0.8, 3, 0.01))
    cmds = run("G0 T0101 X0 Z0\n", md, LATHE)
    end = [c for c in cmds if isinstance(c, StraightTraverse)][-1].end
    assert end[0] == pytest.approx(20.01) and end[2] == pytest.approx(-150.0)


def test_g43_h_uses_length_geometry_plus_wear() -> None:
    md = MachineData({7: ToolData(length=-120.0, length_wear=0.5)})
    cmds = run("G90 G43 H7 G0 Z10\n", md)
    assert cmds[-1].end[2] == pytest.approx(10.0 - 119.5)


def test_unset_offset_reads_zero_and_out_of_range_is_refused() -> None:
    md = MachineData()
    assert run("G43 H12 G0 Z0\n", md)[-1].end[2] == 0.0
    with pytest.raises(NcError, match="out of range"):
        run("G43 H1000 G0 Z0\n", md)


def test_work_offsets_and_g92_come_from_machine_data() -> None:
    md = MachineData(work_offsets={1: (-300.0, -200.0, -400.0), 0: (0.0, 0.0, 1.0)})
    md.set_g92((1.0, 0.0, 0.0))
    assert run("G90 G54 G0 X0 Y0 Z0\n", md)[-1].end == pytest.approx((-299.0, -200.0, -399.0))


def test_g92_shift_is_kept_in_machine_data() -> None:
    md = MachineData()
    run("G90 G0 X10\nG92 X0\n", md)
    assert md.g92 == pytest.approx((10.0, 0.0, 0.0))
    assert run("G90 G0 X5\n", md)[-1].end[0] == pytest.approx(15.0)


def test_power_on_unit_inch_reads_program_in_inch() -> None:
    md = MachineData(power_on_units="inch")
    it = Interpreter(MILL, machine_data=md)
    cmds = list(it.run("G90 G0 X1\n"))
    assert cmds[-1].end[0] == pytest.approx(25.4)
    assert not it.units_programmed
    it2 = Interpreter(MILL, machine_data=md)
    assert list(it2.run("G21 G90 G0 X1\n"))[-1].end[0] == pytest.approx(1.0)
    assert it2.units_programmed


def test_decimal_style_parameter_overrides_machine_params() -> None:
    md = MachineData(decimal_style="least_increment")
    assert run("G90 G0 X10\n", md)[-1].end[0] == pytest.approx(0.010)


def test_check_with_machine_data_copy_leaves_original() -> None:
    md = MachineData()
    cp = md.copy()
    assert check("G10 L10 P1 R5\n", MILL, machine_data=cp) == []
    assert 1 in cp.tools and 1 not in md.tools


# --- G96 clamp ---------------------------------------------------------------------------


def test_g96_clamps_to_the_spindle_max_rpm_from_config() -> None:
    from cnc.config import builtin_machine

    params = replace(builtin_machine("lathe2").params, axes=LATHE.axes)
    assert params.max_spindle_rpm == 4000.0
    cmds = list(Interpreter(params).run("G0 X2 Z0\nG96 S200 M3\n"))
    sp = [c for c in cmds if isinstance(c, Spindle)][-1]
    # 200 m/min at 1 mm radius would be 31831 rpm: the spindle's 4000 holds
    assert sp.rpm == pytest.approx(4000.0)
    cmds = list(Interpreter(params).run("G50 S1500\nG0 X2 Z0\nG96 S200 M3\n"))
    assert [c for c in cmds if isinstance(c, Spindle)][-1].rpm == pytest.approx(1500.0)
    cmds = list(Interpreter(params).run("G50 S9000\nG0 X2 Z0\nG96 S200 M3\n"))
    assert [c for c in cmds if isinstance(c, Spindle)][-1].rpm == pytest.approx(4000.0)


# --- validation of whole documents -------------------------------------------------------

BAD_DOCS = [
    ({"tools": {"0": {}}}, "/tools/0"),
    ({"tools": {"1000": {}}}, "/tools/1000"),
    ({"tools": {"x": {}}}, "/tools/x"),
    ({"tools": {"1": {"length": "a"}}}, "/tools/1/length"),
    ({"tools": {"1": {"lenght": 1}}}, "/tools/1/lenght"),
    ({"tools": {"1": {"tip": 12}}}, "/tools/1/tip"),
    ({"tools": {"1": {"uses": -1}}}, "/tools/1/uses"),
    ({"work_offsets": {"G60": [0, 0, 0]}}, "/work_offsets/G60"),
    ({"work_offsets": {"G54": [0, 0]}}, "/work_offsets/G54"),
    ({"work_offsets": {"G54": {"q": 1}}}, "/work_offsets/G54/q"),
    ({"g92": [0, 0, float("nan")]}, "/g92/2"),
    ({"parameters": {"power_on_units": "cm"}}, "/parameters/power_on_units"),
    ({"bogus": 1}, "/bogus"),
]


@pytest.mark.parametrize("doc,pointer", BAD_DOCS)
def test_bad_documents_name_the_json_pointer(doc, pointer) -> None:
    with pytest.raises(MachineDataError) as ei:
        MachineData.from_dict(doc)
    assert ei.value.pointer == pointer


def test_round_trip_through_dict() -> None:
    md = MachineData({3: ToolData(length=1.5, radius_wear=0.1, comment="ø6 end mill")})
    md.set_work_offset(9, (1.0, 2.0, 3.0))
    md.set_parameters(power_on_units="inch", decimal_style="least_increment")
    assert MachineData.from_dict(json.loads(json.dumps(md.to_dict()))) == md


def test_tool_life_counters() -> None:
    md = MachineData({1: ToolData(life_uses=2, life_time_s=60.0)})
    md.count_use(1)
    assert not md.tools[1].expired
    md.count_use(1)
    assert md.tools[1].expired and md.tools[1].uses == 2
    md.count_use(1, cut_time_s=10.0)
    assert md.tools[1].cut_time_s == 10.0 and md.tools[1].uses == 2


# --- the store ------------------------------------------------------------------------


def test_save_and_load(tmp_path) -> None:
    md = MachineData({1: ToolData(length=100.0)}, {1: (-300.0, -200.0, -400.0)})
    path = tmp_path / "m.machine-data.json"
    save(path, md)
    assert load(path) == md
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary left


def test_a_crash_mid_write_keeps_the_old_file(tmp_path, monkeypatch) -> None:
    path = tmp_path / "m.json"
    old = MachineData({1: ToolData(length=1.0)})
    save(path, old)
    before = path.read_bytes()
    real_fsync = os.fsync

    def crash(fd):  # the new text is written but not yet on disk: the process dies
        raise OSError(5, "simulated power loss")

    monkeypatch.setattr(os, "fsync", crash)
    with pytest.raises(OSError, match="power loss"):
        save(path, MachineData({1: ToolData(length=2.0)}))
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert path.read_bytes() == before
    assert load(path) == old
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_a_crash_before_the_rename_keeps_the_old_file(tmp_path, monkeypatch) -> None:
    path = tmp_path / "m.json"
    write_atomically(path, "old\n")

    def crash(src, dst):
        raise KeyboardInterrupt  # killed between the write and the rename

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(KeyboardInterrupt):
        write_atomically(path, "new\n")
    assert path.read_text() == "old\n"


def test_a_bad_state_file_names_file_and_place(tmp_path) -> None:
    path = tmp_path / "m.json"
    path.write_text('{"tools": {"1": {"length": "x"}}}')
    with pytest.raises(NcError, match=r"/tools/1/length"):
        load(path)
    path.write_text('{"tools": \n  {1}')
    with pytest.raises(NcError) as ei:
        load(path)
    assert ei.value.line == 2


# --- operator files ---------------------------------------------------------------------


def test_tools_csv_round_trip() -> None:
    md = MachineData({1: ToolData(length=100.0, radius=5.0), 12: ToolData(x=1.5, tip=3)})
    assert parse_tools(tools_csv(md), "t.csv") == md.tools


BAD_TOOL_ROWS = [
    ("number,length\n1,abc\n", 2, 3, "not a number"),
    ("number,length\n0,1\n", 2, 1, "within"),
    ("number,length\n1,1\n1,2\n", 3, 1, "already on line 2"),
    ("number,length\n1,1,2\n", 2, 3, "header has 2"),
    ("number, lenght\n", 1, 9, "unknown column"),
    ("length\n1\n", 1, 1, "'number' column"),
    ("number,tip\n1,11\n", 2, 3, "tip"),
    ("# comment\n\nnumber,radius\n5, 99999\n", 4, 4, "within"),
]


@pytest.mark.parametrize("text,line,col,fragment", BAD_TOOL_ROWS)
def test_bad_tool_rows_name_file_line_column(text, line, col, fragment) -> None:
    with pytest.raises(FileErrors) as ei:
        parse_tools(text, "tools.csv")
    e = ei.value
    assert (e.file, e.line, e.col) == ("tools.csv", line, col)
    assert fragment in e.message
    assert str(e).startswith(f"tools.csv:{line}:{col}: ")


def test_every_bad_row_is_reported() -> None:
    with pytest.raises(FileErrors) as ei:
        parse_tools("number,length\nx,1\n2,y\n3,3\n", "t.csv")
    assert [(e.line, e.col) for e in ei.value.errors] == [(2, 1), (3, 3)]


def test_linuxcnc_tool_table() -> None:
    tools = parse_tools("T1 P1 Z+50.0 D10.0 ;10 mm end mill\nT2 P2 Z30 X1 Q3\n", "t.tbl")
    assert tools[1] == ToolData(length=50.0, radius=5.0, comment="10 mm end mill")
    assert (tools[2].length, tools[2].x, tools[2].tip) == (30.0, 1.0, 3)
    with pytest.raises(FileErrors) as ei:
        parse_tools("T1 Z1\nT2 Z=5\nT3 K4\n", "t.tbl")
    assert [(e.line, e.col) for e in ei.value.errors] == [(2, 4), (3, 4)]


def test_offsets_file_and_apply(tmp_path) -> None:
    assert parse_offsets("offset,x,y,z\nG54,-300,-200,-400\nG54.1 P2,1,,\n", "o.csv") == {
        "G54": (-300.0, -200.0, -400.0),
        "G54.1P2": (1.0, 0.0, 0.0),
    }
    for text, line, col in [
        ("offset,x,y,z\nG60,0,0,0\n", 2, 1),
        ("offset,x,y,z\nG54,0,a,0\n", 2, 7),
        ("offset,x,y,z\nG54,0,0,0\nG54,1,1,1\n", 3, 1),
        ("name,x\n", 1, 1),
    ]:
        with pytest.raises(FileErrors) as ei:
            parse_offsets(text, "o.csv")
        assert (ei.value.line, ei.value.col) == (line, col), text
    tools = tmp_path / "t.csv"
    tools.write_text("number,length\n7,99\n")
    ofs = tmp_path / "o.csv"
    ofs.write_text("offset,x,y,z\nG55,1,2,3\nG92,0,0,1\n")
    base = MachineData({1: ToolData(length=1.0)}, {1: (5.0, 5.0, 5.0)})
    got = apply_files(base, tools, ofs)
    assert set(got.tools) == {7} and got.work_offsets[1] == (5.0, 5.0, 5.0)
    assert got.work_offsets[2] == (1.0, 2.0, 3.0) and got.g92 == (0.0, 0.0, 1.0)
    assert set(base.tools) == {1}  # the original is left alone


def test_g92_shift_out_of_range_is_an_nc_error_and_changes_nothing() -> None:
    md = MachineData()
    with pytest.raises(NcError, match="G92 shift"):
        run("G92 X280300\n", md)
    assert md.g92 == (0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    "prog,want",
    [
        # Fanuc T series: P10000+n geometry, P n wear; X in diameter, U/W add
        ("G10 P10003 X-40 Z12 R0.4 Q3\n", {"x": -20.0, "z": 12.0, "radius": 0.4, "tip": 3}),
        ("G10 P3 X0.06 Z-0.02\n", {"x_wear": 0.03, "z_wear": -0.02}),
        ("G10 P10003 X-40\nG10 P10003 U2 W-1\n", {"x": -19.0, "z": -1.0}),
        ("G10 P3 U0.02\nG10 P3 U0.02\n", {"x_wear": 0.02}),
    ],
)
def test_lathe_g10_p_form(prog, want) -> None:
    md = MachineData()
    run(prog, md, LATHE)
    t = md.tools[3]
    assert {k: getattr(t, k) for k in want} == pytest.approx(want)


@pytest.mark.parametrize("prog", ["G10 P0 X1\n", "G10 P10000 X1\n", "G10 P1000 X1\n", "G10 P3\n"])
def test_lathe_g10_p_form_refusals(prog) -> None:
    with pytest.raises(NcError, match="G10 P"):
        run(prog, MachineData(), LATHE)


def test_offsets_csv_round_trip(tmp_path) -> None:
    md = MachineData(work_offsets={1: (-300.0, -200.0, -300.0), 9: (1.5, 0.0, -2.0)})
    md.set_g92((0.0, 0.0, 0.25))
    path = tmp_path / "o.csv"
    path.write_text(offsets_csv(md))
    assert apply_files(MachineData(), offsets=path) == md


# --- property: a refused change never changes anything; every accepted one round-trips ---


_VALUES = st.one_of(
    st.floats(-2000.0, 2000.0, allow_nan=False),
    st.just(float("nan")),
    st.just(float("inf")),
    st.text(max_size=3),
)
_OPS = st.lists(
    st.one_of(
        st.tuples(st.just("tool"), st.integers(-2, 1002), st.sampled_from(
            ["length", "radius_wear", "x", "tip", "uses", "bogus"]), _VALUES),
        st.tuples(st.just("offset"), st.integers(-2, 56), st.integers(0, 2), _VALUES),
    ),
    max_size=25,
)  # fmt: skip


@settings(max_examples=150, deadline=None)
@given(_OPS)
def test_refused_changes_change_nothing_and_accepted_ones_round_trip(ops) -> None:
    md = MachineData()
    for kind, number, key, value in ops:
        before = md.to_dict()
        try:
            if kind == "tool":
                md.update_tool(number, **{key: value})
            else:
                xyz = [0.0, 0.0, 0.0]
                xyz[key] = value
                md.set_work_offset(number, xyz)
        except MachineDataError as e:
            assert e.pointer.startswith("/")
            assert md.to_dict() == before
    assert MachineData.from_dict(json.loads(json.dumps(md.to_dict()))) == md
