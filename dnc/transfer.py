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

from cnc.faces.tape import PUNCH_ON, XOFF, XON, TapeDecoder, encode_program
from dnc.errors import DncError

_FLOW_BYTE = re.compile(rb"[\x11-\x14]")
# Parity as whole-buffer translations: the host handles every byte of every transfer, so no
# per-byte Python loop.
_STRIP = bytes(i & 0x7F for i in range(256))
_EVEN = bytes((i | 0x80) if bin(i).count("1") % 2 else i for i in range(128)) + bytes(128)
# Little in flight, like a serial line, so XOFF takes effect within a few blocks (in a
# drip-feed the machine counts what still arrives after its XOFF as an overrun). The
# machine's DNC port reads with a 4 KB receive buffer, smaller than a loopback segment:
# writes larger than that window leave TCP waiting on its persist timer (measured: 100 KB
# loads of 0.4 ms turned into 0.2-1.7 s stalls with 16-64 KB writes, and 4 KB writes still
# stalled), so writes stay at half the window: 2 KB sends a program with 40 % less CPU
# than 1 KB, and twenty transfers at once ran without a stall.
CHUNK = 2048
WINDOW = 4096
LINE_ALARMS = frozenset({2001, 2004, 2007, 2010})  # parity, cut off, time-out, overrun
_REQUEST = re.compile(r"/REQ\s*(\d+)", re.I)


class TransferError(DncError):
    """A transfer to or from a machine that failed (a DncError: the package's one root; the
    REST API answers it as a 502 `transfer-failed` problem, web_api/problems.py).

    kind: connect | refused | cut_off | xoff_timeout | timeout | protocol | verify | read
    (the host could not read the revision's text from its database) | encode (the text has
    a character the 7-bit tape cannot carry) | dependency (a program it calls has no released
    revision: nothing sent) | post (an APT/CL revision the post-processor refuses for the
    machine) | check (G-code naming an axis the machine does not have: nothing sent) |
    internal (an unexpected error in an attempt)."""

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
        # a failed read of the text on the host (a busy database) may pass on the next attempt
        return self.kind in ("connect", "cut_off", "timeout", "xoff_timeout", "verify", "read")


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
    return stored_form(encode_program(text))


def stored_form(tape: bytes) -> str:
    """A punched tape (parity already stripped) decoded to the form machines store."""
    lines: list[str] = []
    for ev in TapeDecoder().feed_runs(tape):
        if ev.kind == "lines":
            lines += ev.lines
        elif ev.kind == "line":
            lines.append(ev.text)
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
        chunk: int = CHUNK,
        secret: str | None = None,
    ) -> None:
        self.host, self.port, self.parity = host, port, parity
        self._secret = secret  # the machine's `ports.secret`: sent as `AUTH <secret>` first
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
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, WINDOW)
        if self._secret is not None:
            try:
                self._raw_send(f"AUTH {self._secret}\n".encode("ascii"))
                self._reply()  # ERR 2011 raises TransferError("refused", alarm=2011)
            except BaseException:
                self._sock.close()
                self._sock = None
                raise
            self.sent = 0  # the handshake is not tape
        return self

    def __exit__(self, *exc: object) -> None:
        if self._sock is not None:
            with contextlib.suppress(OSError, TransferError):
                self._raw_send(b"QUIT\n")
            self._sock.close()
            self._sock = None

    def _encode(self, data: bytes) -> bytes:
        if not self.parity:
            return data
        if not data.isascii():
            raise TransferError("protocol", "tape text must be 7-bit ASCII to add parity")
        return data.translate(_EVEN)

    def _decode(self, data: bytes) -> bytes:
        return data.translate(_STRIP) if self.parity else data

    def _raw_send(self, data: bytes) -> None:
        try:
            self._sock.sendall(self._encode(data))
        except OSError as exc:
            self._lost(exc)
        self.sent += len(data)

    def _lost(self, exc: OSError) -> None:
        self._raise_machine_reason()
        raise TransferError(
            "cut_off", f"connection lost after {self.sent} bytes: {exc}", sent=self.sent
        ) from exc

    def _raise_machine_reason(self) -> None:
        """When the line drops, the machine's last words (`ERR <alarm> ...`) say why."""
        with contextlib.suppress(OSError):
            while select.select([self._sock], [], [], 0.2)[0]:
                data = self._sock.recv(4096)
                if not data:
                    break
                self._inbox += self._decode(data)
        start = self._inbox.find(b"ERR ")
        if start >= 0 and b"\n" in self._inbox[start:]:
            self._inbox = self._inbox[start:]
            self._reply()  # raises the refusal with its alarm number

    def _poll_flow(self, wait: float) -> None:
        """Read what the machine sent; track XON/XOFF; keep everything else for replies."""
        readable, _, _ = select.select([self._sock], [], [], wait)
        if readable:
            self._receive()

    def _receive(self) -> None:
        try:
            data = self._sock.recv(65536)
        except OSError as exc:
            raise TransferError("cut_off", f"connection lost: {exc}", sent=self.sent) from exc
        if not data:
            self._raise_machine_reason()
            raise TransferError(
                "cut_off",
                f"the machine closed the connection after {self.sent} bytes",
                sent=self.sent,
            )
        plain = self._decode(data)
        # Runs between control characters go where the last control sent them, whole: a
        # punched tape arrives as DC2, 100 KB of text, DC4 and is never walked byte by byte.
        start = 0
        for match in _FLOW_BYTE.finditer(plain):
            self._keep(plain[start : match.start()])
            start = match.end()
            b = plain[match.start()]
            if b == XOFF:
                self._stopped = True
                self.xoff_count += 1
            elif b == XON:
                self._stopped = False
            elif b == PUNCH_ON:
                self._punching = True
                self._tape.clear()
            elif self._punching:  # PUNCH_OFF
                self._punching = False
                self._tapes.append(bytes(self._tape))
        self._keep(plain[start:])

    def _keep(self, data: bytes) -> None:
        if data:
            if self._punching:
                self._tape += data
            else:
                self._inbox += data

    def _send_paced(self, data: bytes) -> None:
        """Send `data`, never writing while the machine holds XOFF.

        Each write hands the kernel at most `chunk` bytes and only what it takes at once
        (socket.send, not sendall), then the line is checked for XOFF again: what can be in
        flight when XOFF arrives is bounded by the socket buffers, as on a serial line by the
        UART FIFO. Parity is added to the whole buffer once, not per chunk.
        """
        wire = memoryview(self._encode(data))
        i, stall = 0, time.monotonic() + self.timeout_s
        while i < len(wire):
            try:
                readable, writable, _ = select.select([self._sock], [self._sock], [], 0.05)
            except OSError as exc:
                self._lost(exc)
            if readable:
                self._receive()
            if self._stopped:
                self._hold()
                stall = time.monotonic() + self.timeout_s
            if b"ERR" in self._inbox:
                return  # the machine gave up; its reply explains why
            if self._stopped or not writable:
                if time.monotonic() > stall:
                    raise TransferError(
                        "timeout",
                        f"the machine took nothing for {self.timeout_s:g} s "
                        f"after {self.sent} bytes",
                        sent=self.sent,
                    )
                continue
            try:
                n = self._sock.send(wire[i : i + self.chunk])
            except OSError as exc:
                self._lost(exc)
            i += n
            self.sent += n
            stall = time.monotonic() + self.timeout_s

    def _hold(self) -> None:
        """Stopped by XOFF: send nothing until XON, the machine's ERR, or the XOFF time-out."""
        deadline = time.monotonic() + self.xoff_timeout_s
        while self._stopped:
            if b"\n" in self._inbox and self._inbox.startswith(b"ERR"):
                return
            if time.monotonic() > deadline:
                raise TransferError(
                    "xoff_timeout",
                    f"the machine held XOFF for {self.xoff_timeout_s:g} s after {self.sent} bytes",
                    sent=self.sent,
                )
            self._poll_flow(0.05)

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
        return stored_form(self._receive_raw_tape())

    def _receive_raw_tape(self) -> bytes:
        """The next punched tape (DC2 ... DC4) as the bytes between the two controls."""
        deadline = time.monotonic() + self.timeout_s
        while not self._tapes:
            if self._inbox.startswith(b"ERR") and b"\n" in self._inbox:
                self._reply()  # raises with the machine's reason
            if time.monotonic() > deadline:
                raise TransferError("timeout", "punch output did not arrive", sent=self.sent)
            self._poll_flow(0.05)
        return self._tapes.pop(0)

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

    def punch_sha256(self, number: int, *, expected: str | None = None) -> str:
        """sha256 of program `number` as the machine holds it (read back by punching).

        A machine punches its stored form unchanged, so when the raw tape hashes to
        `expected` it is that text byte for byte and is not decoded; otherwise it is decoded
        to stored form, which is what the answer is about.
        """
        self._raw_send(f"PUNCH O{number:04d}\n".encode())
        raw = self._receive_raw_tape()
        digest = hashlib.sha256(raw).hexdigest()
        if expected is not None and digest == expected:
            return digest
        return sha256_text(stored_form(raw))

    def directory(self) -> list[tuple[int, int, str]]:
        self._raw_send(b"DIR\n")
        entries = []
        while True:
            line = self._reply()
            if line.startswith("OK"):
                return entries
            number, size, sha = line.split()
            entries.append((int(number[1:]), int(size), sha))

    def machine_data(self, what: str, doc: object | None = None) -> object:
        """The machine's tool table (`what` = "tools") or work offsets ("offsets") as JSON
        data; with `doc`, replace them first (TOOLS PUT / OFFSETS PUT). A refusal (in cycle,
        a bad value: alarm 2012 with the JSON pointer) is a TransferError "refused"."""
        command = what.upper()
        if command not in ("TOOLS", "OFFSETS"):
            raise ValueError(f"machine data is tools or offsets, not {what!r}")
        return self._json_exchange(command, doc)

    def host_data(self, doc: dict) -> dict:
        """HOST PUT: what the host knows of the machine (dispatched revisions, jobs) for its
        OPC UA face; returns the machine's answer (the face's commands to audit). A bad
        document is a TransferError "refused" with alarm 2012 and the JSON pointer."""
        return self._json_exchange("HOST", doc)

    def _json_exchange(self, command: str, doc: object | None) -> object:
        """`COMMAND` (read) or `COMMAND PUT <n>` + JSON body; the answer is `DATA <json>`
        then `OK ...`."""
        import json

        if doc is None:
            self._raw_send(f"{command}\n".encode())
        else:
            body = json.dumps(doc, separators=(",", ":"), ensure_ascii=True).encode("ascii")
            self._raw_send(f"{command} PUT {len(body)}\n".encode() + body)
        line = self._reply()
        if not line.startswith("DATA "):
            raise TransferError("protocol", f"expected DATA, got {line[:60]!r}", sent=self.sent)
        data = json.loads(line[5:])
        self._reply()  # OK <COMMAND> ...
        return data

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
