"""The dependency direction between the top-level packages (docs/architecture.md).

Every import of one of our packages from another, at module level or inside a function, is
checked against the allowed direction; a new edge against it fails here with the file and
line, so the layering stays what the docs say. An import of our own packages inside a
function must say why it is not at module level (`# deferred: <reason>`)."""

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


# A function-level import of our own packages is explained by this comment on its line or
# just above the run of import statements it belongs to (the comment may continue on the
# following comment lines).
DEFERRED = "# deferred:"

# Files exempt from the rule (none: cnc/config.py's were moved to module level last).
NOT_YET_EXPLAINED: frozenset[str] = frozenset()


def _own(node: ast.Import | ast.ImportFrom) -> bool:
    if isinstance(node, ast.Import):
        return any(a.name.split(".")[0] in ALLOWED for a in node.names)
    return node.level > 0 or (node.module or "").split(".")[0] in ALLOWED


def _explained(node: ast.stmt, body: list[ast.stmt], lines: list[str]) -> bool:
    if any(DEFERRED in lines[n - 1] for n in range(node.lineno, (node.end_lineno or 0) + 1)):
        return True
    # upwards over the imports just above it (a comment ending one of them is its own) and
    # comment lines, to the first line that is neither (say `try:`): a `# deferred:` comment
    # met on the way, or ending that line, explains the whole run
    ends = {s.end_lineno: s for s in body if isinstance(s, ast.Import | ast.ImportFrom)}
    n = node.lineno - 1
    while n >= 1:
        line = lines[n - 1].strip()
        if n in ends:
            n = ends[n].lineno - 1
        elif DEFERRED in line:
            return True
        elif line.startswith("#"):
            n -= 1
        else:
            return False
    return False


def unexplained_function_imports(path: Path) -> list[tuple[int, str]]:
    """(line, statement) of each import of our packages inside a function with no reason."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    found = []
    for fn in ast.walk(ast.parse(text, str(path))):
        if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        bodies = [fn.body] + [
            getattr(n, field)
            for n in ast.walk(fn)
            if n is not fn and not isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)
            for field in ("body", "orelse", "finalbody", "handlers")
            if isinstance(getattr(n, field, None), list)
        ]
        for body in bodies:
            for node in body:
                own = isinstance(node, ast.Import | ast.ImportFrom) and _own(node)
                if own and not _explained(node, body, lines):
                    found.append((node.lineno, ast.unparse(node)))
    return sorted(set(found))


def function_level_imports_without_a_reason() -> list[str]:
    bad = []
    for package in sorted(ALLOWED):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if "migrations" in path.parts or rel in NOT_YET_EXPLAINED:
                continue
            bad += [f"{rel}:{line}: {stmt}" for line, stmt in unexplained_function_imports(path)]
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


def test_function_level_imports_of_our_packages_say_why():
    """Imports of our own packages belong at module level; one inside a function stays only
    with a `# deferred: <reason>` comment (a start-up cost, an optional dependency, a cycle)."""
    assert function_level_imports_without_a_reason() == []


def test_the_check_sees_a_function_level_import_without_a_reason(tmp_path):
    source = tmp_path / "m.py"
    source.write_text(
        "import json\n"
        "def f():\n"
        "    import os\n"  # not ours: free to stay
        "    from cnc.errors import NcError\n"  # run of imports: one reason for both
        "    # deferred: the web stack costs a second at start-up\n"
        "    # (only `run` needs it)\n"
        "    from web_api.app import create_app\n"
        "    from dnc.db import make_engine\n"
        "    x = 1\n"
        "    from drives.bus import open_bus\n"
        "    if x:\n"
        "        from plc.modbus import ModbusFace  # deferred: pymodbus is optional\n"
        "        from plc.runtime import Runtime\n"
        "    try:  # deferred: optional in some builds\n"
        "        from cnc.cutter_comp import CutterCompensation\n"
        "    except ImportError:\n"
        "        from cnc.machine import Machine\n"
        "    def g():\n"
        "        from . import sibling\n"
        "    return NcError, create_app, make_engine, open_bus, ModbusFace, Runtime, g\n"
    )
    assert unexplained_function_imports(source) == [
        (4, "from cnc.errors import NcError"),
        (10, "from drives.bus import open_bus"),
        (13, "from plc.runtime import Runtime"),
        (17, "from cnc.machine import Machine"),
        (19, "from . import sibling"),
    ]


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
