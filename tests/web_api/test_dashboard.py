# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The dashboard's router: the page and its files, from the package, with nothing from a CDN.

The page itself is tested in a real browser in test_dashboard_browser.py; these tests pin
what the server promises without one (media types, the allow-list, the security headers,
that every module the page imports is served and that no asset comes from elsewhere).
"""

from __future__ import annotations

import re

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)
from web_api.dashboard import STATIC_DIR, dashboard_router, static_files


def with_dashboard(app: FastAPI) -> FastAPI:
    """The app with the dashboard, whether or not create_app registers it already."""
    if not any(getattr(r, "path", None) == "/" for r in app.routes):
        app.include_router(dashboard_router())
    return app


@pytest.fixture
def client():
    app = FastAPI()
    app.include_router(dashboard_router())
    with TestClient(app) as c:
        yield c


def test_the_page_is_served_at_the_root_with_a_same_origin_policy(client):
    r = client.get("/")
    assert r.status_code == 200
    assert r.headers["content-type"] == "text/html; charset=utf-8"
    assert "<title>fmscell" in r.text
    csp = r.headers["content-security-policy"]
    assert "default-src 'self'" in csp and "script-src 'self'" in csp
    assert r.headers["x-content-type-options"] == "nosniff"


@pytest.mark.parametrize(
    ("name", "media"),
    [
        ("app.js", "text/javascript"),
        ("api.js", "text/javascript"),
        ("plot.js", "text/javascript"),
        ("app.css", "text/css"),
        ("favicon.svg", "image/svg+xml"),
        ("index.html", "text/html"),
    ],
)
def test_static_files_have_their_media_type(client, name, media):
    r = client.get(f"/static/{name}")
    assert r.status_code == 200
    assert r.headers["content-type"].startswith(media)
    assert r.content == (STATIC_DIR / name).read_bytes()


@pytest.mark.parametrize(
    "name",
    ["nope.js", "..%2Fdashboard.py", "..%2F..%2Fpyproject.toml", "%2Fetc%2Fpasswd", ".hidden"],
)
def test_only_the_static_folder_files_are_served(client, name):
    r = client.get(f"/static/{name}")
    assert r.status_code == 404


def test_every_asset_and_module_import_is_served_from_the_package():
    files = static_files()
    html = files["index.html"].read_text()
    refs = re.findall(r'(?:src|href)="([^"#]+)"', html)
    assert refs, "the page loads nothing?"
    for ref in refs:
        assert ref.startswith("/static/"), f"index.html loads {ref} from elsewhere"
        assert ref.removeprefix("/static/") in files, ref
    for name, path in files.items():
        if name.endswith(".js"):
            text = path.read_text()
            assert "http://" not in text and "https://" not in text, name
            for target in re.findall(r'from\s+"\./([^"]+)"', text):
                assert target in files, f"{name} imports {target}, which is not served"


@SQLITE_ONLY
def test_the_dashboard_stays_out_of_the_api_document(sessions):
    api = make_api(sessions)
    app = with_dashboard(api.client.app)
    paths = TestClient(app).get("/openapi.json").json()["paths"]
    assert "/" not in paths and not any(p.startswith("/static") for p in paths)


@SQLITE_ONLY
def test_the_api_app_serves_the_dashboard(sessions):
    api = make_api(sessions)
    r = api.client.get("/")
    assert r.status_code == 200 and "<title>fmscell" in r.text
    assert api.client.get("/static/app.js").status_code == 200
