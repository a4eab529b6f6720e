"""The README's tour works as written from `make run`: the key it prints, and the fault
example's request and the MTConnect path that shows its alarm."""

from __future__ import annotations

import json
import re
import subprocess
import time
import urllib.parse
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from server.cell import Cell, default_cell
from web_api.settings import ApiKey, ApiSettings

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()
TOUR = README[README.index("## A five-minute tour") : README.index("## The Modbus map")]


def test_make_run_starts_the_cell_the_tour_needs():
    """`make run` is `fmscell run` with fault injection; the tour takes the key it prints."""
    out = subprocess.run(
        ["make", "-n", "-o", ".venv/.installed", "run"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    ).stdout
    assert re.search(r"^\.venv/bin/fmscell run --faults$", out, re.M), out
    assert "export KEY=" in TOUR and "KEY=operator-key" not in TOUR
    assert "make run" in TOUR


def test_first_build_says_what_it_does_and_how_long(tmp_path):
    out = subprocess.run(
        ["make", "-n", "-B", ".venv/.installed"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    ).stdout
    modules = sum(
        1
        for listing in ROOT.glob("*/**/mypyc.list")
        for line in listing.read_text().splitlines()
        if line.split("#", 1)[0].strip()
    )
    assert "minutes" in out
    assert f"mypyc compiles {modules} hot modules" in out
    assert "--quiet -e" not in out  # pip shows its own steps for the long install


def fault_request() -> dict:
    body = re.search(r"/api/machines/mill1/faults \\\n\s+-d '(\{.*?\})'", TOUR).group(1)
    return json.loads(body)


def mtconnect_path() -> str:
    url = re.search(r'curl -s "\$API(/mtconnect/mill1/current\?path=[^"]+)"', TOUR).group(1)
    return urllib.parse.unquote(url.split("path=", 1)[1])


@pytest.mark.timeout(180)
def test_the_fault_example_shows_its_alarm_where_the_readme_looks(tmp_path):
    request = fault_request()
    path = mtconnect_path()
    assert request["target"] == "drive:Y" and path == '//Linear[@name="Y"]'
    cell = Cell(
        default_cell(free_ports=True),
        clock="fast",
        database_url=f"sqlite:///{tmp_path}/cell.db",
        faults=True,
        state_dir=tmp_path,
    ).start()
    try:
        key = "tour-admin-key-0123456789"
        settings = ApiSettings(api_keys=(ApiKey(user="local-admin", role="admin", key=key),))
        c = TestClient(cell.app(settings), headers={"X-API-Key": key})
        r = c.post("/api/machines/mill1/faults", json=request)
        assert r.status_code == 201, r.text
        assert r.json()["spec"] == "drive:Y:encoder_break"
        deadline = time.monotonic() + 60
        while not (alarms := c.get("/api/machines/mill1").json()["status"]["alarms"]):
            assert time.monotonic() < deadline, "no alarm"
            time.sleep(0.05)
        deadline = time.monotonic() + 60
        while not any(a["condition"] == "Yservo" for a in alarms):
            assert time.monotonic() < deadline, f"no drive alarm: {alarms}"
            time.sleep(0.05)
            alarms = c.get("/api/machines/mill1").json()["status"]["alarms"]
        servo = next(a for a in alarms if a["condition"] == "Yservo")
        assert servo["code"] == "3040" and servo["level"] == "FAULT"
        assert "drive fault 0x7305 on Y" in servo["text"]
        # the encoder break lost the axis' reference: the README shows that warning too
        assert {"condition": "nc_cond", "level": "WARNING", "code": "3031"}.items() <= next(
            a for a in alarms if a["code"] == "3031"
        ).items()
        where = c.get("/mtconnect/mill1/current", params={"path": path}).text
        fault = re.search(r"<Fault [^>]*>[^<]*</Fault>", where)
        assert fault, where
        for attr in ('name="Yservo"', 'type="ACTUATOR"', 'nativeCode="3040"'):
            assert attr in fault.group(0)
        assert "<Fault" in c.get("/mtconnect/mill1/current", params={"path": "//Axes"}).text
        # where the README used to look: the controller's conditions stay Normal
        controller = c.get("/mtconnect/mill1/current", params={"path": "//Controller"}).text
        assert "<Fault" not in controller
    finally:
        cell.stop()


APT_TOUR = TOUR[TOUR.index("The DNC host does the same at dispatch") :]


def curl_commands(text: str) -> list[list[str]]:
    """The section's `curl` commands, continuation lines joined and comments dropped, as
    argument lists (what the shell would pass; $H and $API left for the caller)."""
    import shlex

    block = re.search(r"```sh\n(.*?)```", text, re.S).group(1)
    joined = re.sub(r"\\\n\s*", " ", block)
    commands = []
    for line in joined.splitlines():
        line = line.split("  #", 1)[0].strip()
        if line.startswith("curl "):
            commands.append(shlex.split(line))
    return commands


def run_curl(c: TestClient, args: list[str]):
    """One README curl command through the app: -H, -F file=@, -d, the URL."""
    headers, files, form, data, url = {}, {}, {}, None, None
    it = iter(args[1:])
    for arg in it:
        if arg == "-H":
            name, _, value = next(it).partition(": ")
            if name != "X-API-Key":  # "$H": the client's key
                headers[name] = value
        elif arg == "-F":
            field, _, value = next(it).partition("=")
            if value.startswith("@"):
                path = value[1:]
                files[field] = (Path(path).name, (ROOT / path).read_bytes(), "text/plain")
            else:
                form[field] = value
        elif arg == "-d":
            data = next(it)
        elif arg.strip('"').startswith("$API"):
            url = arg.strip('"').removeprefix("$API")
    if files:
        return c.post(url, headers=headers, files=files, data=form)
    if data is not None:
        return c.post(url, headers=headers, content=data)
    return c.get(url, headers=headers)


@pytest.mark.timeout(240)
def test_the_apt_example_posts_one_source_for_both_mills(tmp_path):
    commands = curl_commands(APT_TOUR)
    assert len(commands) == 6, commands
    cell = Cell(
        default_cell(free_ports=True),
        clock="fast",
        database_url=f"sqlite:///{tmp_path}/cell.db",
        state_dir=tmp_path,
    ).start()
    try:
        key = "tour-admin-key-0123456789"
        settings = ApiSettings(api_keys=(ApiKey(user="local-admin", role="admin", key=key),))
        c = TestClient(cell.app(settings), headers={"X-API-Key": key})
        # the tour's first upload, so that the plate is revision 2 as the README says
        first = TOUR[TOUR.index("**1. Upload**") :]
        assert run_curl(c, curl_commands(first)[0]).status_code == 201
        upload, release, preview, to_mill1, to_mill2, derived = (
            run_curl(c, args) for args in commands
        )
        assert upload.status_code == 201, upload.text
        program, revision = upload.json()["program"], upload.json()["revision"]
        assert (program["number"], program["name"]) == (2001, "PLATE 2001")
        assert (revision["id"], revision["kind"], revision["post_kinds"]) == (2, "apt", ["mill"])
        assert revision["check_ok"] is True
        assert release.status_code == 200, release.text
        assert preview.status_code == 200, preview.text
        assert preview.text.startswith("%\nO2001 (PLATE 2001)\nG21 G90 G94\nT1 M06\n")
        assert to_mill1.status_code == to_mill2.status_code == 202, to_mill1.text
        assert to_mill1.json()["derived_id"] == to_mill2.json()["derived_id"] == 1
        [row] = derived.json()
        assert (row["id"], row["source_revision_id"], row["machine_kind"]) == (1, 2, "mill")
        assert (row["post_name"], row["post_version"], row["tolerance_mm"]) == (
            "fanuc-mill",
            "1.0",
            None,
        )
        # both transfers done and verified: each mill holds the posted program
        for d in (to_mill1.json(), to_mill2.json()):
            deadline = time.monotonic() + 60
            while (now := c.get(f"/api/dispatches/{d['id']}").json())["state"] != "done":
                assert now["state"] != "failed", now["error"]
                assert time.monotonic() < deadline, now
                time.sleep(0.05)
            assert now["verified"] is True
        assert c.get("/api/derived-revisions/1/text").text == preview.text
    finally:
        cell.stop()
