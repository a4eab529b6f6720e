"""The examples in docs/ladder.md compile, and the sample programs check clean."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from plc.ladder import check_file, compile_text
from plc.runtime import Runtime

ROOT = Path(__file__).resolve().parents[2]


def test_first_program_in_the_docs_compiles_and_runs():
    doc = (ROOT / "docs" / "ladder.md").read_text()
    section = doc.split("## 1. A first program", 1)[1]
    code = re.search(r"```\n(.*?)```", section, re.S).group(1)
    rt = Runtime(compile_text(code, "doc.ld"))
    rt.write_once("StartPb", True)
    rt.write_once("StopPb", True)
    rt.write_once("SetSpeed", 1500)
    rt.scan(0)
    assert rt.read("SpindleOn") is True and rt.read("SpeedRef") == 1500
    rt.scan(5000)  # no at-speed within 5 s
    rt.scan(5010)
    assert rt.read("AlarmLamp") is True and rt.read("SpindleOn") is False


@pytest.mark.parametrize("name", ["spindle.ld", "openplc_seal_in.xml"])
def test_sample_programs_check_clean(name):
    assert check_file(str(ROOT / "tests" / "plc" / "programs" / name)) == []
