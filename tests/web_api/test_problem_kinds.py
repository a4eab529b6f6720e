"""Every refusal of the DNC host (a DncError) has its problem type, status and title in
web_api/problems.py, the one place they are mapped, and its row in docs/api.md."""

from __future__ import annotations

import re
from pathlib import Path

import dnc.dependencies  # noqa: F401 - MissingDependency lives there
import dnc.posting  # noqa: F401 - PostRefused lives there
from dnc.errors import DncError
from web_api.problems import STATUS_OF_KIND, TITLES

API_DOC = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def _refusals(cls: type) -> list[type]:
    return [c for sub in cls.__subclasses__() for c in (sub, *_refusals(sub))]


def test_every_host_refusal_is_mapped_once_and_documented():
    kinds = {c.kind: c.__name__ for c in _refusals(DncError)}
    assert set(kinds) == set(STATUS_OF_KIND), "a DncError kind without a status, or the reverse"
    doc = API_DOC.read_text()
    for kind, status in STATUS_OF_KIND.items():
        assert kind in TITLES, f"{kinds[kind]}: no title for {kind!r}"
        assert re.search(rf"^\| `{kind}` \| {status} \|", doc, re.M), f"docs/api.md: {kind}"
