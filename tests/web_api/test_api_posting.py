# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""APT and CL revisions over HTTP: upload of each kind, the post preview, dispatch posting
into derived revisions, and the refusals as problem documents."""

from __future__ import annotations

import hashlib
from pathlib import Path

from tests.cam.test_post import SEED15
from tests.dnc.test_posting import FIVE_AXIS_CL
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    pg_url,
    sessions,
    sqlite_template,
)

PLATE = (Path(__file__).resolve().parents[2] / "cam" / "examples" / "plate.apt").read_text()


def release(api, rev_id: int) -> None:
    r = api.post(f"/api/revisions/{rev_id}/release", role="programmer", json={"comment": "ok"})
    assert r.status_code == 200, r.text


def dispatch(api, rev_id: int, machine: str, key: str):
    return api.post(
        "/api/dispatches",
        role="operator",
        json={"revision_id": rev_id, "machine": machine},
        headers={"Idempotency-Key": key},
    )


def test_json_upload_of_apt_and_cl(api):
    apt = api.upload(15, SEED15, kind="apt")["revision"]
    assert (apt["kind"], apt["post_kinds"], apt["check_ok"]) == ("apt", ["mill"], True)
    cl = api.upload(77, FIVE_AXIS_CL, kind="cl", post_kinds=["mill", "lathe"])["revision"]
    assert (cl["kind"], cl["post_kinds"], cl["check_ok"]) == ("cl", ["mill", "lathe"], False)
    by_kind = {e["machine_kind"]: e for e in cl["check_errors"]}
    assert by_kind["mill"]["line"] == 9 and "5-axis CL data" in by_kind["mill"]["message"]


@SQLITE_ONLY
def test_multipart_apt_file_takes_kind_number_and_name_from_the_file(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        files={"file": ("plate.apt", PLATE.encode(), "text/plain")},
    )
    assert r.status_code == 201, r.text
    body = r.json()
    assert (body["program"]["number"], body["program"]["name"]) == (2001, "PLATE 2001")
    assert (body["revision"]["kind"], body["revision"]["post_kinds"]) == ("apt", ["mill"])
    # a .cl file, and a form field naming the kinds
    r = api.post(
        f"/api/programs/{body['program']['id']}/revisions",
        role="programmer",
        files={"file": ("tilt.cls", FIVE_AXIS_CL.encode(), "text/plain")},
        data={"post_kinds": "mill5"},
    )
    assert r.status_code == 201, r.text
    assert (r.json()["kind"], r.json()["post_kinds"]) == ("cl", ["mill5"])


@SQLITE_ONLY
def test_malformed_apt_is_a_problem_with_line_column_and_pointer(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        json={"number": 5, "name": "bad", "text": "P1 = POINT/1,2\nGOTO/P2\n", "kind": "apt"},
    )
    body = assert_problem(r, 422, "invalid-upload")
    assert (body["line"], body["column"], body["pointer"]) == (2, 6, "#/text")
    assert "undefined name 'P2'" in body["detail"]
    r = api.post(
        "/api/programs",
        role="programmer",
        files={"file": ("bad.cl", b"GOTO/1,2,3\nGOTO/1,,3\n", "text/plain")},
        data={"number": "6"},
    )
    body = assert_problem(r, 422, "invalid-upload")
    assert (body["line"], body["column"]) == (2, 8)
    assert api.get("/api/programs").json()["items"] == []  # nothing stored


def test_preview_then_dispatch_posts_into_a_derived_revision(api):
    rev = api.upload(2001, PLATE, kind="apt")["revision"]["id"]
    release(api, rev)
    r = api.get(f"/api/revisions/{rev}/posted", params={"machine": "mill-1"})
    assert r.status_code == 200, r.text
    assert r.headers["x-post-processor"] == "fanuc-mill 1.0"
    assert r.headers["x-machine-kind"] == "mill"
    assert r.headers["etag"] == f'"{hashlib.sha256(r.text.encode()).hexdigest()}"'
    assert r.text.startswith("%\nO2001 (PLATE 2001)\nG21 G90 G94\n")
    assert api.get(f"/api/revisions/{rev}/derived").json() == []  # a preview stores nothing
    first = dispatch(api, rev, "mill-1", "d1")
    second = dispatch(api, rev, "mill-2", "d2")
    assert first.status_code == second.status_code == 202, first.text
    assert first.json()["derived_id"] == second.json()["derived_id"] is not None
    [derived] = api.get(f"/api/revisions/{rev}/derived").json()
    assert derived["sha256"] == r.headers["etag"].strip('"')
    assert (derived["post_name"], derived["machine_kind"]) == ("fanuc-mill", "mill")
    text = api.get(f"/api/derived-revisions/{derived['id']}/text")
    assert text.text == r.text


def test_post_refusals_are_problems_with_the_source_line(api):
    seed = api.upload(15, SEED15, kind="apt")["revision"]["id"]
    release(api, seed)
    # mill3's shipped G54 leaves no room for Y8 in: travel checked after posting
    body = assert_problem(
        api.get(f"/api/revisions/{seed}/posted", params={"machine": "mill-1"}), 422, "post-refused"
    )
    assert (body["line"], body["machine"]) == (11, "mill-1")
    assert "G01 X4. Y8. Z7. F10." in body["reason"]
    five = api.upload(77, FIVE_AXIS_CL, kind="cl", post_kinds=["mill5"])["revision"]["id"]
    release(api, five)
    body = assert_problem(dispatch(api, five, "mill-1", "k5"), 422, "post-refused")
    assert body["line"] == 9 and "cannot be posted to a 3-axis machine" in body["detail"]
    assert api.get("/api/dispatches").json()["items"] == []
    gcode = api.released()
    assert_problem(
        api.get(f"/api/revisions/{gcode}/posted", params={"machine": "mill-1"}),
        422,
        "invalid-upload",
    )


@SQLITE_ONLY
def test_an_unknown_kind_is_a_validation_problem(api):
    r = api.post(
        "/api/programs",
        role="programmer",
        files={"file": ("plate.apt", PLATE.encode(), "text/plain")},
        data={"kind": "step"},
    )
    body = assert_problem(r, 422, "validation")
    assert body["errors"][0]["pointer"] == "#/kind"
