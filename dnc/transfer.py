"""The host's side of a machine's DNC port: send, drip-feed, punch, directory, remote requests.

Synchronous sockets: each transfer runs in a worker thread of the host. Flow control follows
the machine: between chunks the client looks for XOFF and, once stopped, sends nothing until
XON. Every failure is a TransferError with a `kind` the dispatch record keeps, so "the
transfer failed" always says how (cut off, refused with alarm N, stuck in XOFF, ...).
"""

from __future__ import annotations

import contextlib
import hashlib
import re
import select
import socket
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from cnc.faces.tape import (
    PUNCH_OFF,
    PUNCH_ON,
    XOFF,
    XON,
    TapeDecoder,
    add_parity,
    encode_program,
    strip_parity,
)

_FLOW_BYTES = bytes([XON, XOFF, PUNCH_ON, PUNCH_OFF])
LINE_ALARMS = frozenset({2001, 2004, 2007, 2010})  # parity, cut off, time-out, overrun
_REQUEST = re.compile(r"/REQ\s*(\d{1,5})", re.I)


class TransferError(Exception):
    """kind: connect | refused | cut_off | xoff_timeout | timeout | protocol | verify."""

    def __init__(self, kind: str, message: str, *, alarm: int | None = None, sent: int = 0):
        super().__init__(message)
        self.kind, self.message, self.alarm, self.sent = kind, message, alarm, sent

    @property
    def retryable(self) -> bool:
        # Line trouble (a cut, a time-out, a parity error, an overrun) may pass on the next
        # attempt; a refusal for a reason in the machine (memory full, wrong state, no O
        # number) will not cure itself by resending the same bytes.
        if self.kind == "refused":
            return self.alarm in LINE_ALARMS
        return self.kind in ("connect", "cut_off", "timeout", "xoff_timeout", "verify")


@dataclass(frozen=True, slots=True)
class SendResult:
    number: int
    size: int
    sha256: str
    bytes_sent: int
    xoff_count: int


@dataclass(frozen=True, slots=True)
class DripResult:
    blocks: int
    bytes_sent: int
    xoff_count: int


def canonical_text(text: str) -> str:
    """The exact text a machine stores for `text`: what verification compares against."""
    decoder = TapeDecoder()
    lines = [ev.text for ev in decoder.feed(encode_program(text)) if ev.kind == "line"]
    return "%\n" + "".join(f"{ln}\n" for ln in lines) + "%\n"


def sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class DncClient:
    def __init__(
        self,
        host: str,
        port: int,
        *,
        parity: bool = False,
        timeout_s: float = 10.0,
        xoff_timeout_s: float = 30.0,
        chunk: int = 1024,
    ) -> None:
        self.host, self.port, self.parity = host, port, parity
        self.timeout_s, self.xoff_timeout_s, self.chunk = timeout_s, xoff_timeout_s, chunk
        self._sock: socket.socket | None = None
        self._inbox = b""  # reply lines
        self._punching = False
        self._tape = bytearray()  # the punch output being received (between DC2 and DC4)
        self._tapes: list[bytes] = []  # complete punch outputs, oldest first
        self._stopped = False
        self.xoff_count = 0
        self.sent = 0

    # ---------------------------------------------------------------------------- plumbing

    def __enter__(self) -> DncClient:
        try:
            self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        except OSError as exc:
            raise TransferError(
                "connect", f"cannot reach the DNC port {self.host}:{self.port}: {exc}"
            ) from exc
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        # Like a serial line, keep little in flight so XOFF takes effect within a few blocks.
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._sock is not None:
            with contextlib.suppress(OSError, TransferError):
                self._raw_send(b"QUIT\n")
            self._sock.close()
            self._sock = None

    def _encode(self, data: bytes) -> bytes:
        return add_parity(data) if self.parity else data

    def _raw_send(self, data: bytes) -> None:
        try:
            self._sock.sendall(self._encode(data))
        except OSError as exc:
            self._raise_machine_reason()
            raise TransferError(
                "cut_off", f"connection lost after {self.sent} bytes: {exc}", sent=self.sent
            ) from exc
        self.sent += len(data)

    def _raise_machine_reason(self) -> None:
        """When the line drops, the machine's last words (`ERR <alarm> ...`) say why."""
        with contextlib.suppress(OSError):
            while select.select([self._sock], [], [], 0.2)[0]:
                data = self._sock.recv(4096)
                if not data:
                    break
                self._inbox += strip_parity(data) if self.parity else data
        start = self._inbox.find(b"ERR ")
        if start >= 0 and b"\n" in self._inbox[start:]:
            self._inbox = self._inbox[start:]
            self._reply()  # raises the refusal with its alarm number

    def _poll_flow(self, wait: float) -> None:
        """Read what the machine sent; track XON/XOFF; keep everything else for replies."""
        readable, _, _ = select.select([self._sock], [], [], wait)
        if not readable:
            return
        try:
            data = self._sock.recv(4096)
        except OSError as exc:
            raise TransferError("cut_off", f"connection lost: {exc}", sent=self.sent) from exc
        if not data:
            self._raise_machine_reason()
            raise TransferError(
                "cut_off",
                f"the machine closed the connection after {self.sent} bytes",
                sent=self.sent,
            )
        plain = strip_parity(data) if self.parity else data
        if len(plain.translate(None, _FLOW_BYTES)) == len(plain):
            # No flow or punch control in this chunk: it all goes where the last one went.
            if self._punching:
                self._tape += plain
            else:
                self._inbox += plain
            return
        for b in plain:
            if b == XOFF:
                self._stopped = True
                self.xoff_count += 1
            elif b == XON:
                self._stopped = False
            elif b == PUNCH_ON:
                self._punching = True
                self._tape.clear()
            elif b == PUNCH_OFF and self._punching:
                self._punching = False
                self._tapes.append(bytes(self._tape))
            elif self._punching:
                self._tape.append(b)
            else:
                self._inbox += bytes([b])

    def _send_paced(self, data: bytes) -> None:
        for i in range(0, len(data), self.chunk):
            self._poll_flow(0)
            deadline = time.monotonic() + self.xoff_timeout_s
            while self._stopped:
                if b"\n" in self._inbox and self._inbox.startswith(b"ERR"):
                    return  # the machine gave up; its reply explains why
                if time.monotonic() > deadline:
                    raise TransferError(
                        "xoff_timeout",
                        f"the machine held XOFF for {self.xoff_timeout_s:g} s after {self.sent} bytes",
                        sent=self.sent,
                    )
                self._poll_flow(0.05)
            if b"ERR" in self._inbox:
                return
            self._raw_send(data[i : i + self.chunk])

    def _reply(self) -> str:
        deadline = time.monotonic() + self.timeout_s
        while b"\n" not in self._inbox.lstrip(b"\n"):
            if time.monotonic() > deadline:
                raise TransferError("timeout", "no answer from the machine", sent=self.sent)
            self._poll_flow(0.05)
        self._inbox = self._inbox.lstrip(b"\r\n")
        line, _, self._inbox = self._inbox.partition(b"\n")
        text = line.decode("ascii", "replace").strip()
        if text.startswith("ERR"):
            _, alarm, message = (text.split(" ", 2) + ["", ""])[:3]
            raise TransferError(
                "refused",
                f"machine alarm {alarm}: {message}",
                alarm=int(alarm) if alarm.isdigit() else None,
                sent=self.sent,
            )
        return text

    def _receive_tape(self) -> str:
        """The next punched tape (DC2 ... DC4), in stored form."""
        deadline = time.monotonic() + self.timeout_s
        while not self._tapes:
            if self._inbox.startswith(b"ERR") and b"\n" in self._inbox:
                self._reply()  # raises with the machine's reason
            if time.monotonic() > deadline:
                raise TransferError("timeout", "punch output did not arrive", sent=self.sent)
            self._poll_flow(0.05)
        lines = [ev.text for ev in TapeDecoder().feed(self._tapes.pop(0)) if ev.kind == "line"]
        return "%\n" + "".join(f"{ln}\n" for ln in lines) + "%\n"

    # -------------------------------------------------------------------------- operations

    def send_program(self, text: str, *, number: int | None = None) -> SendResult:
        """Load a program into the machine's memory; returns what the machine stored."""
        self.xoff_count = 0
        command = f"READ O{number:04d}\n" if number else "READ\n"
        self._raw_send(command.encode())
        self._send_paced(encode_program(text))
        reply = self._reply()
        parts = reply.split()
        if len(parts) != 4 or parts[0] != "OK":
            raise TransferError("protocol", f"unexpected answer {reply!r}", sent=self.sent)
        return SendResult(int(parts[1][1:]), int(parts[2]), parts[3], self.sent, self.xoff_count)

    def drip_feed(
        self, blocks: Iterable[str], *, progress: Callable[[int, int], None] | None = None
    ) -> DripResult:
        """Stream blocks for execution (BTR). Holds one chunk at a time: memory stays flat."""
        self.xoff_count = 0
        start = self.sent
        self._raw_send(b"DRIP\n")
        self._send_paced(b"%\n")
        count = 0
        pending = bytearray()
        for block in blocks:
            block = block.rstrip("\r\n")
            if block.strip() == "%":
                continue
            pending += block.encode("ascii", "replace") + b"\n"
            count += 1
            if len(pending) >= self.chunk:
                self._send_paced(bytes(pending))
                pending.clear()
                if progress:
                    progress(count, self.sent - start)
            if self._inbox.startswith(b"ERR"):
                break
        self._send_paced(bytes(pending) + b"%\n")
        reply = self._reply()
        if not reply.startswith("OK DRIP"):
            raise TransferError("protocol", f"unexpected answer {reply!r}", sent=self.sent)
        return DripResult(count, self.sent - start, self.xoff_count)

    def punch(self, number: int) -> str:
        """Upload program `number` from the machine's memory (in the machine's stored form)."""
        self._raw_send(f"PUNCH O{number:04d}\n".encode())
        return self._receive_tape()

    def directory(self) -> list[tuple[int, int, str]]:
        self._raw_send(b"DIR\n")
        entries = []
        while True:
            line = self._reply()
            if line.startswith("OK"):
                return entries
            number, size, sha = line.split()
            entries.append((int(number[1:]), int(size), sha))

    def delete(self, number: int) -> None:
        self._raw_send(f"DELETE O{number:04d}\n".encode())
        self._reply()

    def listen(
        self,
        answer: Callable[[int], str | None],
        *,
        until: Callable[[], bool],
        poll_s: float = 0.05,
    ) -> int:
        """Serve the machine's remote requests until `until()` is true; returns how many.

        `answer(number)` gives the text to load (the released revision) or None to refuse.
        """
        self._raw_send(b"LISTEN\n")
        if self._reply() != "OK LISTEN":
            raise TransferError("protocol", "machine did not enter LISTEN")
        served = 0
        while not until():
            self._poll_flow(poll_s)
            if not self._tapes:
                continue
            request = self._receive_tape()
            m = _REQUEST.search(request)
            if not m:
                continue
            text = answer(int(m.group(1)))
            if text is not None:
                self.send_program(text)
                served += 1
        return served


def iter_blocks(chunks: Iterable[str]) -> Iterator[str]:
    """Blocks from text arriving in chunks of any size (database pages, file reads)."""
    tail = ""
    for chunk in chunks:
        tail += chunk
        *lines, tail = tail.split("\n")
        yield from lines
    if tail:
        yield tail
