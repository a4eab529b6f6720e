"""The API reference pages, `/docs` (Swagger UI) and `/redoc` (ReDoc), with their scripts
and styles served by the app itself: a shop network without internet shows them too.

FastAPI's own pages load Swagger UI and ReDoc from a public CDN. The same pages are built
here by FastAPI's functions, pointing at the files the `fastapi-offline` package ships
(Swagger UI's bundle and CSS, ReDoc's standalone bundle; their licences come with that
package), served under `/docs-assets/`. The favicon is the dashboard's; Swagger UI's
validator badge (which would call validator.swagger.io) is off, and ReDoc loads no web fonts.
"""

from __future__ import annotations

import html
import importlib.util
import logging
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

log = logging.getLogger(__name__)
ASSETS_URL = "/docs-assets"
ASSETS = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js")


def assets_dir() -> Path:
    """The folder holding Swagger UI's and ReDoc's files (the `fastapi-offline` package)."""
    spec = importlib.util.find_spec("fastapi_offline")
    if spec is None or spec.origin is None:
        raise RuntimeError(
            "the API reference pages need the package fastapi-offline (pyproject.toml);"
            " reinstall fmscell (`make run` does)"
        )
    folder = Path(spec.origin).with_name("static")
    missing = [name for name in ASSETS if not (folder / name).is_file()]
    if missing:
        raise RuntimeError(f"{folder}: missing {', '.join(missing)}")
    return folder


def install_api_docs(app: FastAPI) -> None:
    """Mount the assets and the two pages on an app created with docs_url=None,
    redoc_url=None."""
    openapi_url = app.openapi_url or "/openapi.json"
    try:
        folder = assets_dir()
    except RuntimeError as exc:
        # the API itself works without its reference pages: say why they are missing
        log.warning("%s", exc)
        missing = f"<p>{html.escape(str(exc))}</p><p>The API's document: {openapi_url}</p>"

        @app.get("/docs", include_in_schema=False)
        @app.get("/redoc", include_in_schema=False)
        async def no_docs() -> HTMLResponse:
            return HTMLResponse(missing, status_code=503)

        return
    app.mount(ASSETS_URL, StaticFiles(directory=folder), name="docs-assets")
    oauth2_redirect = app.swagger_ui_oauth2_redirect_url or "/docs/oauth2-redirect"

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi_url,
            title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=oauth2_redirect,
            swagger_js_url=f"{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url="/static/favicon.svg",
            swagger_ui_parameters={"validatorUrl": None},
        )

    @app.get(oauth2_redirect, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    @app.get("/redoc", include_in_schema=False)
    async def redoc() -> HTMLResponse:
        return get_redoc_html(
            openapi_url=openapi_url,
            title=f"{app.title} - ReDoc",
            redoc_js_url=f"{ASSETS_URL}/redoc.standalone.js",
            redoc_favicon_url="/static/favicon.svg",
            with_google_fonts=False,
        )
