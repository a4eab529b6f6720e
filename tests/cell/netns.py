"""Network namespaces as the test's own hosts: each joined to this one by a veth pair on a
private /24 of its own (10.x.y.0/24: this side .1, the namespace's .2).

Names carry a random tag (namespaces `fmsc-<tag>-<n>`, veths `fv<tag><n>` here and
`fp<tag><n>` inside, within the 15 characters of an interface name), and the subnets are
chosen among those no interface here uses, so tests running in parallel (pytest-xdist,
other checkouts) never meet. `close()` deletes what was made, whatever failed.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import random
import secrets
import shutil
import subprocess
from dataclasses import dataclass, field

IP = shutil.which("ip") or "/usr/sbin/ip"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run([IP, *args], capture_output=True, text=True, timeout=20, check=check)


def why_not_permitted() -> str | None:
    """None when this process may make network namespaces and veth pairs, else why not."""
    if not os.path.exists(IP):
        return "no `ip` command (iproute2)"
    if os.geteuid() != 0:
        return "`ip netns add` needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN)"
    probe = f"fmsc-probe-{secrets.token_hex(3)}"
    made = _ip("netns", "add", probe, check=False)
    if made.returncode != 0:
        return f"`ip netns add` is not permitted here: {made.stderr.strip()}"
    _ip("netns", "del", probe, check=False)
    return None


@dataclass
class Host:
    """One namespace: its name and its address (.2) and this side's (.1) on its link."""

    netns: str
    veth: str  # this side's end
    address: str
    peer_address: str

    def command(self, *args: str) -> list[str]:
        """`args` run inside the namespace (ip execs it: the pid is the command's)."""
        return [IP, "netns", "exec", self.netns, *args]


@dataclass
class Namespaces:
    tag: str = field(default_factory=lambda: secrets.token_hex(3))
    hosts: list[Host] = field(default_factory=list)

    def add(self) -> Host:
        n = len(self.hosts) + 1
        netns, here, there = f"fmsc-{self.tag}-{n}", f"fv{self.tag}{n}", f"fp{self.tag}{n}"
        net = _free_subnet({ipaddress.ip_network(f"{h.address}/24", strict=False)
                            for h in self.hosts})  # fmt: skip
        host = Host(netns, here, str(net[2]), str(net[1]))
        # recorded before it exists: close() deletes whatever part of it was made
        self.hosts.append(host)
        _ip("netns", "add", netns)
        _ip("link", "add", here, "type", "veth", "peer", "name", there)
        _ip("link", "set", there, "netns", netns)
        _ip("addr", "add", f"{host.peer_address}/24", "dev", here)
        _ip("link", "set", here, "up")
        inside = ["netns", "exec", netns, IP]
        _ip(*inside, "addr", "add", f"{host.address}/24", "dev", there)
        _ip(*inside, "link", "set", there, "up")
        _ip(*inside, "link", "set", "lo", "up")
        return host

    def close(self) -> list[str]:
        """Delete every namespace and veth made; the failures, if any (never raises)."""
        failures = []
        for host in self.hosts:
            with contextlib.suppress(subprocess.SubprocessError, OSError):
                # a namespace's end goes with it, and the pair with either end
                r = _ip("netns", "del", host.netns, check=False)
                if r.returncode != 0 and "No such file" not in r.stderr:
                    failures.append(f"netns del {host.netns}: {r.stderr.strip()}")
                r = _ip("link", "del", host.veth, check=False)
                if r.returncode != 0 and "Cannot find device" not in r.stderr:
                    failures.append(f"link del {host.veth}: {r.stderr.strip()}")
        return failures


def _free_subnet(taken: set) -> ipaddress.IPv4Network:
    """A 10.x.y.0/24 that no interface here (nor this test) uses."""
    used = set(taken)
    for line in _ip("-o", "-4", "addr", "show").stdout.splitlines():
        parts = line.split()
        if "inet" in parts:
            used.add(ipaddress.ip_network(parts[parts.index("inet") + 1], strict=False))
    for _ in range(200):
        net = ipaddress.ip_network(f"10.{random.randint(160, 250)}.{random.randint(0, 255)}.0/24")
        if not any(net.overlaps(u) for u in used):
            return net
    raise RuntimeError("no free 10.x.y.0/24 subnet found")
