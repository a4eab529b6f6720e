# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Security by default over real HTTP: a limit on failed authentication (429 with
Retry-After), HTTPS with a configured certificate."""

from __future__ import annotations

import shutil
import socket
import ssl
import subprocess
import threading

import httpx
import pytest
import uvicorn

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    KEYS,
    SQLITE_ONLY,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)
from web_api.ratelimit import AuthFailureLimiter

pytestmark = [pytest.mark.timeout(120)]


class Served:
    """The API on a real uvicorn socket on 127.0.0.1 (HTTPS when given a cert and key)."""

    def __init__(self, app, *, cert: str | None = None, key: str | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        config = uvicorn.Config(
            app,
            log_level="warning",
            lifespan="off",
            timeout_graceful_shutdown=5,
            ssl_certfile=cert,
            ssl_keyfile=key,
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True
        )
        self.thread.start()
        scheme = "https" if cert else "http"
        self.base = f"{scheme}://127.0.0.1:{self.sock.getsockname()[1]}"

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=20)
        self.sock.close()
        assert not self.thread.is_alive(), "uvicorn did not shut down"


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def served(sessions):
    api = make_api(sessions)
    clock = FakeClock()
    # the app's own limiter (10 failures per 10 s), read on a clock the test moves
    limiter: AuthFailureLimiter = api.client.app.state.auth_failures
    limiter.clock = clock
    s = Served(api.client.app)
    yield s, limiter, clock
    s.close()


@SQLITE_ONLY
def test_guessing_keys_gets_429_with_retry_after_and_valid_keys_are_unaffected(served):
    s, limiter, clock = served
    assert (limiter.limit, limiter.window_s) == (10, 10.0)
    with httpx.Client(base_url=s.base, timeout=20) as c:
        good = {"X-API-Key": KEYS["viewer"]}
        # successful requests never count, however many
        for _ in range(25):
            assert c.get("/api/whoami", headers=good).status_code == 200
        # ten wrong keys: ten 401s, interleaved valid requests still 200
        for i in range(10):
            r = c.get("/api/whoami", headers={"X-API-Key": f"guess-{i:02d}-0123456789"})
            assert r.status_code == 401, r.text
            clock.t += 0.5
            if i < 9:  # under the limit a valid key is served as usual
                assert c.get("/api/whoami", headers=good).status_code == 200
        # the eleventh presented key, whatever it is, is not even looked at: 429
        for headers in ({"X-API-Key": "guess-11-0123456789"}, good, {"Authorization": "Bearer x"}):
            r = c.get("/api/programs", headers=headers)
            assert r.status_code == 429, r.text
            assert r.headers["content-type"].startswith("application/problem+json")
            body = r.json()
            assert body["type"].endswith("/too-many-auth-failures")
            # the first failure was at t=1000, so the block ends at 1010; now t=1005
            assert r.headers["retry-after"] == "5" == str(body["retry_after_s"])
            assert "10 failed authentications from 127.0.0.1" in body["detail"]
        # no key at all is still the plain 401 (nothing to guess)
        assert c.get("/api/whoami").status_code == 401
        # the block ends when the oldest failures leave the window
        clock.t = 1009.9
        assert c.get("/api/whoami", headers=good).status_code == 429
        clock.t = 1010.01
        assert c.get("/api/whoami", headers=good).status_code == 200
        # one more failure right away blocks again (9 still in the window + 1)
        assert c.get("/api/whoami", headers={"X-API-Key": "guess-x-0123456789"}).status_code == 401
        assert c.get("/api/whoami", headers=good).status_code == 429


@SQLITE_ONLY
def test_the_openapi_document_lists_429_where_keys_are_checked(served):
    s, _, _ = served
    doc = httpx.get(s.base + "/openapi.json", timeout=20).json()
    whoami = doc["paths"]["/api/whoami"]["get"]["responses"]
    assert "401" in whoami and "429" in whoami


def test_the_limiter_is_per_address_and_bounded():
    clock = FakeClock()
    lim = AuthFailureLimiter(3, 10.0, max_addresses=2, clock=clock)
    for _ in range(3):
        lim.failed("10.0.0.1")
    assert lim.retry_after("10.0.0.1") == 10
    assert lim.retry_after("10.0.0.2") is None
    lim.failed("10.0.0.2")
    lim.failed("10.0.0.3")  # a third address evicts the least recently failing one
    assert lim.retry_after("10.0.0.1") is None
    clock.t += 9.5
    assert lim.retry_after("10.0.0.2") is None
    with pytest.raises(ValueError):
        AuthFailureLimiter(0, 1.0)


# --- HTTPS ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def self_signed(tmp_path_factory):
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("SKIPPED: no `openssl` command to make a self-signed certificate")
    d = tmp_path_factory.mktemp("tls")
    cert, key = d / "cert.pem", d / "key.pem"
    subprocess.run(
        [
            openssl,
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
            "-keyout",
            str(key),
            "-out",
            str(cert),
            "-days",
            "2",
            "-subj",
            "/CN=127.0.0.1",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
        ],
        check=True,
        capture_output=True,
        timeout=60,
    )
    return cert, key


@SQLITE_ONLY
def test_https_with_the_configured_certificate(sessions, self_signed):
    cert, key = self_signed
    api = make_api(sessions)
    s = Served(api.client.app, cert=str(cert), key=str(key))
    try:
        with httpx.Client(
            base_url=s.base, verify=ssl.create_default_context(cafile=str(cert)), timeout=20
        ) as c:
            r = c.get("/api/whoami", headers={"X-API-Key": KEYS["operator"]})
            assert r.status_code == 200 and r.json()["role"] == "operator"
            assert r.url.scheme == "https"
        # plain HTTP to the HTTPS port is not served
        with pytest.raises(httpx.HTTPError):
            httpx.get(s.base.replace("https", "http") + "/api/health", timeout=5).raise_for_status()
        # a client that does not trust the certificate refuses it
        with pytest.raises(httpx.ConnectError):
            httpx.get(s.base + "/api/health", timeout=5)
    finally:
        s.close()
