"""A whole cell (default: two mills and a lathe) on the fast clock behind a real uvicorn
socket on 127.0.0.1, with one API key per role."""

from __future__ import annotations

import socket
import threading
import time
import uuid

import httpx
import pytest
import uvicorn

from server.cell import Cell, default_cell
from web_api.settings import ApiSettings

KEYS = {
    "viewer": "viewer-key-0123456789",
    "operator": "operator-key-0123456789",
    "programmer": "programmer-key-0123456789",
    "admin": "admin-key-0123456789abc",
}
SETTINGS = ApiSettings.from_mapping(
    {"api_keys": [{"user": role, "role": role, "key": key} for role, key in KEYS.items()]}
)

# A part: rapid over the stock, a feed move down and across, back up, M30 counts it.
MILL_PROGRAM = """%
O1001 (E2E POCKET)
N10 G21 G90 G17
N20 G0 X-40 Y-30 Z-10
N30 G1 Z-50 F6000
N40 G1 X-100 Y-60
N50 G0 Z-20
N60 M30
%
"""
# machine coordinates: the program's X-100 Y-60 Z-20 from the shipped mill3's G54
# (X-300 Y-200 Z-300, its factory setup in cnc/machines/mill3.yaml)
MILL_FINAL = {"X": -400.0, "Y": -260.0, "Z": -320.0}


class Api:
    """The cell's HTTP API as one role sees it."""

    def __init__(self, base: str) -> None:
        self.base = base
        self.clients: dict[str, httpx.Client] = {}

    def __call__(self, role: str = "admin") -> httpx.Client:
        if role not in self.clients:
            headers = {"X-API-Key": KEYS[role]} if role in KEYS else {}
            self.clients[role] = httpx.Client(base_url=self.base, headers=headers, timeout=30)
        return self.clients[role]

    def close(self) -> None:
        for c in self.clients.values():
            c.close()


def serve(cell: Cell, settings: ApiSettings = SETTINGS):
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(64)
    server = uvicorn.Server(uvicorn.Config(cell.app(settings), log_level="warning", lifespan="off"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    return server, thread, sock


@pytest.fixture
def make_cell(tmp_path):
    """make_cell(faults=...) -> (cell, api); everything stopped at the end."""
    made = []

    def make(*, faults: bool = False, ideal_axes: bool = True, config=None) -> tuple[Cell, Api]:
        cell = Cell(
            config or default_cell(free_ports=True),
            clock="fast",
            database_url=f"sqlite:///{tmp_path}/cell-{len(made)}.db",
            faults=faults,
            ideal_axes=ideal_axes,
        ).start()
        server, thread, sock = serve(cell)
        api = Api(f"http://127.0.0.1:{sock.getsockname()[1]}")
        made.append((cell, server, thread, sock, api))
        return cell, api

    yield make
    for cell, server, thread, sock, api in made:
        api.close()
        server.should_exit = True
        thread.join(20)
        sock.close()
        cell.stop()


def poll(fn, timeout_s: float, what: str, interval_s: float = 0.05):
    """Poll `fn` until it returns a truthy value or fail after `timeout_s`, saying what."""
    end = time.monotonic() + timeout_s
    last = None
    while time.monotonic() < end:
        last = fn()
        if last:
            return last
        time.sleep(interval_s)
    raise AssertionError(f"{what}: not within {timeout_s} s (last: {last!r})")


def upload_released(api: Api, text: str = MILL_PROGRAM, number: int = 1001, kind: str = "mill"):
    """Upload as programmer and release; returns the revision id."""
    r = api("programmer").post(
        "/api/programs",
        json={"number": number, "name": f"e2e {number}", "text": text, "machine_kind": kind},
    )
    assert r.status_code == 201, r.text
    rev = r.json()["revision"]
    assert rev["check_ok"], rev["check_errors"]
    r = api("programmer").post(f"/api/revisions/{rev['id']}/release", json={"comment": "e2e ok"})
    assert r.status_code == 200, r.text
    return rev["id"]


def idem() -> dict:
    return {"Idempotency-Key": uuid.uuid4().hex}


def sse_until(api: Api, predicate, timeout_s: float, role: str = "viewer") -> list[dict]:
    """Read the event stream from the start until `predicate(event)` holds; the events read."""
    import json

    seen: list[dict] = []
    deadline = time.monotonic() + timeout_s
    with api(role).stream(
        "GET", "/api/events", params={"after": 0}, timeout=httpx.Timeout(5, read=timeout_s)
    ) as r:
        assert r.status_code == 200, r.read()
        for line in r.iter_lines():
            if line.startswith("data:"):
                seen.append(json.loads(line[5:]))
                if predicate(seen[-1]):
                    return seen
            if time.monotonic() > deadline:
                break
    raise AssertionError(
        f"event not seen within {timeout_s} s; saw {[e.get('action') for e in seen]}"
    )
