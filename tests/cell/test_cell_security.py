"""`fmscell run` secure by default: off loopback it needs keys (or says loudly that it has
none), on loopback without keys it prints a one-run admin key, `host.tls` serves HTTPS."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import ssl
import subprocess
import sys
import threading
from pathlib import Path

import httpx
import pytest
import yaml
from typer.testing import CliRunner

from server.cell import exposure
from server.cli import app
from web_api.settings import ApiSettings

ROOT = Path(__file__).resolve().parents[2]
KEYED = ApiSettings.from_mapping(
    {"api_keys": [{"user": "anna", "role": "operator", "key": "anna-key-0123456789"}]}
)
NO_KEYS = ApiSettings()
OPEN = ApiSettings(insecure_open=True)

# bind, settings, tls -> refused?, the words the warning must carry (None = no warning)
EXPOSURE = [
    ("127.0.0.1", NO_KEYS, False, False, None),
    ("::1", NO_KEYS, False, False, None),
    ("localhost", OPEN, False, False, None),
    ("127.0.0.2", KEYED, False, False, None),
    ("0.0.0.0", NO_KEYS, False, True, None),
    ("::", NO_KEYS, True, True, None),
    ("192.168.1.20", NO_KEYS, False, True, None),
    ("cellhost.local", NO_KEYS, False, True, None),
    ("0.0.0.0", OPEN, False, False, "ANYONE who can reach port 8000 is an admin"),
    ("0.0.0.0", KEYED, False, False, "API keys cross the network in clear"),
    ("0.0.0.0", KEYED, True, False, "reachable from other hosts"),
]


@pytest.mark.parametrize(("bind", "settings", "tls", "refused", "warning"), EXPOSURE)
def test_serving_off_loopback_needs_keys_or_a_loud_demo_flag(bind, settings, tls, refused, warning):
    refusal, warnings = exposure(bind, 8000, settings, tls=tls)
    assert (refusal is not None) == refused
    if refused:
        assert f"refusing to serve on {bind}" in refusal
        assert "host.auth.api_keys" in refusal and "--insecure-open" in refusal
    if warning is None:
        assert warnings == []
    else:
        assert len(warnings) == 1 and warning in warnings[0]
        assert warnings[0].startswith("WARNING")
        assert ("in clear" in warnings[0]) == (not tls and not settings.insecure_open)


def test_run_on_all_interfaces_without_keys_refuses_before_starting_anything():
    result = CliRunner().invoke(app, ["run", "--host", "0.0.0.0", "--port", "1"])
    assert result.exit_code == 2, result.output
    assert "refusing to serve on 0.0.0.0" in result.output
    assert "fmscell cell:" not in result.output  # no machine started


def test_a_missing_or_bad_certificate_is_refused_before_anything_starts(tmp_path):
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        "machines:\n  m1:\n    base: mill3\n"
        "host:\n  tls:\n    cert: nowhere.pem\n    key: nowhere.key\n"
    )
    result = CliRunner().invoke(app, ["run", "--config", str(cell)])
    assert result.exit_code == 2, result.output
    assert "host.tls.cert: no such file" in result.output
    assert str(tmp_path / "nowhere.pem") in result.output  # relative to the cell file
    (tmp_path / "nowhere.pem").write_text("not a certificate\n")
    (tmp_path / "nowhere.key").write_text("not a key\n")
    result = CliRunner().invoke(app, ["run", "--config", str(cell)])
    assert result.exit_code == 2 and "host.tls: cannot load" in result.output


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_run_without_keys_prints_a_working_admin_key_and_serves_https(tmp_path):
    """The README's tour from `make run`: the printed `export KEY=...` line is a key the
    cell takes; with host.tls the API is HTTPS with that certificate."""
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("SKIPPED: no `openssl` command to make a self-signed certificate")
    subprocess.run(
        [openssl, "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1"]
        + ["-nodes", "-keyout", "key.pem", "-out", "cert.pem", "-days", "2"]
        + ["-subj", "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1"],
        cwd=tmp_path,
        check=True,
        capture_output=True,
        timeout=60,
    )
    port = free_port()
    ports = {"host": "127.0.0.1", "dnc": 0, "modbus": 0, "shdr": 0}
    cell = {
        "machines": {"m1": {"base": "mill3", "ports": ports}},
        "host": {"port": port, "tls": {"cert": "cert.pem", "key": "key.pem"}},
    }
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump(cell))
    env = {
        **os.environ,
        "PYTHONPATH": str(ROOT),  # not PYTHONUNBUFFERED: the banner is flushed
        "FMSCELL_DATABASE_URL": f"sqlite:///{tmp_path}/cell.db",
    }
    cmd = [sys.executable, "-m", "server.cli", "run", "--config", "cell.yaml"]
    cmd += ["--clock", "fast", "--ideal-axes"]
    proc = subprocess.Popen(
        cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    lines: list[str] = []
    key_seen = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if line.startswith("export KEY="):
                key_seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert key_seen.wait(180), "\n".join(lines)
        key = next(ln for ln in lines if ln.startswith("export KEY="))[len("export KEY=") :]
        assert len(key) >= 16
        assert any(f"https://127.0.0.1:{port}/docs" in ln for ln in lines), lines
        verify = ssl.create_default_context(cafile=str(tmp_path / "cert.pem"))
        base = f"https://127.0.0.1:{port}"
        with httpx.Client(base_url=base, verify=verify, timeout=20) as c:
            # at once: the key line is printed once the API answers (a script reading it
            # and connecting straight away met a refused connection when it came first)
            r = c.get("/api/whoami", headers={"X-API-Key": key})
            assert r.status_code == 200, r.text
            assert r.json() == {"user": "local-admin", "role": "admin"}
            assert c.get("/api/whoami").status_code == 401
            assert c.get("/api/health").json()["insecure_open"] is False
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
        reader.join(10)
    assert "fmscell cell stopped" in lines, lines


def test_machine_secrets_generated_kept_owner_only_and_configured_ones_win(tmp_path):
    from server.cell import Cell
    from server.config import load_cell_config

    cfg = load_cell_config(
        {
            "machines": {
                "m1": {"base": "mill3"},
                "m2": {
                    "base": "mill3",
                    "ports": {"dnc": 0, "modbus": 0, "shdr": 0, "secret": "configured-secret-0001"},
                },
            }
        }
    )
    cell = Cell(cfg, state_dir=tmp_path)
    first = cell._secret("m1", cfg.machines["m1"], persist=True)
    path = tmp_path / "m1.machine.secret"
    assert path.stat().st_mode & 0o777 == 0o600
    assert len(first) >= 16
    # a host started again finds the secret of the machine process it adopts
    assert Cell(cfg, state_dir=tmp_path)._secret("m1", cfg.machines["m1"], persist=True) == first
    # an in-process machine gets a fresh one each start; a configured one is used as is
    fresh = {cell._secret("m1", cfg.machines["m1"], persist=False) for _ in range(3)}
    assert len(fresh) == 3 and first not in fresh
    assert cell._secret("m2", cfg.machines["m2"], persist=True) == "configured-secret-0001"
    assert not (tmp_path / "m2.machine.secret").exists()
