"""Every YAML snippet in the docs that is a cell or machine file is accepted by the loader
(server.config and cnc.config; a 5-axis post description by cam.machine5), so a reader who copies one gets a
working file."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from cam.machine5 import load_mill5
from cnc.config import load_machine_config
from server.config import load_cell_config

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
FENCE = re.compile(r"^```ya?ml[^\n]*\n(.*?)^```", re.S | re.M)
# A machine so that a snippet showing only `host:` is a whole cell file.
ONE_MACHINE = {"m1": {"base": "mill3"}}


def snippets() -> list[tuple[str, str]]:
    out = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            line = text[: m.start()].count("\n") + 2  # the snippet's first line
            out.append((f"{path.relative_to(ROOT)}:{line}", m.group(1)))
    return out


SNIPPETS = snippets()


def test_the_docs_have_config_snippets():
    where = {w.split(":")[0] for w, _ in SNIPPETS}
    assert {"docs/api.md", "docs/cell.md", "docs/configuration.md"} <= where


@pytest.mark.parametrize(("where", "text"), SNIPPETS, ids=[w for w, _ in SNIPPETS])
def test_yaml_snippet_is_accepted_by_the_loader(where, text):
    doc = yaml.safe_load(text)
    assert isinstance(doc, dict), f"{where}: a YAML snippet in the docs is a mapping"
    if "machines" in doc:
        load_cell_config(doc)
    elif set(doc) <= {"host"}:
        load_cell_config({"machines": ONE_MACHINE, **doc})
    elif doc.get("kind") == "mill5" and "kinematics" in doc:
        load_mill5(doc)  # the CAM post's description of the 5-axis machine (docs/cam.md)
    elif "kind" in doc or "base" in doc:
        load_machine_config(doc)
    else:
        pytest.fail(f"{where}: neither a cell file nor a machine file: {sorted(doc)}")


def test_a_wrong_key_in_a_snippet_would_be_caught():
    """The old docs/api.md snippet (`host.api.api_keys`) is refused, naming the key."""
    old = {"host": {"api": {"api_keys": [{"user": "a", "role": "viewer", "key": "x" * 16}]}}}
    with pytest.raises(Exception, match="host.api"):
        load_cell_config({"machines": ONE_MACHINE, **old})
