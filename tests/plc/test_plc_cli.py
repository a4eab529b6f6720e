"""`fmscell plc check` and `fmscell plc run` through the real command line."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from pymodbus.client import ModbusTcpClient
from typer.testing import CliRunner

from plc.cli import plc_app

PROGRAMS = Path(__file__).parent / "programs"
runner = CliRunner()


def test_check_valid_program():
    result = runner.invoke(plc_app, ["check", str(PROGRAMS / "spindle.ld")])
    assert result.exit_code == 0, result.output
    assert "OK, program 'spindle': 8 rungs" in result.output


def test_check_plcopen_and_export():
    result = runner.invoke(plc_app, ["check", str(PROGRAMS / "openplc_seal_in.xml"), "--export"])
    assert result.exit_code == 0, result.output
    assert "BST XIC Start NXB XIC Motor BND XIO Stop OTE Motor" in result.output


def test_check_prints_warnings_and_exits_0(tmp_path):
    f = tmp_path / "w.ld"
    f.write_text("XIC %IX0.0 OTE %QX0.0\nXIC %IX0.1 OTE %QX0.0\n")
    result = runner.invoke(plc_app, ["check", str(f)])
    assert result.exit_code == 0
    assert f"{f}:2:16: warning: duplicate output" in result.output


def test_check_errors_exit_1_with_file_line_col(tmp_path):
    f = tmp_path / "e.ld"
    f.write_text("TAG A : BOOL AT %IX0.0\n\nXIC A FOO %QX0.0\nXIC A OTE %IW1\n")
    result = runner.invoke(plc_app, ["check", str(f)])
    assert result.exit_code == 1
    lines = [ln for ln in result.output.splitlines() if ln.startswith(str(f) + ":")]
    assert lines[0] == f"{f}:3:7: error: unknown instruction 'FOO'"
    assert lines[1].startswith(f"{f}:4:11: error: OTE needs a writable bit")


def test_check_missing_file_and_watchdog_estimate(tmp_path):
    result = runner.invoke(plc_app, ["check", str(tmp_path / "nope.ld")])
    assert result.exit_code == 1 and "no such file" in result.output
    f = tmp_path / "big.ld"
    f.write_text("XIC %IX0.0 OTL %QX0.0\n" * 200)
    result = runner.invoke(plc_app, ["check", str(f), "--watchdog-ms", "0.01"])
    assert result.exit_code == 1 and "exceeds the watchdog" in result.output


def test_run_serves_the_image_over_modbus_until_interrupted():
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from server.cli import main; main()",
            "plc",
            "run",
            str(PROGRAMS / "spindle.ld"),
            "--modbus-port",
            "0",
            "--period-ms",
            "10",
            "--writable",
            "%MW0-%MW9",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        line = proc.stdout.readline()
        m = re.search(r"Modbus TCP on 127\.0\.0\.1:(\d+)", line)
        assert m, line + proc.stderr.read()
        client = ModbusTcpClient("127.0.0.1", port=int(m.group(1)), timeout=10)
        assert client.connect()
        try:
            assert not client.write_register(1024, 1500).isError()  # %MW0 = SetSpeed
            # The write is applied by a later scan of a real-time process: poll to a
            # generous deadline, not a read count (100 reads can take less than one scan).
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                rr = client.read_holding_registers(1024, count=1)
                if not rr.isError() and rr.registers == [1500]:
                    break
            assert rr.registers == [1500]
            coils = client.read_coils(0, count=2)
            assert coils.bits[:2] == [False, False]  # spindle off, no alarm
            assert client.write_register(0, 5).isError()  # %QW0 is read-only
        finally:
            client.close()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()  # never leave the server running after a failed test
            proc.communicate()
            raise
    assert proc.returncode == 0, err
    assert "stopped after" in out and "mode RUN" in out


def test_run_refuses_a_bad_program(tmp_path):
    f = tmp_path / "bad.ld"
    f.write_text("XIC Nope OTE %QX0.0\n")
    result = runner.invoke(plc_app, ["run", str(f), "--duration-s", "0.1"])
    assert result.exit_code == 1 and f"{f}:1:5: error: undeclared tag 'Nope'" in result.output


def test_run_with_scan_gate_and_rt_priority_reports_the_scheduling():
    result = runner.invoke(
        plc_app,
        [
            "run",
            str(PROGRAMS / "spindle.ld"),
            "--modbus-port",
            "0",
            "--duration-s",
            "0.2",
            "--scan-gate",
            "--rt-priority",
            "5",
        ],
    )
    assert result.exit_code == 0, result.output
    # granted (root / CAP_SYS_NICE) or refused with the reason: either way it is reported
    assert "scan thread scheduling: " in result.output and "mode RUN" in result.output


def test_run_refuses_a_malformed_rt_priority_environment(monkeypatch):
    monkeypatch.setenv("FMSCELL_PLC_RT_PRIORITY", "high")
    result = runner.invoke(
        plc_app, ["run", str(PROGRAMS / "spindle.ld"), "--modbus-port", "0", "--duration-s", "0.1"]
    )
    assert result.exit_code == 2
    assert "FMSCELL_PLC_RT_PRIORITY='high': not an integer" in result.output
