"""Machine and cell configuration: shipped machines, loading forms and every validation error."""

from __future__ import annotations

import dataclasses
import textwrap
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from cnc.config import (
    BUILTIN_MACHINES,
    MACHINES_DIR,
    ConfigError,
    MachineConfig,
    builtin_machine,
    load_machine_config,
    load_machine_params,
)
from cnc.errors import NcError
from cnc.kinematics import CartesianMill, Lathe, kinematics_for
from cnc.params import DecimalStyle, MachineParams
from server.config import config_reference_markdown, default_cell_config, load_cell_config

ROOT = Path(__file__).resolve().parents[2]


def write(tmp_path: Path, text: str, name: str = "cell.yaml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
    return p


# --- shipped machines --------------------------------------------------------------------


def test_mill3_params():
    p = load_machine_params(MACHINES_DIR / "mill3.yaml")
    assert p.kind == "mill"
    assert [a.name for a in p.axes] == ["X", "Y", "Z"]
    x = p.axis("X")
    assert (x.min_mm, x.max_mm, x.home_mm) == (-600.0, 0.0, 0.0)
    assert x.max_velocity == 30000.0  # 30 m/min
    assert x.max_accel == 3000.0  # 3 m/s^2
    assert x.max_jerk == 50000.0  # 50 m/s^3
    assert p.ipo_cycle_s == pytest.approx(0.002)
    assert p.lookahead == 200
    assert p.decimal_style is DecimalStyle.CALCULATOR
    assert p.second_reference_mm == (-300.0, 0.0, 0.0)
    assert isinstance(kinematics_for(p), CartesianMill)
    m = builtin_machine("mill3")
    assert m.tool_changer.kind == "atc"
    assert m.drives.node_id("Z", 2) == 3


def test_lathe2_params():
    m = builtin_machine("lathe2")
    p = m.params
    assert p.kind == "lathe"
    assert [a.name for a in p.axes] == ["X", "Z"]
    assert p.lathe_diameter_mode
    assert p.second_reference_mm is None
    assert isinstance(kinematics_for(p), Lathe)
    assert m.tool_changer.kind == "turret"
    assert m.tool_changer.pockets == 12


def test_default_cell_has_one_of_each_shipped_machine():
    cell = default_cell_config()
    assert tuple(cell.machines) == BUILTIN_MACHINES
    assert cell.params("mill3") == load_machine_params(MACHINES_DIR / "mill3.yaml")
    assert cell.host.bind == "127.0.0.1"
    ports = [getattr(m.ports, f) for m in cell.machines.values() for f in ("dnc", "modbus", "shdr")]
    assert len(set(ports)) == len(ports)
    with pytest.raises(NcError, match="no machine 'mill9' in the cell"):
        cell.machine("mill9")


def test_builtin_machine_unknown():
    with pytest.raises(NcError, match="no shipped machine 'drill'"):
        builtin_machine("drill")


# --- loading forms -----------------------------------------------------------------------


def test_cell_file_with_base_and_overrides(tmp_path):
    path = write(
        tmp_path,
        """
        machines:
          mill1:
            base: mill3
            axes:
              X: {max_accel: 2000.0}
            ports: {dnc: 7101, modbus: 5101, shdr: 7801}
          lathe1:
            base: lathe2
            ipo_cycle_ms: 1
            ports: {dnc: 7102, modbus: 5102, shdr: 7802}
        host:
          port: 8080
        """,
    )
    cell = load_cell_config(path)
    assert list(cell.machines) == ["mill1", "lathe1"]
    x = cell.params("mill1").axis("X")
    assert x.max_accel == 2000.0
    assert x.max_velocity == 30000.0  # from the base
    assert [a.name for a in cell.params("mill1").axes] == ["X", "Y", "Z"]  # order kept
    assert cell.params("lathe1").ipo_cycle_s == pytest.approx(0.001)
    assert cell.host.port == 8080
    assert cell.source == str(path)
    assert load_machine_params(path, "lathe1") == cell.params("lathe1")


def test_base_may_be_a_file_relative_to_the_cell_file(tmp_path):
    (tmp_path / "sub").mkdir()
    write(tmp_path, "base: mill3\nmax_feed: 9000\n", "sub/mymill.yaml")
    path = write(tmp_path, "machines:\n  m1:\n    base: sub/mymill.yaml\n    lookahead: 50\n")
    p = load_machine_params(path)
    assert (p.max_feed, p.lookahead, p.axis("X").min_mm) == (9000.0, 50, -600.0)


def test_base_cycle_is_refused(tmp_path):
    write(tmp_path, "base: b.yaml\n", "a.yaml")
    write(tmp_path, "base: a.yaml\n", "b.yaml")
    path = write(tmp_path, "machines:\n  m1:\n    base: a.yaml\n")
    with pytest.raises(ConfigError, match="`base` chain deeper than 8"):
        load_cell_config(path)


def test_single_machine_dict_and_cell_dict():
    section = yaml.safe_load((MACHINES_DIR / "lathe2.yaml").read_text())
    assert load_machine_params(section) == builtin_machine("lathe2").params
    cell = {"machines": {"l1": section}}
    assert load_machine_params(cell) == builtin_machine("lathe2").params
    assert load_machine_params(cell, "l1") == builtin_machine("lathe2").params


def test_machine_selection_errors(tmp_path):
    path = write(
        tmp_path,
        """
        machines:
          a: {base: mill3, ports: {dnc: 1, modbus: 2, shdr: 3}}
          b: {base: mill3, ports: {dnc: 4, modbus: 5, shdr: 6}}
        """,
    )
    with pytest.raises(ConfigError, match=r"machines: several machines \(a, b\): name one"):
        load_machine_params(path)
    with pytest.raises(ConfigError, match=r"1:1: machines: no machine 'c' \(machines: a, b\)"):
        load_machine_params(path, "c")


def test_yaml_anchors_and_merge_keys(tmp_path):
    path = write(
        tmp_path,
        """
        kind: mill
        axes:
          X: &a {min_mm: -100, max_mm: 0, max_velocity: 10000, max_accel: 1000, max_jerk: 10000}
          Y: {<<: *a, min_mm: -50}
          Z: *a
        """,
    )
    p = load_machine_params(path)
    assert p.axis("Y").min_mm == -50.0
    assert p.axis("Y").max_velocity == 10000.0
    assert p.axis("Z") == dataclasses.replace(p.axis("X"), name="Z")


def test_a_helper_key_for_anchors_is_still_an_unknown_key(tmp_path):
    path = write(tmp_path, "_defaults: &d {max_jerk: 1}\nbase: mill3\n")
    with pytest.raises(ConfigError, match=r"1:1: _defaults: unknown key"):
        load_machine_params(path)


def test_loaded_config_is_frozen():
    m = builtin_machine("mill3")
    with pytest.raises(ValidationError):
        m.lookahead = 5  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.params.lookahead = 5  # type: ignore[misc]


def test_drive_helpers():
    m = load_machine_config(
        {
            "base": "mill3",
            "drives": {
                "plant": {"loops": {"kv": 30.0}, "screw": {"lead": 0.005}},
                "axes": {"X": {"node_id": 5, "plant": {"screw": {"table_mass": 40.0}}}},
            },
        }
    )
    assert m.drives.node_id("X", 0) == 5
    assert m.drives.node_id("Y", 1) == 2
    assert m.drives.plant_overrides("X") == {
        "loops": {"kv": 30.0},
        "screw": {"lead": 0.005, "table_mass": 40.0},
    }
    assert m.drives.plant_overrides("Y") == {"loops": {"kv": 30.0}, "screw": {"lead": 0.005}}
    assert m.can.bus_config("m1") == {"interface": "sim", "channel": "m1", "bitrate": 1_000_000}


def test_plant_overrides_build_drive_plant_params():
    from drives.plant.params import PlantParams

    m = builtin_machine("mill3")
    plant = PlantParams().with_(**m.drives.plant_overrides("Z"))
    assert plant.screw.table_mass == 80.0


# --- validation errors: one row per rule --------------------------------------------------
# Each row: YAML lines under `machines.m1:` (which starts from `base: mill3`), the expected
# `LINE:COL: key.path: reason` (the cell file's lines; line 4 is the override line).

ERRORS = [
    ("axes: {X: {max_accel: -5}}", "4:27: machines.m1.axes.X.max_accel: must be > 0, got -5"),
    ("axes: {X: {max_jerk: 0}}", "machines.m1.axes.X.max_jerk: must be > 0, got 0"),
    ("axes: {Y: {max_velocity: -1.5}}", "machines.m1.axes.Y.max_velocity: must be > 0, got -1.5"),
    ("axes: {X: {max_accel: '3'}}", "machines.m1.axes.X.max_accel: must be a number, got '3'"),
    ("axes: {X: {max_accel: true}}", "machines.m1.axes.X.max_accel: must be a number, got true"),
    ("axes: {X: {max_acel: 3}}", "machines.m1.axes.X.max_acel: unknown key (did you mean 'max_accel'?"),
    ("axes: {X: {min_mm: 0, max_mm: -600}}", "machines.m1.axes.X.max_mm: must be > min_mm (0), got -600"),
    ("axes: {X: {home_mm: 5}}", "machines.m1.axes.X.home_mm: must lie within the soft limits -600 .. 0, got 5"),
    ("axes: {Q: {min_mm: 0, max_mm: 1, max_velocity: 1, max_accel: 1, max_jerk: 1}}",
     "machines.m1.axes.Q: bad name 'Q': an axis is one of X Y Z A B C U V W"),
    ("axes: {W: {min_mm: 0, max_mm: 1, max_velocity: 1, max_accel: 1, max_jerk: 1}}",
     "machines.m1.axes: machine kind 'mill' has axes X Y Z, configured X Y Z W"),
    ("axes: {Z: {continuous: true}}", "machines.m1.axes.Z.continuous: only a rotary axis (A, B, C) is endless"),
    ("axes: {W: {min_mm: 0}}", "machines.m1.axes.W.max_mm: required key missing"),
    ("axes: []", "machines.m1.axes: must be a mapping, got a list"),
    ("kind: lathe", "machines.m1.axes: machine kind 'lathe' has axes X Z, configured X Y Z"),
    ("kind: router", "4:11: machines.m1.kind: no kinematics for machine kind 'router'"),
    ("kind: 5", "machines.m1.kind: must be a string, got 5"),
    ("ipo_cycle_ms: 9", "4:19: machines.m1.ipo_cycle_ms: must be <= 8, got 9"),
    ("ipo_cycle_ms: 0.25", "machines.m1.ipo_cycle_ms: must be >= 0.5, got 0.25"),
    ("ipo_cycle_ms: .nan", "machines.m1.ipo_cycle_ms: must be a finite number, got nan"),
    ("lookahead: 0", "machines.m1.lookahead: must be >= 1, got 0"),
    ("lookahead: 2.5", "machines.m1.lookahead: must be an integer, got 2.5"),
    ("default_path_tolerance: -0.1", "machines.m1.default_path_tolerance: must be >= 0, got -0.1"),
    ("max_feed: 0", "machines.m1.max_feed: must be > 0, got 0"),
    ("decimal_style: fanuc",
     "machines.m1.decimal_style: must be one of 'calculator' or 'least_increment', got 'fanuc'"),
    ("least_increment_mm: 0", "machines.m1.least_increment_mm: must be > 0, got 0"),
    ("lathe_diameter_mode: 1", "machines.m1.lathe_diameter_mode: must be true or false, got 1"),
    ("second_reference_mm: {X: 5}",
     "machines.m1.second_reference_mm.X: must lie within the soft limits -600 .. 0, got 5"),
    ("second_reference_mm: {B: 0}", "machines.m1.second_reference_mm.B: no such axis (axes: X Y Z)"),
    ("program_memory_bytes: 10", "machines.m1.program_memory_bytes: must be >= 1024, got 10"),
    ("home_sequence: [[Z], [X]]", "machines.m1.home_sequence: must name each axis of X Y Z exactly"
     " once, in non-empty groups, got [['Z'], ['X']]"),
    ("home_sequence: [[Z], [], [X, Y]]", "machines.m1.home_sequence: must name each axis"),
    ("home_sequence: [[Z, Z], [X, Y]]", "machines.m1.home_sequence: must name each axis"),
    ("home_sequence: [[Q], [X, Y, Z]]", "4:22: machines.m1.home_sequence.0.0: bad name 'Q': an axis"),
    ("max_acel: 3", "machines.m1.max_acel: unknown key (did you mean 'max_feed'?"),
    ("spindle: {max_rpm: -1}", "machines.m1.spindle.max_rpm: must be > 0, got -1"),
    ("spindle: {min_rpm: 9000}", "machines.m1.spindle.min_rpm: must be <= max_rpm (8000), got 9000"),
    ("tool_changer: {kind: robot}",
     "machines.m1.tool_changer.kind: must be one of 'atc', 'turret' or 'manual', got 'robot'"),
    ("tool_changer: {pockets: 0}", "machines.m1.tool_changer.pockets: must be >= 1, got 0"),
    ("plc: {period_ms: 3}",
     "machines.m1.plc.period_ms: must be an integer multiple of the IPO cycle (2 ms), got 3"),
    ("plc: {period_ms: 0}", "machines.m1.plc.period_ms: must be >= 1, got 0"),
    ("plc: {perod_ms: 10}", "machines.m1.plc.perod_ms: unknown key (did you mean 'period_ms'?"),
    ("plc: {modbus_write_allow: 'hr:5-x'}", "machines.m1.plc.modbus_write_allow: "),
    ("can: {bitrate: 300000}", "machines.m1.can.bitrate: must be one of 10000, 20000, 50000,"),
    ("can: {interface: slcan}",
     "machines.m1.can.interface: must be one of 'sim', 'socketcan' or 'virtual', got 'slcan'"),
    ("ports: {dnc: 70000}", "machines.m1.ports.dnc: must be <= 65535, got 70000"),
    ("ports: {shdr: -1}", "machines.m1.ports.shdr: must be >= 0, got -1"),
    ("ports: {host: ''}", "machines.m1.ports.host: must not be empty"),
    ("drives: {axes: {Y: {node_id: 1}}}",
     "machines.m1.drives.axes.Y.node_id: node-ID 1 already used by axis X"),
    ("drives: {axes: {X: {node_id: 128}}}", "machines.m1.drives.axes.X.node_id: must be <= 127, got 128"),
    ("drives: {axes: {B: {node_id: 9}}}", "machines.m1.drives.axes.B: no such axis (axes: X Y Z)"),
    ("drives: {plant: {motr: {km: 1}}}",
     "machines.m1.drives.plant.motr: unknown plant group (did you mean 'motor'?"),
    ("drives: {plant: {screw: {leed: 0.01}}}",
     "machines.m1.drives.plant.screw.leed: unknown plant parameter (did you mean 'lead'?"),
    ("drives: {plant: {screw: {lead: true}}}", "machines.m1.drives.plant.screw.lead: must be a number, got true"),
    ("drives: {plant: {encoder: {counts_per_rev: 1.5}}}",
     "machines.m1.drives.plant.encoder.counts_per_rev: must be an integer, got 1.5"),
    ("drives: {plant: {screw: {lead: 'fine'}}}",
     "4:36: machines.m1.drives.plant.screw.lead: must be a finite number, got 'fine'"),
    ("drives: {plant: {screw: {lead: .inf}}}",
     "machines.m1.drives.plant.screw.lead: must be a finite number, got inf"),
    ("drives: {plant: [1]}", "machines.m1.drives.plant: must be a mapping, got a list"),
    ("plc: {m_codes: {3: {ms: 10}}}",
     "machines.m1.plc.m_codes.3: M3 is handled by the NC or the standard PLC program"),
    ("plc: {m_codes: {31: {ms: 40000}}}", "machines.m1.plc.m_codes.31.ms: must be <= 29000"),
    ("macro_variable_map: fanuc", "machines.m1.macro_variable_map: must be one of 'haas_ngc' or"),
    ("macro_variable_map: kitamura\n    machine_data: {macro_variables: {10002: 1}}",
     "machines.m1.machine_data.macro_variables.10002: on a `macro_variable_map: kitamura`"
     " machine #10001-#10999 are tool length offsets"),
]  # fmt: skip


@pytest.mark.parametrize(("override", "expected"), ERRORS, ids=[e[1][:60] for e in ERRORS])
def test_validation_error_names_key_path_and_reason(tmp_path, override, expected):
    path = write(tmp_path, f"machines:\n  m1:\n    base: mill3\n    {override}\n")
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    err = info.value
    assert isinstance(err, NcError)
    lines = str(err).splitlines()
    assert any(expected in line for line in lines), lines
    assert all(line.startswith(f"{path}:") or "mill3.yaml:" in line for line in lines)


CELL_ERRORS = [
    ("machines: {}\n", "1:1: machines: must not be empty"),
    ("", "1:1: the configuration is empty"),
    ("- 1\n", "1:1: must be a mapping, got a list"),
    ("machines:\n  1bad: {base: mill3}\n", "2:3: machines.1bad: bad name '1bad': a machine name"),
    ("machines:\n  m1: {base: mill3}\n  m1: {base: lathe2}\n",
     "3:3: machines.m1: duplicate key (first at line 2)"),
    ("machines:\n  m1:\n    base: mill3\n    kind: mill\n    kind: lathe\n",
     "5:5: machines.m1.kind: duplicate key (first at line 4)"),
    ("machines:\n  m1:\n    base: mill3\n   bad: [\n", "4:4: YAML syntax:"),
    ("machines:\n  m1: {base: mill9}\n", "2:14: machines.m1.base: no shipped machine or file 'mill9'"),
    ("machines:\n  m1: {base: [1]}\n", "machines.m1.base: must name a shipped machine or a file"),
    ("machines:\n  m1: {kind: mill}\n", "2:3: machines.m1.axes: required key missing"),
    ("machines:\n  m1: {base: mill3}\nhost: {port: 99999}\n", "3:14: host.port: must be <= 65535"),
    ("machines:\n  m1: {base: mill3}\nhost: {databse_url: x}\n",
     "host.databse_url: unknown key (did you mean 'database_url'?"),
    ("machines:\n  m1: {base: mill3}\nhosts: {}\n", "3:1: hosts: unknown key (did you mean 'host'?"),
    ("machines:\n  a: {base: mill3}\n  b: {base: mill3}\n",
     "machines.b.ports.dnc: port 7001 already used by machines.a.ports.dnc"),
    ("machines:\n  a: {base: mill3, ports: {modbus: 8000}}\n",
     "machines.a.ports.modbus: port 8000 already used by host.port"),
]  # fmt: skip


@pytest.mark.parametrize(("text", "expected"), CELL_ERRORS, ids=[e[1][:50] for e in CELL_ERRORS])
def test_cell_errors(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    assert any(expected in line for line in str(info.value).splitlines()), str(info.value)


def test_every_problem_is_reported_one_per_line(tmp_path):
    path = write(
        tmp_path,
        """
        machines:
          mill1:
            base: mill3
            axes:
              X:
                max_accel: -5
          mill2:
            base: mill3
            ipo_cycle_ms: 9
          lathe1:
            base: lathe2
            kind: mill
        """,
    )
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    lines = str(info.value).splitlines()
    assert lines[0] == f"{path}:6:20: machines.mill1.axes.X.max_accel: must be > 0, got -5"
    assert lines[1] == f"{path}:9:19: machines.mill2.ipo_cycle_ms: must be <= 8, got 9"
    # lathe1 is valid field by field; its cross-field rule still runs in the same pass.
    assert "machines.lathe1.axes: machine kind 'mill' has axes X Y Z, configured X Z" in lines[2]
    assert len(info.value.problems) == 3
    assert info.value.line == 6 and info.value.col == 20  # NcError fields: the first problem


def test_errors_in_a_base_file_point_into_it(tmp_path):
    write(tmp_path, "base: mill3\nlookahead: -3\n", "bad_base.yaml")
    path = write(tmp_path, "machines:\n  m1: {base: bad_base.yaml}\n")
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    assert str(info.value) == (
        f"{tmp_path / 'bad_base.yaml'}:2:12: machines.m1.lookahead: must be >= 1, got -3"
    )


def test_dict_errors_have_no_line():
    with pytest.raises(ConfigError) as info:
        load_machine_params({"base": "mill3", "lookahead": 0})
    assert str(info.value) == "<config>:0:0: lookahead: must be >= 1, got 0"


def test_unrepresentable_dict_is_refused():
    with pytest.raises(ConfigError, match="not plain configuration data"):
        load_machine_params({"kind": object()})


def test_missing_file():
    with pytest.raises(ConfigError, match="configuration file not found"):
        load_cell_config("/nonexistent/cell.yaml")


@settings(max_examples=40, deadline=None)
@given(
    lo=st.floats(-5000, -1),
    span=st.floats(1, 5000),
    vel=st.floats(1, 1e5),
    acc=st.floats(1, 1e5),
    jerk=st.floats(1, 1e7),
    ipo=st.sampled_from([0.5, 1.0, 2.0, 2.5, 5.0]),
)
def test_valid_values_arrive_unchanged_in_machine_params(lo, span, vel, acc, jerk, ipo):
    axis = {"min_mm": lo, "max_mm": lo + span, "max_velocity": vel, "max_accel": acc,
            "max_jerk": jerk, "home_mm": lo}  # fmt: skip
    section = {"kind": "lathe", "axes": {"X": axis, "Z": axis}, "ipo_cycle_ms": ipo}
    p = load_machine_params(section)
    assert isinstance(p, MachineParams)
    assert p.axis("Z").max_jerk == jerk
    assert p.axis("X").min_mm == lo
    assert p.ipo_cycle_s == pytest.approx(ipo / 1000)


# --- documentation ------------------------------------------------------------------------


def test_docs_document_every_key():
    doc = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert config_reference_markdown() in doc
    for key in MachineConfig.model_fields:
        assert f"| `{key}` |" in doc


def test_docs_show_the_shipped_mill_as_it_is():
    doc = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert (MACHINES_DIR / "mill3.yaml").read_text(encoding="utf-8") in doc


# --- hostile input: only ConfigError, never a crash or a hang ------------------------------

BOMB = """
a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]
b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]
c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]
d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]
e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]
f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]
g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f]
h: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g]
machines: {m1: {base: mill3, description: *h}}
"""


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (BOMB, "machines.m1.description: must be a string, got a list"),
        ("machines: {m1: {base: mill3, description: &r [*r]}}\n", "must be a string"),
        ("machines: &m {m1: *m}\n", "machines.m1"),
        ("machines:\n  m1: {base: mill3, host: &x {<<: *x}}\n", ""),
        ("[" * 1500 + "]" * 1500, "nested too deeply"),
        ("\x00\x01", "YAML"),
        ("? [1, 2]\n: x\n", ""),
        ("machines: {1: {base: mill3}}\n", "machines.1: must be a string, got 1"),
        ("machines:\n  m1:\n", "machines.m1: must be a mapping, got null"),
    ],
)
def test_hostile_yaml_gets_config_error(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    assert expected in str(info.value)


json_scalars = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
json_values = st.recursive(
    json_scalars,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=10,
)
section_keys = st.sampled_from(
    [*MachineConfig.model_fields, "base", "axes", "X", "max_accel", "plant", "screw", "lead"]
)


@settings(max_examples=80, deadline=None)
@given(
    section=st.dictionaries(section_keys, json_values, max_size=6),
    keep_base=st.booleans(),
)
def test_random_sections_only_ever_raise_config_error(section, keep_base):
    if keep_base:
        section = {**section, "base": "mill3"}
    try:
        load_machine_params({"machines": {"m1": section}})
    except ConfigError as exc:
        assert str(exc)  # one line per problem, never empty
        assert all(
            line.startswith(("<config>:", str(MACHINES_DIR))) for line in str(exc).splitlines()
        )


def test_home_sequence_key_sets_the_controllers_homing_sequence(tmp_path):
    from cnc.controller import Controller, ControllerSettings
    from cnc.program_memory import ProgramMemory

    path = write(
        tmp_path, "machines:\n  m1:\n    base: mill3\n    home_sequence: [[Z], [Y], [X]]\n"
    )
    cfg = load_cell_config(path).machine("m1")
    assert Controller(cfg, ProgramMemory(4096)).home_sequence == (("Z",), ("Y",), ("X",))
    # ControllerSettings, when given, still wins over the YAML key
    ctl = Controller(
        cfg, ProgramMemory(4096), settings=ControllerSettings(home_order=("X", "Y", "Z"))
    )
    assert ctl.home_sequence == (("X",), ("Y",), ("Z",))
    assert Controller(builtin_machine("mill3"), ProgramMemory(4096)).home_sequence == (
        ("Z",),
        ("X", "Y"),
    )
