"""A TCP proxy in front of a machine's DNC port that injects line faults, one per connection."""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from dataclasses import dataclass

from cnc.faces.tape import XOFF, XON


@dataclass
class Fault:
    kind: str  # "drop" | "corrupt" | "xoff_hold" | "xoff_storm" | "none"
    at: int = 0  # client->machine byte offset where it strikes
    hold_s: float = 0.0


class FaultPort:
    """Connections take faults from the queue in order; once it is empty they pass clean."""

    def __init__(self, upstream_port: int, faults: list[Fault]) -> None:
        self.upstream = upstream_port
        self.faults = list(faults)
        self.listener = socket.socket()
        # A small window, like a serial line: the sender cannot run far ahead of the faults.
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.listener.bind(("127.0.0.1", 0))
        self.listener.listen()
        self.port = self.listener.getsockname()[1]
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._accept = threading.Thread(target=self._serve, daemon=True)
        self._accept.start()

    def close(self) -> None:
        self._stop.set()
        self.listener.close()
        for t in self._threads:
            t.join(5)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            fault = self.faults.pop(0) if self.faults else Fault("none")
            upstream = socket.create_connection(("127.0.0.1", self.upstream))
            t = threading.Thread(target=self._pump, args=(client, upstream, fault), daemon=True)
            t.start()
            self._threads.append(t)

    def _pump(self, client: socket.socket, upstream: socket.socket, fault: Fault) -> None:
        def down() -> None:  # machine -> client; a half-close passes through as one
            with contextlib.suppress(OSError):
                while True:
                    data = upstream.recv(4096)
                    if not data:
                        client.shutdown(socket.SHUT_WR)
                        break
                    client.sendall(data)

        downstream = threading.Thread(target=down, daemon=True)
        downstream.start()
        seen = 0
        try:
            while True:
                data = client.recv(4096)
                if not data:
                    break
                if seen <= fault.at < seen + len(data):
                    cut = fault.at - seen
                    if fault.kind == "drop":  # the cable is pulled: no goodbyes either way
                        upstream.sendall(data[:cut])
                        for sock in (client, upstream):
                            sock.setsockopt(
                                socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0)
                            )
                            sock.close()
                        return
                    if fault.kind == "corrupt":
                        data = data[:cut] + bytes([data[cut] ^ 0x02]) + data[cut + 1 :]
                    elif fault.kind == "xoff_hold":
                        client.sendall(bytes([XOFF]))
                        time.sleep(fault.hold_s)  # the line stays stopped this long
                        client.sendall(bytes([XON]))
                    elif fault.kind == "xoff_storm":
                        for _ in range(50):
                            client.sendall(bytes([XOFF, XON]))
                seen += len(data)
                upstream.sendall(data)
        except OSError:
            pass
        finally:
            with contextlib.suppress(OSError):
                upstream.shutdown(socket.SHUT_WR)
            downstream.join(5)
            for s in (client, upstream):
                with contextlib.suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)
                s.close()
