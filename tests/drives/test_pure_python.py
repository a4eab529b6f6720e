"""The compiled drive modules (mypyc, `drives/*/mypyc.list`) compute what their Python
sources compute.

The .py files stay the reference. A copy of `drives` without any extension module runs in a
subprocess (so only the sources can be imported) and must give the same candump hash for a
scenario that homes, follows ramps and trips an encoder fault, and pass the plant theory and
fast-path tests. Without compiled modules both sides are plain Python and the test is a
determinism check.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Runs inside the copy: where the listed modules came from, then the scenario's hash.
PROBE = """
import importlib, sys
for name in sys.argv[1:]:
    print(importlib.import_module(name).__file__)
from tests.drives.test_axis_group import _scenario
print(_scenario())
"""


def compiled_module_names() -> list[str]:
    """Every module named in a drives `mypyc.list`, as a dotted name."""
    names = []
    for listing in sorted((ROOT / "drives").rglob("mypyc.list")):
        for line in listing.read_text().splitlines():
            line = line.split("#", 1)[0].strip()
            if line:
                path = (listing.parent / line).relative_to(ROOT).with_suffix("")
                names.append(".".join(path.parts))
    return names


@pytest.fixture(scope="module")
def pure_copy(tmp_path_factory) -> Path:
    """`drives` and `tests/drives` copied without extension modules and caches."""
    root = tmp_path_factory.mktemp("pure")
    skip = shutil.ignore_patterns("*.so", "*.pyd", "__pycache__")
    shutil.copytree(ROOT / "drives", root / "drives", ignore=skip)
    shutil.copytree(ROOT / "tests" / "drives", root / "tests" / "drives", ignore=skip)
    shutil.copy(ROOT / "tests" / "__init__.py", root / "tests" / "__init__.py")
    (root / "pytest.ini").write_text("[pytest]\npythonpath = .\n")
    return root


def _run(root: Path, *args: str) -> subprocess.CompletedProcess:
    # PYTHONPATH puts the copy before the editable install's finder (a meta-path hook that
    # comes after the path-based one)
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.run(
        [sys.executable, *args], cwd=root, env=env, capture_output=True, text=True, timeout=240
    )


def test_candump_hash_of_the_sources_equals_this_process(pure_copy):
    from tests.drives.test_axis_group import _scenario

    names = compiled_module_names()
    assert "drives.plant.plant" in names
    proc = _run(pure_copy, "-c", PROBE, *names)
    assert proc.returncode == 0, proc.stderr
    *files, pure_hash = proc.stdout.split()
    for name, file in zip(names, files, strict=True):
        assert file == str(pure_copy.joinpath(*name.split(".")).with_suffix(".py")), name
    assert pure_hash == _scenario()


def test_plant_theory_and_fast_paths_pass_on_the_sources(pure_copy):
    proc = _run(
        pure_copy,
        "-m",
        "pytest",
        "-q",
        "-p",
        "no:cacheprovider",
        "-c",
        "pytest.ini",
        "tests/drives/test_plant_theory.py",
        "tests/drives/test_fast_paths.py",
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
