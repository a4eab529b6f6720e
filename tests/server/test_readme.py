"""What the README shows must work: every `fmscell ... check` example runs clean, every file
and doc it links exists."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from server.cli import app

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()


def test_readme_shows_the_two_commands():
    assert "make run" in README and "make test" in README


@pytest.mark.parametrize("link", sorted(set(re.findall(r"\]\(([^)#]+)\)", README))))
def test_linked_files_exist(link):
    assert (ROOT / link).exists(), link


CHECKS = [
    line.split("fmscell ", 1)[1]
    for line in README.splitlines()
    if line.startswith(".venv/bin/fmscell ") and " check " in line
]


def test_readme_has_check_examples():
    assert len(CHECKS) >= 2


@pytest.mark.parametrize("command", CHECKS)
def test_readme_check_examples_pass(command, monkeypatch):
    monkeypatch.chdir(ROOT)
    result = CliRunner().invoke(app, shlex.split(command))
    assert result.exit_code == 0, result.output
