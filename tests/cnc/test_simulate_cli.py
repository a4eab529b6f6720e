"""`fmscell nc simulate`: the command-line contract (one JSON object, exit codes, errors)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import cnc.cli_simulate  # noqa: F401  (registers `simulate` on nc_app)
from cnc.cli import nc_app

PROGRAMS = Path(__file__).parent / "programs"
SQUARE = """%
O0010 (SQUARE)
N10 G21 G90 G17
N20 T2 M6
N30 G0 X-100 Y-100 Z-10
N40 G1 X-150 F3000
N50 Y-150
N60 X-100
N70 Y-100
N80 G0 Z-5
N90 M30
%
"""
KEYS = {
    "result",
    "alarms",
    "cycle_time_s",
    "final_position",
    "max_following_error_mm",
    "max_contour_error_mm",
    "bus_load",
    "blocks",
}


def run(*args: str):
    result = CliRunner().invoke(nc_app, ["simulate", *args])
    return result.exit_code, result.stdout, result.stderr


def test_seed_pocket_program_completes_on_ideal_axes():
    code, out, _ = run(str(PROGRAMS / "pocket_mill.nc"), "--ideal")
    assert code == 0
    data = json.loads(out)
    assert set(data) == KEYS
    assert data["result"] == "completed" and data["alarms"] == []
    # G54 at X-400 Y-300 Z-200; the last hole at X70 Y40, then G28 Z
    assert data["final_position"] == {"X": -330.0, "Y": -260.0, "Z": 0.0}
    assert data["blocks"] > 15 and data["cycle_time_s"] > 10.0
    assert data["bus_load"] == {"mean": 0.0, "peak": 0.0}


def test_square_on_canopen_drives_with_trace_and_candump(tmp_path):
    prog = tmp_path / "square.nc"
    prog.write_text(SQUARE)
    trace, candump = tmp_path / "t.csv", tmp_path / "c.log"
    code, out, _ = run(str(prog), "--trace", str(trace), "--candump", str(candump))
    assert code == 0, out
    data = json.loads(out)
    assert data["result"] == "completed"
    # the program's X-100 Y-100 Z-5 from the shipped G54 (X-300 Y-200 Z-300)
    for axis, want in {"X": -400.0, "Y": -300.0, "Z": -305.0}.items():
        assert data["final_position"][axis] == pytest.approx(want, abs=0.01)
    assert all(0 < fe < 1.0 for fe in data["max_following_error_mm"].values())
    assert 0 < data["max_contour_error_mm"] < 0.1
    assert 10 < data["bus_load"]["mean"] < 100
    assert trace.read_text().startswith("t,X_cmd,Y_cmd,Z_cmd,X_act,Y_act,Z_act,line\n")
    first = candump.read_text().splitlines()[0]
    assert first.startswith("(0.") and " mill3 " in first


def test_estop_fault_ends_the_run_with_an_alarm():
    code, out, _ = run(str(PROGRAMS / "pocket_mill.nc"), "--ideal", "--fault", "plc:estop@2s")
    assert code == 1
    data = json.loads(out)
    assert data["result"] == "alarm"
    numbers = {(a["number"], a["source"]) for a in data["alarms"]}
    assert (3001, "NC") in numbers or (1001, "PLC") in numbers
    assert all(set(a) == {"number", "text", "source", "axis", "line"} for a in data["alarms"])


def test_drive_encoder_fault_on_canopen_drives(tmp_path):
    prog = tmp_path / "square.nc"
    prog.write_text(SQUARE)
    code, out, _ = run(str(prog), "--fault", "drive:X:encoder@3s")
    assert code == 1
    data = json.loads(out)
    assert data["result"] == "alarm"
    alarm = data["alarms"][0]
    assert (alarm["source"], alarm["axis"]) == ("DRIVE", "X")


def test_encoder_noise_from_the_fault_registry_is_a_drive_encoder_fault(tmp_path):
    prog = tmp_path / "square.nc"
    prog.write_text(SQUARE)
    code, out, _ = run(str(prog), "--fault", "drive:X:encoder_noise:counts=40000@3s")
    assert code == 1
    alarm = json.loads(out)["alarms"][0]
    assert (alarm["source"], alarm["axis"]) == ("DRIVE", "X")
    assert "0x7305" in alarm["text"]


def test_unknown_fault_spec_is_a_usage_error_listing_the_valid_specs():
    code, out, err = run(str(PROGRAMS / "pocket_mill.nc"), "--fault", "drive:X:meltdown@1s")
    assert code == 2 and out == ""
    assert "unknown drive fault 'meltdown'" in err and "plc:door_open@<t>" in err


def test_program_larger_than_memory_is_refused_with_drip_feed_suggested(tmp_path):
    cfg = tmp_path / "small.yaml"
    cfg.write_text("base: mill3\nprogram_memory_bytes: 1024\n")
    prog = tmp_path / "big.nc"
    prog.write_text("%\nO0042\n" + "G1 X-10 Y-10 F1000\n" * 200 + "M30\n%\n")
    code, out, err = run(str(prog), "--config", str(cfg), "--ideal")
    assert code == 2 and out == ""
    assert "O0042" in err and "drip-feed" in err


def test_bad_config_and_missing_file_are_clear_errors(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("base: mill3\nipo_cycle_ms: 9\n")
    code, _, err = run(str(PROGRAMS / "pocket_mill.nc"), "--config", str(cfg))
    assert code == 2 and "ipo_cycle_ms" in err
    code, _, err = run(str(tmp_path / "nope.nc"), "--ideal")
    assert code == 2 and "nope.nc" in err and "cannot read" in err


def test_a_bus_that_cannot_carry_the_axes_is_refused_with_the_load_plan(tmp_path):
    cfg = tmp_path / "fast.yaml"
    cfg.write_text("base: mill3\nipo_cycle_ms: 0.5\n")
    code, out, err = run(str(PROGRAMS / "pocket_mill.nc"), "--config", str(cfg))
    assert code == 2 and out == ""
    assert "bus configuration refused" in err and "exceeds 100 %" in err
