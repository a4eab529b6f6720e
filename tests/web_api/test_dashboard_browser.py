# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The dashboard in a real browser: Debian's Chromium driven by playwright.

The app runs on a real uvicorn socket on 127.0.0.1 with a seeded SQLite library and a fake
machines provider whose axes move on every poll (a circle, the actual position lagging the
commanded one). The page must ask for the API key, show every machine with its state,
positions and toolpath, list the library, upload a program through the form, release it and
dispatch it, and show the outbox events. Screenshots go to test-output/.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import socket
import threading
from pathlib import Path
from urllib.parse import urlsplit

import pytest
import uvicorn

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    KEYS,
    SQLITE_ONLY,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)
from tests.web_api.test_dashboard import with_dashboard

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
OUTPUT = Path(__file__).resolve().parents[2] / "test-output"

playwright_sync = pytest.importorskip(
    "playwright.sync_api",
    reason="playwright is not installed (.venv/bin/pip install playwright==1.65.2)",
)
pytestmark = [
    SQLITE_ONLY,
    pytest.mark.timeout(90),
    pytest.mark.skipif(
        not (CHROMIUM.exists() and os.access(CHROMIUM, os.X_OK)),
        reason="/usr/bin/chromium is missing (apt-get install -y chromium)",
    ),
]


# Evaluated through the DevTools protocol (the page's CSP forbids eval from page scripts,
# not this): visible form controls without a label, aria-label or aria-labelledby.
UNNAMED_CONTROLS = """
() => [...document.querySelectorAll("input, select, textarea, button")]
  .filter((e) => e.offsetParent !== null && e.type !== "hidden")
  .filter((e) => !(e.labels && e.labels.length) && !e.getAttribute("aria-label")
    && !e.getAttribute("aria-labelledby") && !(e.tagName === "BUTTON" && e.textContent.trim()))
  .map((e) => e.outerHTML.slice(0, 120))
"""


class MovingMachines:
    """A machines provider whose mill-1 moves on a 20 mm circle, one step per poll.

    Positions are a function of the poll count, not of the clock, so what the page is shown
    depends only on how often it asked. mill-2 holds with a drive alarm; lathe-1 is disconnected.
    """

    def __init__(self) -> None:
        self.polls = 0
        self._lock = threading.Lock()

    def __call__(self) -> dict:
        with self._lock:
            self.polls += 1
            k = self.polls
        angle = k * 0.15
        lag = 0.25  # the actual position trails the command by a quarter radian

        def xy(a: float) -> tuple[float, float]:
            return -300 + 20 * math.cos(a), -200 + 20 * math.sin(a)

        (cx, cy), (ax, ay) = xy(angle), xy(angle - lag)
        mill1 = status(
            execution="ACTIVE",
            program="O1001",
            line=k % 40 + 1,
            block="G2 X-280. Y-200. I-20. J0 F800",
            feed_mm_min=800.0,
            actual={"X": ax, "Y": ay, "Z": -50.0},
            commanded={"X": cx, "Y": cy, "Z": -50.0},
            overrides={"feed": 90.0, "rapid": 100.0, "spindle": 100.0},
            spindle={"speed_rpm": 6000.0, "load_percent": 12.0, "mode": "SPINDLE"},
            bus_load={"mean_percent": 41.5, "peak_percent": 55.0},
            plc={"scan_time_ms": 0.412},
        )
        mill2 = status(
            execution="FEED_HOLD",
            alarms=[
                {
                    "condition": "Yservo",
                    "level": "FAULT",
                    "code": "8612",
                    "text": "following error too large",
                }
            ],
            actual=dict.fromkeys("XYZ", -10.0),
            commanded=dict.fromkeys("XYZ", -10.0),
        )
        # The lathe's SHDR stream is down: the agent has no values for it.
        lathe = status(
            connected=False,
            availability="UNAVAILABLE",
            execution="UNAVAILABLE",
            actual={"X": None, "Z": None},
            commanded={"X": None, "Z": None},
            bus_load={"mean_percent": None, "peak_percent": None},
            plc={"scan_time_ms": None},
        )
        return {"mill-1": mill1, "mill-2": mill2, "lathe-1": lathe}


def status(**over) -> dict:
    """A live status as the cell serves it (server.host.MonitoringModel.status)."""
    base = {
        "connected": True,
        "availability": "AVAILABLE",
        "emergency_stop": "ARMED",
        "mode": "AUTOMATIC",
        "mode_detail": "AUTO",
        "execution": "READY",
        "program": "",
        "line": 0,
        "block": "",
        "actual": {},
        "commanded": {},
        "feed_mm_min": 0.0,
        "overrides": {"feed": 100.0, "rapid": 100.0, "spindle": 100.0},
        "spindle": {"speed_rpm": 0.0, "load_percent": 0.0, "mode": "SPINDLE"},
        "alarms": [],
        "counters": {"part_count": 3},
        "bus_load": {"mean_percent": 12.0, "peak_percent": 20.0},
        "plc": {"scan_time_ms": 0.2},
    }
    return {**base, **over}


@contextlib.contextmanager
def serve(app):
    """The app on a real uvicorn socket on 127.0.0.1; yields its base URL."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(64)  # the browser may connect before uvicorn accepts: no start-up wait
    config = uvicorn.Config(app, log_level="warning", lifespan="off", timeout_graceful_shutdown=3)
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{sock.getsockname()[1]}"
    finally:
        server.should_exit = True
        thread.join(timeout=20)
        sock.close()
    assert not thread.is_alive(), "uvicorn did not shut down"


@contextlib.contextmanager
def browser_page(base: str):
    """A Chromium page that may reach only `base`; fails on JavaScript errors."""
    OUTPUT.mkdir(exist_ok=True)
    with playwright_sync.sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
        )
        context = browser.new_context(viewport={"width": 1400, "height": 1000})
        context.set_default_timeout(15_000)
        foreign: list[str] = []

        def only_our_host(route):
            # The page must work without any network but the cell's host.
            if urlsplit(route.request.url).netloc != urlsplit(base).netloc:
                foreign.append(route.request.url)
                return route.abort()
            return route.continue_()

        context.route("**/*", only_our_host)
        pg = context.new_page()
        errors: list[str] = []
        pg.on("pageerror", lambda exc: errors.append(str(exc)))

        def console_error(msg):
            # API refusals (401 before the key, 404 fault types) are answers the page
            # handles; a failed load of anything else (a page asset) is a defect.
            url = msg.location.get("url", "")
            if msg.type == "error" and not urlsplit(url).path.startswith("/api/"):
                errors.append(f"{msg.text} ({url})")

        pg.on("console", console_error)
        try:
            yield pg
        finally:
            context.close()
            browser.close()
    assert not foreign, f"the page reached beyond the host: {foreign}"
    assert not errors, f"errors on the page (scripts, failed loads): {errors}"


@pytest.fixture
def served(sessions):
    """The app with a seeded library; yields (api, base URL, provider)."""
    provider = MovingMachines()
    api = make_api(sessions, events_keepalive_s=0, machines_provider=provider)
    api.released(1001)  # a released program, ready to dispatch
    api.upload(1002, GOOD.replace("O1001", "O1002"))  # a draft
    with serve(with_dashboard(api.client.app)) as base:
        yield api, base, provider


@pytest.fixture
def page(served):
    with browser_page(served[1]) as pg:
        yield pg


def test_dashboard_shows_the_cell_and_drives_the_library(served, page, tmp_path):
    api, base, provider = served
    expect = playwright_sync.expect

    page.goto(base + "/")
    # No key yet: the API answers 401 and the page asks for one.
    dialog = page.locator("#key-dialog")
    expect(dialog).to_be_visible()
    page.get_by_label("Key", exact=True).fill(KEYS["admin"])
    page.locator("#key-save").click()
    expect(page.locator("#whoami")).to_have_text("admin-user (admin)")
    assert page.evaluate("localStorage.getItem('fmscell.apiKey')") == KEYS["admin"]

    # Machines: one tile each, with state in words and colour class, positions and plot.
    tiles = page.locator(".tile[data-machine]")
    expect(tiles).to_have_count(3)
    mill1 = page.locator('.tile[data-machine="mill-1"]')
    mill2 = page.locator('.tile[data-machine="mill-2"]')
    lathe = page.locator('.tile[data-machine="lathe-1"]')
    expect(mill1).to_have_attribute("data-state", "active")
    expect(mill1.locator(".m-state")).to_have_text("ACTIVE")
    expect(mill1.locator(".m-mode")).to_have_text("AUTOMATIC / AUTO")
    expect(mill1.locator(".m-program")).to_have_text("O1001")
    expect(mill1.locator(".m-feed")).to_contain_text("800 mm/min · 90 %")
    expect(mill1.locator(".m-spindle")).to_contain_text("6000 rpm")
    expect(mill1.locator(".m-scan")).to_have_text("0.412 ms")
    expect(mill1.locator(".m-bus-text")).to_contain_text("41.5 %")
    expect(mill1.locator(".m-axes tr")).to_have_count(3)
    expect(mill2).to_have_attribute("data-state", "alarm")
    expect(mill2.locator(".m-alarms li")).to_contain_text("DRIVE 8612 [Y]: following error")
    expect(lathe).to_have_attribute("data-state", "offline")
    expect(lathe.locator(".m-state")).to_have_text("OFFLINE")
    expect(lathe.locator('.m-axes tr[data-axis="X"] td')).to_have_text(["—", "—", "—"])
    expect(lathe.locator(".m-bus-text")).to_have_text("—")
    expect(lathe.locator(".m-scan")).to_have_text("—")
    expect(lathe.locator(".m-plane")).to_have_text("plane Z–X")

    # The toolpath grows while the provider's circle turns: the page keeps polling.
    polls_before = provider.polls
    # (expect() polls from the test side: the page's CSP forbids evaluating strings)
    canvas = mill1.locator("canvas.m-plot")
    expect(canvas).to_have_attribute("data-points", re.compile(r"^(1[3-9]|[2-9]\d|\d{3,})$"))
    assert provider.polls > polls_before
    x_actual = mill1.locator('.m-axes tr[data-axis="X"] td').first
    seen = x_actual.inner_text()
    expect(x_actual).not_to_have_text(seen)
    # No fault injection in this cell: GET /api/fault-types is 404, so no panel.
    expect(mill1.locator(".m-faults")).to_be_hidden()
    page.screenshot(path=str(OUTPUT / "dashboard.png"), full_page=True)

    # Library: the seeded programs, released and draft.
    rows = page.locator("#program-rows tr[data-program]")
    expect(rows).to_have_count(2)
    o1001 = page.locator('#program-rows tr[data-number="1001"]')
    expect(o1001.locator(".released")).not_to_have_text("—")
    expect(
        page.get_by_role("button", name=re.compile(r"Release O1002 revision \d+"))
    ).to_be_visible()

    # Upload through the form: number and name come from the tape's O block.
    tape = tmp_path / "o1003.nc"
    tape.write_text(GOOD.replace("O1001 (BRACKET)", "O1003 (FLANGE)"))
    page.get_by_label("Program file").set_input_files(str(tape))
    page.get_by_label("Tags").fill("op20,alu")
    page.locator("#upload-form button[type=submit]").click()
    o1003 = page.locator('#program-rows tr[data-number="1003"]')
    expect(o1003).to_be_visible()
    expect(o1003).to_contain_text("FLANGE")
    stored = api.get("/api/programs?number=1003").json()["items"][0]
    assert sorted(stored["tags"]) == ["alu", "op20"] and stored["released_revision_id"] is None

    # Release it with an approval comment.
    rev = stored["latest_revision_id"]
    page.get_by_role("button", name=f"Release O1003 revision {rev}").click()
    page.get_by_label(re.compile("Approval comment")).fill("proved out in the browser test")
    page.get_by_role("button", name="Release", exact=True).click()
    expect(o1003.locator(".released")).to_have_text(str(rev))
    r = api.get(f"/api/revisions/{rev}").json()
    assert r["status"] == "released" and r["approved_by"] == "admin-user"
    assert r["approval_comment"] == "proved out in the browser test"

    # Dispatch it to mill-2: the history shows it, the API has exactly one.
    page.get_by_role("button", name=f"Dispatch O1003 revision {rev}").click()
    page.get_by_label("Machine", exact=True).select_option("mill-2")
    page.get_by_role("button", name="Dispatch", exact=True).click()
    row = page.locator("#dispatch-rows tr[data-dispatch]").first
    expect(row).to_contain_text("mill-2")
    dispatches = api.get("/api/dispatches").json()["items"]
    assert [(d["revision_id"], d["machine"], d["mode"]) for d in dispatches] == [
        (rev, "mill-2", "memory")
    ]

    # A job for the released revision through the job form.
    page.get_by_label("Revision id").fill(str(rev))
    page.get_by_label("Quantity").fill("4")
    page.get_by_role("button", name="Create job").click()
    job = page.locator("#job-rows tr[data-job]").first
    expect(job).to_contain_text("0 / 4")
    expect(job).to_have_attribute("data-status", "queued")
    jobs = api.get("/api/jobs").json()["items"]
    assert [(j["revision_id"], j["quantity"]) for j in jobs] == [(rev, 4)]

    # Every control on the page has an accessible name.
    unnamed = page.evaluate(UNNAMED_CONTROLS)
    assert unnamed == [], f"controls without a label: {unnamed}"

    # The event stream reached the page (registrations, uploads, release, dispatch).
    expect(page.locator("#event-log li").filter(has_text="revision.release")).not_to_have_count(0)
    expect(page.locator("#live")).to_have_text("events: live")
    page.screenshot(path=str(OUTPUT / "dashboard-after-dispatch.png"), full_page=True)


FAULT_TYPES = [
    {
        "type": "encoder",
        "target": "drive:<AXIS>",
        "params": [{"name": "noise", "unit": "counts", "default": 4.0}],
        "description": "encoder noise",
    },
    {"type": "coolant_low", "target": "plc", "params": [], "description": "coolant level low"},
]


class FakeFaults:
    """The fault routes' contract (web_api/routers/faults.py) over a list, for the page."""

    def __init__(self) -> None:
        self.injected: list[dict] = []
        self.cleared: list[int] = []

    def install(self, app) -> None:
        @app.get("/api/fault-types")
        def fault_types() -> list[dict]:
            return FAULT_TYPES

        @app.post("/api/machines/{name}/faults", status_code=201)
        def inject(name: str, body: dict) -> dict:
            fault = {"id": len(self.injected) + 1, "machine": name, "state": "active", **body}
            self.injected.append(fault)
            return fault

        @app.get("/api/machines/{name}/faults")
        def listed(name: str) -> list[dict]:
            return [
                {**f, "state": "cleared" if f["id"] in self.cleared else "active"}
                for f in self.injected
                if f["machine"] == name
            ]

        @app.delete("/api/machines/{name}/faults/{fault_id}")
        def clear(name: str, fault_id: int) -> dict:
            self.cleared.append(fault_id)
            return {"id": fault_id, "state": "cleared"}


def test_fault_panel_offers_the_cells_fault_types_and_injects(sessions):
    provider = MovingMachines()
    api = make_api(sessions, insecure_open=True, machines_provider=provider)
    faults = FakeFaults()
    app = with_dashboard(api.client.app)
    faults.install(app)
    expect = playwright_sync.expect
    with serve(app) as base, browser_page(base) as page:
        page.goto(base + "/")
        # insecure-open: no key asked for, the caller is the anonymous admin.
        expect(page.locator("#whoami")).to_have_text("anonymous (admin)")
        expect(page.locator("#key-dialog")).to_be_hidden()
        mill1 = page.locator('.tile[data-machine="mill-1"]')
        panel = mill1.locator(".m-faults")
        expect(panel).to_be_visible()
        panel.locator("summary").click()
        expect(panel.locator(".f-type option")).to_have_count(2)
        # The first type's target and parameter defaults are offered, on the first axis.
        expect(panel.locator(".f-target")).to_have_value("drive:X")
        expect(panel.locator(".f-params")).to_have_value('{"noise":4}')
        panel.get_by_label("Duration, s").fill("2.5")
        panel.get_by_role("button", name="Inject").click()
        expect(panel.locator(".f-active li")).to_contain_text("#1 encoder drive:X active")
        assert faults.injected == [
            {
                "id": 1,
                "machine": "mill-1",
                "state": "active",
                "type": "encoder",
                "target": "drive:X",
                "params": {"noise": 4},
                "duration": 2.5,
            }
        ]
        page.screenshot(path=str(OUTPUT / "dashboard-faults.png"), full_page=True)
        # A PLC fault takes no parameters; then clear the first fault.
        panel.locator(".f-type").select_option("coolant_low")
        expect(panel.locator(".f-target")).to_have_value("plc")
        panel.get_by_label("Duration, s").fill("")
        panel.get_by_role("button", name="Inject").click()
        expect(panel.locator(".f-active li")).to_have_count(2)
        assert faults.injected[1]["target"] == "plc" and "duration" not in faults.injected[1]
        panel.get_by_role("button", name="Clear fault 1 on mill-1").click()
        expect(panel.locator(".f-active li").first).to_contain_text("cleared")
        assert faults.cleared == [1]


def test_a_viewer_sees_no_fault_panel_and_is_told_which_role_a_release_needs(sessions):
    api = make_api(sessions, machines_provider=MovingMachines())
    draft = api.upload(1002, GOOD.replace("O1001", "O1002"))["revision"]["id"]
    app = with_dashboard(api.client.app)
    FakeFaults().install(app)
    expect = playwright_sync.expect
    with serve(app) as base, browser_page(base) as page:
        refused = []
        page.on(
            "response",
            lambda r: (
                refused.append(r.url) if r.status == 401 and "/api/machines" in r.url else None
            ),
        )
        page.goto(base + "/")
        # Dismissing the key dialog is final until the user opens it again: the page keeps
        # polling (and being refused) without asking once per request.
        expect(page.locator("#key-dialog")).to_be_visible()
        page.get_by_role("button", name="Cancel").click()
        expect(page.locator("#notice")).to_contain_text("No API key")
        seen = len(refused)
        with page.expect_response(lambda r: r.status == 401 and "/api/machines" in r.url):
            pass
        with page.expect_response(lambda r: r.status == 401 and "/api/machines" in r.url):
            pass
        assert len(refused) >= seen + 2
        expect(page.locator("#key-dialog")).to_be_hidden()
        # the lists' refused refreshes are expected now: they do not bury the hint
        expect(page.locator("#notice")).to_contain_text("No API key")
        page.get_by_role("button", name="API key…").click()
        page.get_by_label("Key", exact=True).fill(KEYS["viewer"])
        page.locator("#key-save").click()
        expect(page.locator("#whoami")).to_have_text("viewer-user (viewer)")
        # A reload signs in with the key kept in localStorage, without asking.
        page.reload()
        expect(page.locator("#whoami")).to_have_text("viewer-user (viewer)")
        expect(page.locator("#key-dialog")).to_be_hidden()
        expect(page.locator(".tile[data-machine]")).to_have_count(3)
        # Fault types are readable by anyone, but injecting needs an admin: no panel.
        expect(page.locator(".m-faults").first).to_be_hidden()
        page.get_by_role("button", name=f"Release O1002 revision {draft}").click()
        page.get_by_label(re.compile("Approval comment")).fill("not mine to release")
        page.get_by_role("button", name="Release", exact=True).click()
        expect(page.locator("#notice")).to_contain_text("needs the programmer role")
        page.screenshot(path=str(OUTPUT / "dashboard-viewer.png"), full_page=True)
    assert api.get(f"/api/revisions/{draft}").json()["status"] == "draft"


def test_the_program_view_shows_an_apt_source_beside_its_posted_g_code(sessions):
    plate = (Path(__file__).resolve().parents[2] / "cam" / "examples" / "plate.apt").read_text()
    api = make_api(sessions, insecure_open=True, machines_provider=MovingMachines())
    _, rev = api.library.create_program(number=2001, name="plate", text=plate, kind="apt")
    api.library.release(rev.id, approver="ann", comment="ok")
    expect = playwright_sync.expect
    with serve(with_dashboard(api.client.app)) as base, browser_page(base) as page:
        page.goto(base + "/")
        expect(page.locator(".tile[data-machine]")).to_have_count(3)
        page.get_by_role("button", name=f"View O2001 revision {rev.id}").click()
        view = page.get_by_role("form", name="Program O2001")
        expect(view.get_by_label("O2001 source text")).to_contain_text("GOLFT/L3,PAST,L1")
        # posted for a machine of the kind MACHIN/MILL names, the post named under it
        expect(view.locator("#view-machine")).to_have_value("mill-1")
        expect(view.get_by_label("O2001 posted text")).to_contain_text("O2001 (PLATE 2001)")
        expect(view.locator(".post-note")).to_contain_text("fanuc-mill 1.0 for a mill")
        # the lathe cannot hold the plate's Y moves: the refusal with its APT line
        view.locator("#view-machine").select_option("lathe-1")
        expect(view.locator(".post-note")).to_contain_text("no Y axis")
        page.screenshot(path=str(OUTPUT / "dashboard-program-view.png"), full_page=True)
