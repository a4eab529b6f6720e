"""The mypyc-compiled modules (setup.py, `mypyc.list` files) must never shadow newer sources.

Python imports `geometry.cpython-311-….so` before `geometry.py`, so an edit to a compiled
module is invisible until the extension is rebuilt. `make test` rebuilds when a listed source
changes; this test catches a run that bypassed it (plain `pytest` after an edit).
"""

from __future__ import annotations

import importlib.machinery
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def listed_modules() -> list[Path]:
    modules = []
    for listing in sorted(ROOT.glob("*/**/mypyc.list")):
        for line in listing.read_text().splitlines():
            line = line.split("#", 1)[0].strip()
            if line:
                modules.append(listing.parent / line)
    return modules


def extensions_of(source: Path) -> list[Path]:
    return [
        source.with_name(source.stem + suffix)
        for suffix in importlib.machinery.EXTENSION_SUFFIXES
        if source.with_name(source.stem + suffix).exists()
    ]


@pytest.mark.parametrize("source", listed_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_listed_module_exists_and_its_extension_is_not_stale(source: Path) -> None:
    assert source.is_file(), f"{source.parent / 'mypyc.list'} names a missing module {source.name}"
    for ext in extensions_of(source):
        assert ext.stat().st_mtime >= source.stat().st_mtime, (
            f"{ext.relative_to(ROOT)} is older than {source.relative_to(ROOT)}: "
            "run `make test` (or `pip install -e .`) to rebuild it"
        )


def test_no_extension_without_a_listing() -> None:
    """An extension left behind after its module left the list would still be imported."""
    listed = {p.with_suffix("") for p in listed_modules()}
    for package in ("cam", "cnc", "drives", "plc", "dnc", "server", "web_api"):
        for ext in (ROOT / package).rglob("*.so"):
            stem = ext.with_name(ext.name.split(".", 1)[0])
            assert stem in listed, f"{ext.relative_to(ROOT)} is not in any mypyc.list: delete it"
