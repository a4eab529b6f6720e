"""Every refusal of the DNC host (a DncError) has its problem type, status and title in
web_api/problems.py, the one place they are mapped, and its row in docs/api.md; so have
a failed transfer (a DncError whose `kind` is the line trouble) and the cell's CellError."""

from __future__ import annotations

import re
from pathlib import Path

from fastapi import FastAPI
from fastapi.testclient import TestClient

import dnc.dependencies  # noqa: F401 - MissingDependency lives there
import dnc.posting  # noqa: F401 - PostRefused lives there
from dnc.cell import MachineUnavailable
from dnc.errors import DncError
from dnc.transfer import TransferError
from web_api.problems import STATUS_OF_KIND, TITLES, install_problem_handlers

API_DOC = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def _refusals(cls: type) -> list[type]:
    # a TransferError's kind names the line trouble: it has a handler of its own
    subs = [s for s in cls.__subclasses__() if s is not TransferError]
    return [c for sub in subs for c in (sub, *_refusals(sub))]


def test_every_host_refusal_is_mapped_once_and_documented():
    kinds = {c.kind: c.__name__ for c in _refusals(DncError)}
    assert set(kinds) == set(STATUS_OF_KIND), "a DncError kind without a status, or the reverse"
    doc = API_DOC.read_text()
    for kind, status in STATUS_OF_KIND.items():
        assert kind in TITLES, f"{kinds[kind]}: no title for {kind!r}"
        assert re.search(rf"^\| `{kind}` \| {status} \|", doc, re.M), f"docs/api.md: {kind}"


def test_a_failed_transfer_and_an_unreachable_machine_are_documented_problems():
    doc = API_DOC.read_text()
    for kind, status in (("transfer-failed", 502), ("machine-unavailable", 503)):
        assert kind in TITLES
        assert re.search(rf"^\| `{kind}` \| {status} \|", doc, re.M), f"docs/api.md: {kind}"


def test_a_failed_transfer_and_a_cell_error_are_answered_as_their_problems():
    app = FastAPI()
    install_problem_handlers(app, "https://fmscell.dev/problems/")

    @app.get("/transfer")
    def transfer():
        raise TransferError("refused", "2002 memory full", alarm=2002)

    @app.get("/cell")
    def cell():
        raise MachineUnavailable("mill1: no answer on the simulation face")

    client = TestClient(app)
    r = client.get("/transfer")
    assert r.status_code == 502 and r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["type"].endswith("/transfer-failed")
    assert (body["detail"], body["transfer_kind"], body["alarm"]) == (
        "2002 memory full",
        "refused",
        2002,
    )
    r = client.get("/cell")
    assert r.status_code == 503
    assert r.json()["type"].endswith("/machine-unavailable")
    assert r.json()["detail"] == "mill1: no answer on the simulation face"
