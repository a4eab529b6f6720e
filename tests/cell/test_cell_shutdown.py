"""`fmscell run` stops cleanly on SIGTERM/SIGINT while a client watches the event stream (and
`host.faults` in the cell file turns fault injection on by itself).

uvicorn waits for open responses before it shuts the app down, and an SSE stream never ends
by itself: without closing the event hub first, an open dashboard kept the host up forever."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import httpx
import pytest
import yaml

from tests.cell.conftest import KEYS, Api
from tests.cell.test_cell_restart import cell_file, free_port, wait_healthy

pytestmark = pytest.mark.timeout(120)


@pytest.mark.parametrize(("sig", "faults"), [(signal.SIGTERM, False), (signal.SIGINT, True)])
def test_host_stops_on_a_signal_while_an_event_stream_is_open(tmp_path, sig, faults):
    port = free_port()
    env = {
        k: v for k, v in os.environ.items() if k not in ("FMSCELL_DATABASE_URL", "FMSCELL_FAULTS")
    }
    config = cell_file(tmp_path)
    doc = yaml.safe_load(config.read_text())
    doc["host"]["faults"] = faults  # fault injection enabled by the configuration alone
    config.write_text(yaml.safe_dump(doc))
    cmd = [sys.executable, "-m", "server.cli", "run", "--config", str(config)]
    cmd += ["--clock", "fast", "--ideal-axes", "--port", str(port)]
    log = tmp_path / "host.log"
    with open(log, "ab") as out:
        host = subprocess.Popen(
            cmd, cwd=tmp_path, stdout=out, stderr=out, env={**env, "PYTHONPATH": os.getcwd()}
        )
    api = Api(f"http://127.0.0.1:{port}")
    try:
        wait_healthy(api, host, tmp_path)
        assert api("admin").get("/api/fault-types").status_code == (200 if faults else 404)
        headers = {"X-API-Key": KEYS["viewer"]}
        with httpx.stream(
            "GET", f"http://127.0.0.1:{port}/api/events", headers=headers, timeout=30
        ) as stream:
            assert stream.status_code == 200
            lines = stream.iter_lines()
            assert next(lines).startswith(":")  # the stream's opening comment: it is open
            host.send_signal(sig)
            # the stream ends (the hub closed it) instead of holding the server up
            for _ in lines:
                pass
        assert host.wait(60) == 0, log.read_text()[-3000:]
    finally:
        api.close()
        if host.poll() is None:
            host.kill()
            host.wait(10)
    assert "fmscell cell stopped" in log.read_text()
