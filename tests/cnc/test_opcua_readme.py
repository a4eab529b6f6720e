"""The README's OPC UA commands work as written (the asyncua command-line tools against a
machine's OPC UA face), on a free port instead of 4841."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cnc.faces.loop_thread import LoopThread
from cnc.faces.opcua import OpcUaFace
from cnc.status import MachineStatus

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()
SECTION = README[README.index("## Browse a machine with an OPC UA client") :]
SECTION = SECTION[: SECTION.index("\n## ", 3)]
BIN = Path(sys.executable).parent


def commands() -> list[list[str]]:
    block = re.search(r"```sh\n(.*?)```", SECTION, re.S).group(1)
    return [shlex.split(line) for line in block.splitlines() if line.startswith(".venv/bin/")]


@pytest.fixture(scope="module")
def face():
    f = OpcUaFace("mill1", ("X", "Y", "Z"))
    loop = LoopThread("opcua-readme").start()
    loop.run(f.start, timeout=120)
    f.publish(MachineStatus(execution="ACTIVE", program="O1001", line=12), time.time())
    yield f
    loop.run(f.stop)
    loop.stop()


def run(argv: list[str], face: OpcUaFace, timeout: float) -> subprocess.CompletedProcess:
    argv = [str(BIN / Path(argv[0]).name)] + [
        a.replace("opc.tcp://127.0.0.1:4841", face.address) for a in argv[1:]
    ]
    return subprocess.run(argv, capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def test_the_readme_browses_and_reads_a_machine(face):
    cmds = {c[0].rsplit("/", 1)[1]: c for c in commands()}
    assert {"uals", "uaread", "uasubscribe"} <= set(cmds)
    listing = run(cmds["uals"], face, 120)
    assert listing.returncode == 0, listing.stderr
    for name in (
        "2:Identification",
        "5:Monitoring",
        "5:Production",
        "5:Notification",
        "5:Equipment",
    ):
        assert name in listing.stdout, listing.stdout
    # the state the README shows is the one published (ACTIVE = 0 Active)
    for _ in range(100):
        read = run(cmds["uaread"], face, 120)
        if read.stdout.strip().splitlines()[-1:] == ["0"]:
            break
        time.sleep(0.05)
    assert read.stdout.strip().splitlines()[-1] == "0", (read.stdout, read.stderr)
