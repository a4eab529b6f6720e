"""docker-compose.yml without a Docker engine: its structure against the Compose
specification, and every service's command parsed by the real fmscell CLI.

The compose file is the version-less Compose specification. These tests check what
`docker compose config` would refuse and what would only fail at `up`: commands or options
the CLI does not have, a dependency on a service without a health check, undeclared named
volumes, a database URL that does not point at the db service, health checks on ports the
machines do not open. The health check script itself is run against real sockets.
"""

from __future__ import annotations

import http.server
import re
import socket
import subprocess
import sys
import threading
from pathlib import Path

import click
import pytest
import typer
import yaml
from sqlalchemy.engine import make_url
from typer.testing import CliRunner

from server.cli import app as fmscell_app
from server.config import load_cell_config
from web_api.settings import ApiSettings

ROOT = Path(__file__).resolve().parents[1]
COMPOSE = ROOT / "docker-compose.yml"
CELL = ROOT / "docker" / "cell.yaml"
HEALTHCHECK = ROOT / "docker" / "healthcheck.py"
TOP_LEVEL = {"name", "services", "networks", "volumes", "configs", "secrets", "include"}
CONDITIONS = {"service_started", "service_healthy", "service_completed_successfully"}
DURATION = re.compile(r"^(\d+(\.\d+)?(us|ms|s|m|h))+$")
CONTAINER_CELL = "/etc/fmscell/cell.yaml"


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


@pytest.fixture(scope="module")
def services(compose) -> dict:
    return compose["services"]


@pytest.fixture(scope="module")
def cell():
    return load_cell_config(CELL)


def fmscell_services(services: dict) -> dict:
    return {n: s for n, s in services.items() if s.get("command", [None])[0] == "fmscell"}


def machine_services(services: dict) -> dict:
    return {n: s for n, s in fmscell_services(services).items() if s["command"][1] == "machine"}


def option(command: list[str], name: str) -> str:
    assert name in command, f"{command} has no {name}"
    return command[command.index(name) + 1]


# ------------------------------------------------------------------------------ structure


def test_the_file_is_the_versionless_compose_specification(compose):
    assert "version" not in compose, "the Compose specification has no 'version' key"
    unknown = {k for k in compose if k not in TOP_LEVEL and not k.startswith("x-")}
    assert not unknown, f"unknown top-level keys {unknown}"


def test_the_cell_has_a_database_a_host_and_one_service_per_machine(services, cell):
    assert {"db", "host"} <= set(services)
    assert set(machine_services(services)) == set(cell.machines)
    assert set(services) == {"db", "host", *cell.machines}


def test_every_service_has_an_image_or_a_build_that_exists(services):
    for name, s in services.items():
        assert "image" in s or "build" in s, name
        if "build" in s:
            build = s["build"]
            context = ROOT / build["context"]
            assert context.is_dir(), f"{name}: build context {context}"
            assert (context / build.get("dockerfile", "Dockerfile")).is_file(), name


def test_the_database_is_postgresql_16_with_a_named_volume_and_pg_isready(services, compose):
    db = services["db"]
    assert db["image"] == "postgres:16"
    named = [v.split(":")[0] for v in db["volumes"] if not v.startswith((".", "/"))]
    assert named and all(v in compose["volumes"] for v in named)
    test = db["healthcheck"]["test"]
    assert test[0] in ("CMD", "CMD-SHELL") and "pg_isready" in " ".join(test)


def test_the_host_uses_the_db_service_with_its_credentials(services):
    db_env = services["db"]["environment"]
    url = make_url(services["host"]["environment"]["FMSCELL_DATABASE_URL"])
    assert url.drivername == "postgresql+psycopg"  # psycopg 3 is the pinned driver
    assert url.host == "db" and (url.port or 5432) == 5432
    assert url.username == db_env["POSTGRES_USER"]
    assert url.password == db_env["POSTGRES_PASSWORD"]
    assert url.database == db_env["POSTGRES_DB"]


def test_dependencies_name_services_and_wait_for_health(services):
    for name, s in services.items():
        deps = s.get("depends_on", {})
        assert isinstance(deps, dict), f"{name}: depends_on in the long form, with conditions"
        for target, spec in deps.items():
            assert target in services, f"{name} depends on unknown service {target}"
            assert spec["condition"] in CONDITIONS, (name, target)
            if spec["condition"] == "service_healthy":
                assert "healthcheck" in services[target], f"{target} has no healthcheck"
    host_deps = services["host"]["depends_on"]
    assert host_deps["db"]["condition"] == "service_healthy"
    for machine in machine_services(services):
        assert host_deps[machine]["condition"] == "service_healthy"


def test_every_service_has_a_wellformed_healthcheck(services):
    for name, s in services.items():
        hc = s.get("healthcheck")
        assert hc, f"{name} has no healthcheck"
        assert isinstance(hc["test"], list) and hc["test"][0] in ("CMD", "CMD-SHELL"), name
        for key in ("interval", "timeout", "start_period"):
            assert DURATION.match(str(hc[key])), f"{name}.healthcheck.{key}: {hc[key]!r}"
        assert isinstance(hc["retries"], int) and hc["retries"] >= 1, name


def test_named_volumes_are_declared_and_bind_mounts_exist(services, compose):
    declared = set(compose.get("volumes") or {})
    used = set()
    for name, s in services.items():
        for v in s.get("volumes", []):
            source, target = v.split(":")[:2]
            assert target.startswith("/"), f"{name}: volume target {target}"
            if source.startswith((".", "/")):
                assert (ROOT / source).exists(), f"{name}: bind mount {source} does not exist"
            else:
                assert source in declared, f"{name}: volume {source} not declared"
                used.add(source)
    assert used == declared, f"declared but unused: {declared - used}"


def test_networks_are_declared(services, compose):
    declared = set(compose.get("networks") or {})
    for name, s in services.items():
        assert set(s.get("networks", [])) <= declared, name


def test_published_ports_are_on_the_loopback_only(services):
    for name, s in services.items():
        for p in s.get("ports", []):
            assert str(p).startswith("127.0.0.1:"), f"{name} publishes {p} on every address"


# ------------------------------------------------------------------------------ commands


def test_commands_are_in_exec_form(services):
    for name, s in fmscell_services(services).items():
        assert all(isinstance(a, str) for a in s["command"]), f"{name}: strings only"
    assert set(fmscell_services(services)) == set(services) - {"db"}


@pytest.mark.parametrize("name", ["host", "mill1", "mill2", "lathe1"])
def test_every_command_and_option_exists_in_the_cli(services, name):
    """The command line is parsed by the real CLI (click's parser, nothing is run): an
    unknown sub-command, an unknown option or a value of the wrong type fails here."""
    argv = services[name]["command"][1:]
    group = typer.main.get_command(fmscell_app)
    with click.Context(group, info_name="fmscell") as ctx:
        sub = group.get_command(ctx, argv[0])
        assert sub is not None, (
            f"{name}: `fmscell {argv[0]}` is not a command of the fmscell CLI "
            f"(commands: {', '.join(group.list_commands(ctx))})"
        )
        known = {o for p in sub.params for o in p.opts + p.secondary_opts}
        missing = [a for a in argv[1:] if a.startswith("--") and a not in known]
        assert not missing, (
            f"{name}: `fmscell {argv[0]}` has no option {', '.join(missing)} "
            f"(it has {', '.join(sorted(known))})"
        )
        try:
            sub.make_context(argv[0], list(argv[1:]), parent=ctx)
        except click.ClickException as err:
            pytest.fail(f"{name}: fmscell {' '.join(argv)}: {err.format_message()}")
    result = CliRunner().invoke(fmscell_app, [argv[0], "--help"])
    assert result.exit_code == 0, result.output


def test_machine_services_run_the_machine_of_their_name_from_the_mounted_cell(services, cell):
    for name, s in machine_services(services).items():
        command = s["command"]
        assert option(command, "--name") == name
        assert option(command, "--config") == CONTAINER_CELL
        assert any(v.endswith(f":{CONTAINER_CELL}:ro") for v in s["volumes"]), name
        log = option(command, "--event-log")
        assert any(log.startswith(v.split(":")[1] + "/") for v in s["volumes"]), (
            f"{name}: the event log {log} is not on a volume"
        )


def test_machine_services_power_on_before_the_attached_host_gives_them_work(services):
    """The attached host starts no machine and runs no power-on: each machine service homes
    its axes and takes AUTO itself (a `home` command over the API would do it later)."""
    for name, s in machine_services(services).items():
        assert "--power-on" in s["command"], name


def test_machine_healthchecks_probe_the_configured_modbus_face(services, cell):
    for name, s in machine_services(services).items():
        test = s["healthcheck"]["test"]
        assert test[1:3] == ["fmscell-healthcheck", "tcp"], name
        ports = cell.machines[name].ports
        assert test[3] == ports.host == name, f"{name}: faces must bind to the service name"
        assert int(test[4]) == ports.modbus


def test_fault_injection_reaches_every_machines_simulation_face(services, cell):
    """`--faults` on the host sends faults through each machine's simulation face, which
    must then be on (`--simulation`) at a fixed port the host knows from the cell file."""
    if "--faults" not in services["host"]["command"]:
        pytest.skip("the compose cell runs without fault injection")
    for name, s in machine_services(services).items():
        assert "--simulation" in s["command"], name
        assert cell.machines[name].ports.simulation, f"{name}: no fixed simulation port"


def test_host_serves_on_the_published_port_and_checks_its_health(services, cell):
    host = services["host"]
    command = host["command"]
    assert option(command, "--config") == CONTAINER_CELL
    port = int(option(command, "--port"))
    assert f"127.0.0.1:{port}:{port}" in host["ports"]
    assert host["healthcheck"]["test"][-1] == f"http://127.0.0.1:{port}/api/health"
    assert cell.host.port == port


def test_the_cell_file_is_valid_and_its_keys_parse(cell):
    settings = ApiSettings.from_mapping(cell.host.auth)
    assert {k.role.name for k in settings.api_keys} == {
        "viewer",
        "operator",
        "programmer",
        "admin",
    }


def test_the_image_installs_the_healthcheck_and_the_cell_file():
    dockerfile = (ROOT / "docker" / "Dockerfile").read_text()
    assert re.search(r"^FROM python:3\.11", dockerfile, re.M)
    assert "COPY docker/healthcheck.py /usr/local/bin/fmscell-healthcheck" in dockerfile
    for package in ("server", "web_api", "dnc", "cam", "cnc", "plc", "drives"):
        assert f"COPY {package} ./{package}" in dockerfile, package
    assert re.search(r"^USER (?!root)", dockerfile, re.M), "the services run unprivileged"
    ignored = (ROOT / "docker" / "Dockerfile.dockerignore").read_text().split()
    assert {".venv", ".git", "test-output", "*.db"} <= set(ignored)


# ------------------------------------------------------------------------------ healthcheck


def run_check(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(HEALTHCHECK), *args], capture_output=True, text=True, timeout=30
    )


def test_tcp_check_passes_on_a_listening_face_and_fails_on_a_closed_one():
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        port = listener.getsockname()[1]
        assert run_check("tcp", "127.0.0.1", str(port)).returncode == 0
    closed = run_check("tcp", "127.0.0.1", str(port))
    assert closed.returncode == 1
    assert f"unhealthy: tcp 127.0.0.1:{port}" in closed.stderr


class _Health(http.server.BaseHTTPRequestHandler):
    answers = {"/ok": (200, b'{"status":"ok"}'), "/down": (503, b'{"type":"x"}')}

    def do_GET(self):  # noqa: N802 - http.server's name
        status, body = self.answers.get(self.path, (200, b"not json"))
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@pytest.fixture
def health_server():
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Health)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


@pytest.mark.parametrize(
    ("path", "code", "why"),
    [
        ("/ok", 0, ""),
        ("/down", 1, "HTTP 503"),
        ("/garbage", 1, "not a JSON object"),
    ],
)
def test_http_check_wants_200_and_status_ok(health_server, path, code, why):
    r = run_check("http", health_server + path)
    assert r.returncode == code, r.stderr
    assert why in r.stderr


def test_healthcheck_usage_errors_exit_2():
    for args in ([], ["tcp", "db"], ["tcp", "db", "five"], ["ftp", "x"]):
        r = run_check(*args)
        assert r.returncode == 2 and "usage:" in r.stderr, args
