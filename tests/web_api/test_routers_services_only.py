"""Routers call services only (docs/architecture.md): no router builds SQL or opens a
transaction; the queries are the `dnc` services'. The routers' shared module may name the
session types for the services' dependency, nothing more."""

from __future__ import annotations

import ast
from pathlib import Path

ROUTERS = Path(__file__).resolve().parents[2] / "web_api" / "routers"
# names a router may take from sqlalchemy: the session types (routers/__init__.py)
SESSION_TYPES = {"Session", "sessionmaker"}
DATABASE_CALLS = {"transaction", "select", "text", "update", "insert", "delete"}


def offences(path: Path) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            names = {a.name for a in node.names}
            if node.module.split(".")[0] == "sqlalchemy" and not names <= SESSION_TYPES:
                out.append(f"{path.name}:{node.lineno}: from {node.module} import {sorted(names)}")
            if (node.module == "dnc.db" and names & DATABASE_CALLS) or (
                node.module == "dnc.models" or (node.module == "dnc" and "models" in names)
            ):
                out.append(f"{path.name}:{node.lineno}: from {node.module} import {sorted(names)}")
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "sqlalchemy" or a.name == "dnc.models":
                    out.append(f"{path.name}:{node.lineno}: import {a.name}")
    return out


def test_no_router_builds_sql():
    found = [o for path in sorted(ROUTERS.glob("*.py")) for o in offences(path)]
    assert found == []


def test_the_check_sees_a_router_with_sql(tmp_path):
    bad = tmp_path / "r.py"
    bad.write_text("from sqlalchemy import select\nfrom dnc import models as m\n")
    assert offences(bad) == [
        "r.py:1: from sqlalchemy import ['select']",
        "r.py:2: from dnc import ['models']",
    ]
    worse = tmp_path / "w.py"
    worse.write_text("from dnc.db import transaction\nimport dnc.models\n")
    assert offences(worse) == [
        "w.py:1: from dnc.db import ['transaction']",
        "w.py:2: import dnc.models",
    ]
