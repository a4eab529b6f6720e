# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Revisions over HTTP: read, text, release with the key's user as approver, diff."""

from __future__ import annotations

import hashlib

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    pg_url,
    sessions,
    sqlite_template,
)


def test_revision_and_its_text(api):
    rev = api.upload()["revision"]
    r = api.get(f"/api/revisions/{rev['id']}")
    assert r.status_code == 200 and r.json() == rev
    t = api.get(f"/api/revisions/{rev['id']}/text")
    assert t.status_code == 200 and t.headers["content-type"].startswith("text/plain")
    assert t.text == GOOD
    assert t.headers["etag"] == f'"{hashlib.sha256(GOOD.encode()).hexdigest()}"'


def test_a_large_revision_text_is_streamed_whole_with_its_length(api):
    """A text of several stored chunks (dnc.content) comes back exactly, chunk after chunk,
    with its Content-Length (a cut-off stream shows as one)."""
    from dnc.content import CHUNK_CHARS

    body = "".join(f"N{i} G1 X{i % 50}.5 Y{i % 7} F300\n" for i in range(40_000))
    big = f"%\nO77 (BIG)\n{body}M30\n%\n"
    assert len(big) > 3 * CHUNK_CHARS
    api.library.upload_limit = 4 << 20
    _, rev = api.library.create_program(number=77, name="big", text=big)
    t = api.get(f"/api/revisions/{rev.id}/text")
    assert t.status_code == 200 and t.headers["content-type"].startswith("text/plain")
    assert t.headers["content-length"] == str(len(big)) and t.text == big
    assert t.headers["etag"] == f'"{hashlib.sha256(big.encode()).hexdigest()}"'


def test_release_records_the_keys_user_and_supersedes_the_previous(api):
    first = api.released()
    pid = api.get(f"/api/revisions/{first}").json()["program_id"]
    second = api.post(
        f"/api/programs/{pid}/revisions", role="programmer", json={"text": GOOD + "(v2)\n"}
    ).json()["id"]
    r = api.post(
        f"/api/revisions/{second}/release", role="programmer", json={"comment": "tried on mill-1"}
    )
    assert r.status_code == 200, r.text
    rev = r.json()
    assert (rev["status"], rev["approved_by"], rev["approval_comment"]) == (
        "released",
        "programmer-user",
        "tried on mill-1",
    )
    assert api.get(f"/api/revisions/{first}").json()["status"] == "obsolete"
    assert api.get(f"/api/programs/{pid}").json()["released_revision_id"] == second


def test_release_refusals_say_why(api):
    bad = api.upload(2, "O0002\nG1 BAD\nM30\n")["revision"]["id"]
    r = api.post(f"/api/revisions/{bad}/release", role="programmer", json={"comment": "go"})
    body = assert_problem(r, 409, "workflow")
    assert "failed the NC check" in body["detail"] and body["errors"][0]["line"] == 2
    assert api.get(f"/api/revisions/{bad}").json()["status"] == "draft"
    done = api.released(3)
    r = api.post(f"/api/revisions/{done}/release", role="programmer", json={"comment": "again"})
    assert "only a draft can be released" in assert_problem(r, 409, "workflow")["detail"]


@SQLITE_ONLY
def test_release_needs_a_comment(api):
    rev = api.upload()["revision"]["id"]
    for body in ({}, {"comment": ""}):
        r = api.post(f"/api/revisions/{rev}/release", role="programmer", json=body)
        assert assert_problem(r, 422, "validation")["errors"][0]["pointer"] == "#/comment"


def test_diff_with_options(api):
    pid = api.upload(1, "O0001\nN10 G0 X0\nN20 G1 X10 (cut)\nM30\n")["program"]["id"]
    a = api.get(f"/api/programs/{pid}").json()["latest_revision_id"]
    b = api.post(
        f"/api/programs/{pid}/revisions",
        role="programmer",
        json={"text": "O0001\nN100 G0 X0\nN200 G1 X12 (cut deeper)\nM30\n"},
    ).json()["id"]
    r = api.get(f"/api/revisions/{a}/diff/{b}")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/x-diff")
    assert "-N20 G1 X10 (cut)" in r.text and "+N200 G1 X12 (cut deeper)" in r.text
    assert "-N10 G0 X0" in r.text
    r = api.get(f"/api/revisions/{a}/diff/{b}?ignore_numbers=true&ignore_comments=true")
    changed = [
        line
        for line in r.text.splitlines()
        if line[:1] in "+-" and not line.startswith(("---", "+++"))
    ]
    assert len(changed) == 2 and "X10" in changed[0] and "X12" in changed[1], changed
    same = api.get(f"/api/revisions/{a}/diff/{a}")
    assert same.status_code == 200 and same.text == ""


def test_unknown_revisions(api):
    rev = api.upload()["revision"]["id"]
    assert_problem(api.get("/api/revisions/424242"), 404, "not-found")
    assert_problem(api.get("/api/revisions/424242/text"), 404, "not-found")
    assert_problem(api.get(f"/api/revisions/{rev}/diff/424242"), 404, "not-found")
    r = api.post("/api/revisions/424242/release", role="programmer", json={"comment": "x"})
    assert "no revision with id 424242" in assert_problem(r, 404, "not-found")["detail"]


@SQLITE_ONLY
def test_ids_out_of_range_are_validation_problems(api):
    for url in ("/api/revisions/0", "/api/revisions/9999999999", "/api/revisions/abc"):
        body = assert_problem(api.get(url), 422, "validation")
        assert body["errors"][0] == {**body["errors"][0], "location": "path"}
        assert body["errors"][0]["parameter"] == "revision_id"
