# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Programs over HTTP: upload (JSON and multipart), search with cursor pages, one program,
new revisions, and every refusal as a problem with nothing stored."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from dnc import models as m
from dnc.db import transaction
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    SQLITE_ONLY,
    UPLOAD_LIMIT,
    api,
    assert_problem,
    engine,
    pg_url,
    sessions,
    sqlite_template,
)


def stored(api) -> tuple[int, int, int]:
    """(programs, revisions, audit entries): a refusal must change none of them."""
    with transaction(api.sessions) as s:
        return tuple(
            s.scalar(select(func.count()).select_from(t))
            for t in (m.Program, m.Revision, m.AuditEntry)
        )


def test_json_upload_gives_the_program_and_its_checked_first_revision(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        json={
            "number": 1001,
            "name": "bracket",
            "text": GOOD,
            "tags": ["op10", "alu"],
            "description": "left bracket",
        },
    )
    assert r.status_code == 201, r.text
    body = r.json()
    prog, rev = body["program"], body["revision"]
    assert r.headers["location"] == f"/api/programs/{prog['id']}"
    assert (prog["number"], prog["name"], prog["tags"]) == (1001, "bracket", ["alu", "op10"])
    assert prog["latest_revision_id"] == rev["id"] and prog["released_revision_id"] is None
    assert rev["status"] == "draft" and rev["check_ok"] and rev["check_errors"] == []
    assert rev["author"] == "programmer-user" and rev["seq"] == 1
    assert rev["lines"] == GOOD.count("\n")


def test_nc_check_failures_are_stored_with_line_and_column(api):
    body = api.upload(1002, "O1002\nG0 X0\nG1 BAD\nM30\n")
    rev = body["revision"]
    assert rev["check_ok"] is False
    assert rev["check_errors"] == [
        {"line": 3, "col": 4, "message": "bad word", "machine_kind": None}
    ]


def test_multipart_file_upload_takes_number_and_name_from_the_tape(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        files={"file": ("bracket.nc", GOOD.encode(), "text/plain")},
        data={"tags": "op10, alu"},
    )
    assert r.status_code == 201, r.text
    prog, rev = r.json()["program"], r.json()["revision"]
    assert (prog["number"], prog["name"], prog["tags"]) == (1001, "BRACKET", ["alu", "op10"])
    assert rev["comment"] == "uploaded as bracket.nc"
    text = api.get(f"/api/revisions/{rev['id']}/text")
    assert text.text == GOOD


def test_eight_digit_o_numbers_upload_list_and_search(api):
    """O numbers run 1..99999999 (Fanuc 8-digit option): from the tape header and by JSON."""
    tape = "%\nO80000001 (MAIN)\nG0 X10\nM30\n%\n"
    r = api.post("/api/programs", role="programmer",
                 files={"file": ("main.nc", tape.encode(), "text/plain")})  # fmt: skip
    assert r.status_code == 201, r.text
    assert r.json()["program"]["number"] == 80000001
    assert api.upload(99999999, GOOD)["program"]["number"] == 99999999
    assert [p["number"] for p in api.get("/api/programs?number=80000001").json()["items"]] == [
        80000001
    ]
    assert [p["number"] for p in api.get("/api/programs?q=O99999999").json()["items"]] == [99999999]
    # a longer digit string is no O number: no match, never a database error
    assert api.get("/api/programs?q=O123456789012345678901").json()["items"] == []
    r = api.post("/api/programs", role="programmer",
                 files={"file": ("big.nc", b"O123456789\nM30\n", "text/plain")})  # fmt: skip
    assert r.status_code == 422 and "#/number" in r.text and "99999999" in r.text, r.text


@SQLITE_ONLY
def test_multipart_fields_override_the_tape_header(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        files={"file": ("x.ngc", GOOD.encode())},
        data={"number": "77", "name": "override", "machine_kind": "lathe"},
    )
    assert r.status_code == 201, r.text
    prog = r.json()["program"]
    assert (prog["number"], prog["name"], prog["machine_kind"]) == (77, "override", "lathe")


@SQLITE_ONLY
def test_multipart_without_a_number_anywhere_points_at_number(api):
    before = stored(api)
    r = api.post("/api/programs", role="programmer", files={"file": ("x.nc", b"G0 X1\nM30\n")})
    body = assert_problem(r, 422, "validation")
    assert {"pointer": "#/number", "location": "body"}.items() <= body["errors"][0].items()
    assert stored(api) == before


@SQLITE_ONLY
def test_multipart_without_file_part(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        data={"number": "5", "name": "x"},
        files={"attachment": ("a.nc", GOOD.encode())},
    )
    body = assert_problem(r, 422, "validation")
    assert body["errors"][0]["pointer"] == "#/file"


def test_list_searches_and_pages_with_cursor_and_link(api):
    for n in range(1, 6):
        api.upload(n, GOOD, tags=["even"] if n % 2 == 0 else [])
    seen, url = [], "/api/programs?limit=2"
    while url:
        r = api.get(url)
        assert r.status_code == 200, r.text
        page = r.json()
        seen += [p["number"] for p in page["items"]]
        link = r.headers.get("link")
        if page["next_cursor"]:
            assert link == f'</api/programs?limit=2&cursor={page["next_cursor"]}>; rel="next"'
            url = link[1 : link.index(">")]
        else:
            assert link is None
            url = None
    assert seen == [1, 2, 3, 4, 5]
    assert [p["number"] for p in api.get("/api/programs?tag=even").json()["items"]] == [2, 4]
    assert [p["number"] for p in api.get("/api/programs?number=3").json()["items"]] == [3]
    assert [p["number"] for p in api.get("/api/programs?q=O0004").json()["items"]] == [4]
    assert len(api.get("/api/programs?text=X10").json()["items"]) == 5
    assert api.get("/api/programs?machine_kind=lathe").json()["items"] == []


@SQLITE_ONLY
def test_link_keeps_the_search_parameters(api):
    for n in (1, 2, 3):
        api.upload(n, GOOD, tags=["t"])
    r = api.get("/api/programs?tag=t&limit=1")
    assert r.headers["link"].startswith("</api/programs?tag=t&limit=1&cursor=")


@SQLITE_ONLY
@pytest.mark.parametrize("cursor", ["%%%", "bm9wZQ", "ajU"])
def test_foreign_cursor_is_a_400_problem(api, cursor):
    assert_problem(api.get(f"/api/programs?cursor={cursor}"), 400, "invalid-cursor")


def test_one_program_with_revisions_and_resources(api):
    pid = api.upload(1001)["program"]["id"]
    r = api.post(
        f"/api/programs/{pid}/revisions",
        role="programmer",
        json={"text": GOOD.replace("X10", "X12"), "comment": "longer"},
    )
    assert r.status_code == 201, r.text
    assert r.headers["location"] == f"/api/revisions/{r.json()['id']}"
    assert (r.json()["seq"], r.json()["comment"]) == (2, "longer")
    tool = api.library.add_resource("tool", "T01", description="end mill 10")
    api.library.link_resource(pid, tool)
    detail = api.get(f"/api/programs/{pid}").json()
    assert [x["seq"] for x in detail["revisions"]] == [1, 2]
    assert detail["latest_revision_id"] == r.json()["id"]
    assert [(x["kind"], x["code"]) for x in detail["resources"]] == [("tool", "T01")]


@SQLITE_ONLY
def test_revision_by_multipart_file(api):
    pid = api.upload(1001)["program"]["id"]
    r = api.post(
        f"/api/programs/{pid}/revisions",
        role="programmer",
        files={"file": ("v2.nc", GOOD.replace("X10", "X11").encode())},
    )
    assert r.status_code == 201, r.text
    assert r.json()["comment"] == "uploaded as v2.nc"


def test_unknown_program(api):
    assert_problem(api.get("/api/programs/999"), 404, "not-found")
    r = api.post("/api/programs/999/revisions", role="programmer", json={"text": GOOD})
    assert "no program with id 999" in assert_problem(r, 404, "not-found")["detail"]


def test_duplicate_number_is_a_conflict_and_stores_nothing(api):
    api.upload(1001)
    before = stored(api)
    r = api.post(
        "/api/programs", role="programmer", json={"number": 1001, "name": "x", "text": GOOD}
    )
    body = assert_problem(r, 409, "conflict")
    assert "O1001 already exists" in body["detail"] and body["program_id"] >= 1
    assert stored(api) == before


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("content", "ctype", "status", "kind", "says"),
    [
        (b'{"number": 1, "name": ', "application/json", 400, "malformed-json", "not valid JSON"),
        (b"[1, 2]", "application/json", 422, "validation", "should be an object"),
        (b"number=1", "application/x-www-form-urlencoded", 415, "unsupported-media-type", "send"),
        (b"", "", 415, "unsupported-media-type", "no content type"),
    ],
)
def test_malformed_bodies(api, content, ctype, status, kind, says):
    before = stored(api)
    r = api.post(
        "/api/programs", role="programmer", content=content, headers={"content-type": ctype}
    )
    assert says in assert_problem(r, status, kind)["detail"]
    assert stored(api) == before


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("body", "pointer", "says"),
    [
        ({"number": "ten", "name": "x", "text": GOOD}, "#/number", "valid integer"),
        ({"number": 100000000, "name": "x", "text": GOOD}, "#/number", "less than or equal"),
        ({"number": 1, "name": "", "text": GOOD}, "#/name", "at least 1"),
        ({"number": 1, "name": "a\x00b", "text": GOOD}, "#/name", "pattern"),
        ({"number": 1, "name": "x"}, "#/text", "required"),
        ({"number": 1, "name": "x", "text": GOOD, "tags": ["a,b"]}, "#/tags/0", "pattern"),
        ({"number": 1, "name": "x", "text": GOOD, "colour": "red"}, "#/colour", "not permitted"),
    ],
)
def test_wrong_types_point_at_the_field(api, body, pointer, says):
    before = stored(api)
    r = api.post("/api/programs", role="programmer", json=body)
    problem = assert_problem(r, 422, "validation")
    assert problem["errors"][0]["pointer"] == pointer
    assert says in problem["errors"][0]["detail"]
    assert stored(api) == before


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("   \n%\n", "empty"),
        ("O1\nG0 X1\x01\n", "binary data (control character 0x01) at offset 8"),
    ],
)
def test_refused_program_text_says_why(api, text, says):
    before = stored(api)
    r = api.post("/api/programs", role="programmer", json={"number": 1, "name": "x", "text": text})
    assert says in assert_problem(r, 422, "invalid-upload")["detail"]
    assert stored(api) == before


@SQLITE_ONLY
def test_invalid_utf8_file_gives_the_byte_offset(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        files={"file": ("x.nc", b"O0001\nG0 X\xff1\n")},
    )
    body = assert_problem(r, 422, "invalid-upload")
    assert "invalid UTF-8 at byte offset 10" in body["detail"] and body["offset"] == 10


def test_oversized_uploads_are_413_in_every_form(api):
    before = stored(api)
    big = "O0001\n" + "G1 X1\n" * (UPLOAD_LIMIT // 6 + 10)
    r = api.post("/api/programs", role="programmer", json={"number": 1, "name": "x", "text": big})
    body = assert_problem(r, 413, "upload-too-large")
    assert f"limit of {UPLOAD_LIMIT} bytes" in body["detail"] and body["limit"] == UPLOAD_LIMIT
    r = api.post("/api/programs", role="programmer", files={"file": ("big.nc", big.encode())})
    assert_problem(r, 413, "upload-too-large")
    huge = b"x" * (3 * UPLOAD_LIMIT + 70_000)  # above the raw request limit: never read
    r = api.post(
        "/api/programs",
        role="programmer",
        content=huge,
        headers={"content-type": "application/json"},
    )
    assert "exceeds the limit" in assert_problem(r, 413, "upload-too-large")["detail"]
    pid = api.upload(2)["program"]["id"]
    r = api.post(f"/api/programs/{pid}/revisions", role="programmer", json={"text": big})
    assert_problem(r, 413, "upload-too-large")
    assert stored(api)[0] == before[0] + 1 and stored(api)[1] == before[1] + 1


@SQLITE_ONLY
def test_chunked_body_over_the_limit_is_refused_while_streaming(api):
    def chunks():
        for _ in range(100):
            yield b"x" * 1000

    r = api.post(
        "/api/programs",
        role="programmer",
        content=chunks(),
        headers={"content-type": "application/json"},
    )
    assert "at least" in assert_problem(r, 413, "upload-too-large")["detail"]
