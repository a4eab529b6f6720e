"""`fmscell plc run --machine-io`: the machine-tool program runs against the simulated machine."""

import subprocess
import sys


def test_machine_program_runs_standalone_with_the_simulated_machine():
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "server.cli",
            "plc",
            "run",
            "plc/programs/machine_tool.ld",
            "--machine-io",
            "--modbus-port",
            "0",
            "--duration-s",
            "0.5",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert "running:" in proc.stdout and "stopped after" in proc.stdout
    assert proc.stdout.rstrip().endswith("mode RUN")
