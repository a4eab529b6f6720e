"""The live dashboard: one HTML page and its static ES modules, served from the package.

There is no build step and no CDN: `web_api/static/` holds plain HTML, CSS and JavaScript
modules, and this router serves exactly the files found there (an allow-list, so a request
can never name a path outside the folder). The page reads the same REST API and event
stream as any other client, with the API key the user types in.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse, PlainTextResponse

STATIC_DIR = Path(__file__).with_name("static")
_MEDIA_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".ico": "image/x-icon",
}
# Everything the page loads comes from this origin: a dashboard on a shop-floor network
# has no internet, and a script from elsewhere would see the operator's API key.
_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'; "
    "form-action 'self'"
)
_HEADERS = {
    "Cache-Control": "no-cache",
    "Content-Security-Policy": _CSP,
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


def static_files() -> dict[str, Path]:
    """The files the dashboard serves, by name (the static folder's regular files)."""
    return {
        p.name: p
        for p in sorted(STATIC_DIR.iterdir())
        if p.is_file() and p.suffix in _MEDIA_TYPES and not p.name.startswith(".")
    }


def dashboard_router() -> APIRouter:
    """A router serving the dashboard at `/` and its files under `/static/`.

    Kept out of the OpenAPI document: it is a page for people, not part of the API.
    """
    files = static_files()
    router = APIRouter(include_in_schema=False)

    @router.get("/", response_class=FileResponse)
    def index() -> FileResponse:
        return _file(files["index.html"])

    @router.get("/static/{name}", response_model=None)
    def static(name: str) -> FileResponse | PlainTextResponse:
        path = files.get(name)
        if path is None:
            # Plain text, not problem+json: this is the page's asset space, not the API.
            return PlainTextResponse(f"no dashboard file named {name[:80]!r}", status_code=404)
        return _file(path)

    return router


def _file(path: Path) -> FileResponse:
    return FileResponse(path, media_type=_MEDIA_TYPES[path.suffix], headers=_HEADERS)
