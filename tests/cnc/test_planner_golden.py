"""The planner's output, bit for bit, as compiled and as plain Python.

The planner modules may be mypyc extensions (cnc/planner/mypyc.list); the Python sources
stay the reference. Both must reproduce the digests recorded in planner_golden.GOLDEN:
the modules as imported here (compiled when built), and the sources on their own, run in
a subprocess on a copy of `cnc/` that holds no extension modules.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cnc import planner_golden

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def digests() -> dict[str, str]:
    return planner_golden.digests()


@pytest.mark.parametrize("scenario", sorted(planner_golden.GOLDEN))
def test_planner_output_matches_the_golden_digest(digests, scenario):
    assert digests[scenario] == planner_golden.GOLDEN[scenario], (
        f"{scenario}: the planner's output changed (modules: {planner_golden.planner_files()})"
    )


def test_pure_python_sources_match_the_golden_digests(tmp_path):
    """The .py sources alone, whatever is compiled in the checkout."""
    shutil.copytree(
        ROOT / "cnc",
        tmp_path / "cnc",
        ignore=shutil.ignore_patterns("*.so", "*.pyd", "__pycache__"),
    )
    shutil.copy(Path(planner_golden.__file__), tmp_path / "planner_golden.py")
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PYTHONPATH"] = str(tmp_path)
    done = subprocess.run(
        [sys.executable, "planner_golden.py"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    for name, path in got["files"].items():
        assert path.endswith(".py") and path.startswith(str(tmp_path)), (name, path)
    assert got["digests"] == planner_golden.GOLDEN
