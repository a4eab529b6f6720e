# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Program text is held to the ISO 6983 / EIA character set at upload (issue 14, item 9): a
non-ASCII character had passed the NC check and the release and then wedged its dispatch."""

from __future__ import annotations

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

BAD = "%\nO1001 (BRACKET)\nN10 G0 X0 Y0 (\u00d8 12 BOHRUNG)\nN20 M30\n%\n"


@SQLITE_ONLY
def test_json_upload_with_a_non_ascii_character_names_byte_line_and_column(api):
    r = api.post(
        "/api/programs", role="programmer", json={"number": 1001, "name": "x", "text": BAD}
    )
    body = assert_problem(r, 422, "invalid-upload")
    assert (body["offset"], body["line"], body["column"], body["character"]) == (
        32,
        3,
        15,
        "U+00D8",
    )
    assert "outside the ISO 6983 / EIA character set" in body["detail"]
    assert api.get("/api/programs").json()["items"] == []


@SQLITE_ONLY
def test_file_upload_and_new_revision_are_refused_the_same_way(api):
    r = api.post("/api/programs", role="programmer", files={"file": ("b.nc", BAD.encode())})
    body = assert_problem(r, 422, "invalid-upload")
    assert (body["offset"], body["line"], body["column"]) == (32, 3, 15)
    prog = api.upload()["program"]["id"]
    r = api.post(
        f"/api/programs/{prog}/revisions", role="programmer", json={"text": GOOD + "(\u00e9)\n"}
    )
    assert assert_problem(r, 422, "invalid-upload")["character"] == "U+00E9"
    assert len(api.get(f"/api/programs/{prog}").json()["revisions"]) == 1
