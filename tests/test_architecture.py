"""The dependency direction between the top-level packages (docs/architecture.md).

Every import of one of our packages from another, at module level or inside a function, is
checked against the allowed direction; a new edge against it fails here with the file and
line, so the layering stays what the docs say."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# package -> the packages it may import (the layers below it). `server` composes the cell
# from all of them; nothing imports `server`.
ALLOWED: dict[str, frozenset[str]] = {
    "drives": frozenset(),
    "plc": frozenset(),
    "cnc": frozenset({"drives", "plc"}),
    "cam": frozenset({"cnc"}),
    "mtconnect": frozenset({"cnc"}),
    "dnc": frozenset({"cnc", "cam"}),
    "web_api": frozenset({"dnc", "mtconnect", "cnc", "cam"}),
    "server": frozenset({"drives", "plc", "cnc", "cam", "mtconnect", "dnc", "web_api"}),
}


def imports_of(path: Path) -> list[tuple[int, str]]:
    """(line, top-level package) of every absolute import in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name.split(".")[0]) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module.split(".")[0]))
    return found


def edges_against_the_direction(package: str) -> list[str]:
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        if "migrations" in path.parts:
            continue
        for line, top in imports_of(path):
            if top in ALLOWED and top != package and top not in ALLOWED[package]:
                bad.append(f"{path.relative_to(ROOT)}:{line}: {package} imports {top}")
    return bad


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_no_package_imports_against_the_direction(package):
    assert (ROOT / package / "__init__.py").is_file()
    assert edges_against_the_direction(package) == []


def test_the_check_sees_an_import_against_the_direction(tmp_path, monkeypatch):
    """The check itself: a function-level `from server...` in web_api is found."""
    fake = tmp_path / "web_api"
    fake.mkdir()
    (fake / "__init__.py").write_text("")
    (fake / "r.py").write_text("def f():\n    from server.cell import Cell\n    return Cell\n")
    monkeypatch.setattr(__import__(__name__, fromlist=["ROOT"]), "ROOT", tmp_path)
    assert edges_against_the_direction("web_api") == ["web_api/r.py:2: web_api imports server"]


def test_the_cell_implements_the_contract_web_api_sees():
    """Every method of dnc.cell.CellControl is on server.cell.Cell with the same parameters."""
    import inspect

    from dnc.cell import CellControl
    from server.cell import Cell

    wanted = [n for n, v in vars(CellControl).items() if callable(v) and not n.startswith("_")]
    assert sorted(wanted) == [
        "clear", "command", "fault_types", "inject", "machine_data", "machine_faults",
    ]  # fmt: skip
    for name in wanted:
        ours = list(inspect.signature(getattr(CellControl, name)).parameters)
        theirs = list(inspect.signature(getattr(Cell, name)).parameters)
        assert theirs == ours, (name, theirs, ours)
