"""The generated doc sections shared by the fault tables and the G/M code tables."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from drives.generated_docs import GeneratedSections

ROOT = Path(__file__).resolve().parents[2]


def _sections() -> GeneratedSections:
    return GeneratedSections("pkg/table.py", {"one": lambda: "| 1 |\n", "two": lambda: "2\n"})


DOC = (
    "# Title\n"
    "<!-- generated from pkg/table.py: one -->\nstale\n<!-- end generated -->\n"
    "prose\n"
    "<!-- generated from other/source.py: one -->\nkept\n<!-- end generated -->\n"
    "<!-- generated from pkg/table.py: two -->\n<!-- end generated -->\n"
)


def test_sync_renders_this_sources_sections_and_leaves_the_rest():
    s = _sections()
    assert s.names(DOC) == ["one", "two"]
    synced = s.sync(DOC)
    assert synced == DOC.replace("stale\n", "| 1 |\n").replace(
        "two -->\n<!-- end", "two -->\n2\n<!-- end"
    )
    assert s.sync(synced) == synced


def test_an_unknown_section_is_named_with_its_line():
    text = "a\n<!-- generated from pkg/table.py: three -->\nx\n<!-- end generated -->\n"
    with pytest.raises(ValueError, match=r"doc.md:2: no generated section 'three' .*one, two"):
        _sections().sync(text, "doc.md")


@pytest.mark.parametrize(
    "text",
    [
        "\n\n<!-- generated from pkg/table.py: one -->\nno end\n",
        # the end marker that follows belongs to the next section
        "\n\n<!-- generated from pkg/table.py: one -->\nx\n"
        "<!-- generated from pkg/table.py: two -->\n<!-- end generated -->\n",
    ],
)
def test_a_section_without_its_end_marker_is_refused(text):
    with pytest.raises(ValueError, match=r"doc.md:3: generated section 'one' .* has no <!-- end"):
        _sections().names(text, "doc.md")


def test_rewrite_changes_only_the_stale_files(tmp_path):
    stale, fresh = tmp_path / "stale.md", tmp_path / "fresh.md"
    stale.write_text(DOC, encoding="utf-8")
    fresh.write_text(_sections().sync(DOC), encoding="utf-8")
    assert _sections().rewrite([stale, fresh]) == [stale]
    assert stale.read_text(encoding="utf-8") == fresh.read_text(encoding="utf-8")


@pytest.mark.parametrize(
    "module, source",
    [("drives.fault_docgen", "docs/drives.md"), ("cnc.interp.docgen", "docs/gcode.md")],
)
def test_the_entry_points_rewrite_a_stale_doc(tmp_path, module, source):
    doc = tmp_path / Path(source).name
    text = (ROOT / source).read_text(encoding="utf-8")
    end = text.index("<!-- end generated -->")
    doc.write_text(text[: end - 1] + "\n| a stale row |\n" + text[end:], encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, "-m", module, str(doc)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"{doc}: " in proc.stdout
    assert doc.read_text(encoding="utf-8") == text
