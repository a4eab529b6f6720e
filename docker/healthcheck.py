#!/usr/bin/env python3
"""Container health checks of the fmscell services, with nothing but the standard library.

    healthcheck.py tcp HOST PORT     a face accepts a TCP connection (Modbus, DNC, SHDR)
    healthcheck.py http URL          the URL answers 200 with JSON {"status": "ok"}

Exit 0 when healthy, 1 when not (with one line on stderr saying why), 2 on bad usage:
Docker's HEALTHCHECK contract. A TCP check opens and closes a connection and sends
nothing, so it never starts a transfer or a Modbus transaction on the machine.
"""

from __future__ import annotations

import json
import socket
import sys
import urllib.error
import urllib.request

TIMEOUT_S = 3.0


def check_tcp(host: str, port: int, timeout: float = TIMEOUT_S) -> str | None:
    """None when host:port accepts a connection, else why not."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None
    except OSError as err:
        return f"tcp {host}:{port}: {err.strerror or err}"


def check_http(url: str, timeout: float = TIMEOUT_S) -> str | None:
    """None when url answers 200 with a JSON body whose status is "ok", else why not."""
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:  # noqa: S310 - our own URL
            body = r.read(64 * 1024)
    except urllib.error.HTTPError as err:
        return f"{url}: HTTP {err.code} {err.reason}"
    except (urllib.error.URLError, OSError) as err:
        return f"{url}: {getattr(err, 'reason', err)}"
    try:
        status = json.loads(body).get("status")
    except (ValueError, AttributeError):
        return f"{url}: answer is not a JSON object"
    return None if status == "ok" else f"{url}: status {status!r}, not 'ok'"


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] == "tcp" and argv[2].isdigit():
        problem = check_tcp(argv[1], int(argv[2]))
    elif len(argv) == 2 and argv[0] == "http" and argv[1].startswith("http"):
        problem = check_http(argv[1])
    else:
        print("usage: healthcheck.py tcp HOST PORT | http URL", file=sys.stderr)
        return 2
    if problem:
        print(f"unhealthy: {problem}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
