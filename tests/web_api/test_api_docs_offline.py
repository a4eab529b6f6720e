# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""`/docs` (Swagger UI) and `/redoc` (ReDoc) load nothing from another host: a shop network
without internet shows them (web_api/api_docs.py)."""

from __future__ import annotations

import re
from html.parser import HTMLParser

import pytest

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)

pytestmark = SQLITE_ONLY


class Refs(HTMLParser):
    """Every URL a page makes the browser load or link: src, href, and URLs in its scripts."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self._in_script = False

    def handle_starttag(self, tag, attrs):
        self._in_script = tag == "script"
        for name, value in attrs:
            if name in ("src", "href") and value:
                self.urls.append(value)

    def handle_endtag(self, tag):
        self._in_script = False

    def handle_data(self, data):
        if self._in_script:
            self.urls += re.findall(r"""['"]((?:https?:)?//[^'"]+|/[^'"\s]*)['"]""", data)


def refs(html: str) -> list[str]:
    parser = Refs()
    parser.feed(html)
    return parser.urls


@pytest.mark.parametrize(
    ("page", "assets"),
    [
        ("/docs", {"swagger-ui-bundle.js", "swagger-ui.css", "favicon.svg"}),
        ("/redoc", {"redoc.standalone.js", "favicon.svg"}),
    ],
)
def test_the_reference_pages_reference_no_external_host(sessions, page, assets):
    c = make_api(sessions).client
    r = c.get(page)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    urls = refs(html)
    assert urls, html
    external = [u for u in urls if re.match(r"(https?:)?//", u)]
    assert external == [], external
    assert not re.search(r"https?://", html), "a page names another host"
    assert "fonts.googleapis" not in html and "cdn." not in html
    named = {u.rsplit("/", 1)[-1] for u in urls}
    assert assets <= named, named
    # every asset the page loads is served by the app itself
    for url in urls:
        if url.endswith((".js", ".css", ".svg")):
            got = c.get(url)
            assert got.status_code == 200, url
            assert len(got.content) > (100 if url.endswith(".svg") else 10_000), url


def test_swagger_ui_reads_our_openapi_document_without_the_validator(sessions):
    html = make_api(sessions).client.get("/docs").text
    assert "url: '/openapi.json'" in html
    assert '"validatorUrl": null' in html


def test_without_the_assets_the_pages_say_what_is_missing_and_the_api_works(sessions, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "fastapi_offline" else real(name, *a),
    )
    c = make_api(sessions).client
    for page in ("/docs", "/redoc"):
        r = c.get(page)
        assert r.status_code == 503 and "fastapi-offline" in r.text
        assert not re.search(r"https?://", r.text)
    assert c.get("/api/health").status_code == 200
