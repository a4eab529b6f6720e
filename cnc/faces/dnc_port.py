"""The machine's DNC port: ISO tape over TCP with parity, XON/XOFF and a small command set.

The protocol (docs/dnc_port.md) is modelled on a Fanuc serial port with remote buffer,
carried over TCP the way a serial device server carries it. Each operation begins with a
command line; a connection may run several operations in turn:

    READ [Onnnn]    receive a tape into program memory          -> OK Onnnn <bytes> <sha256>
    DRIP            execute while receiving (BTR), XON/XOFF paced -> OK DRIP <blocks>
    PUNCH Onnnn     send a program: DC2, tape, DC4
    DIR             list program memory                           -> lines, OK <count>
    DELETE Onnnn    remove a program                               -> OK
    LISTEN          stay connected for remote requests: DC2 %\\nO9999\\n(/REQ nnnn)\\n% DC4
    TOOLS | OFFSETS read the tool table / work offsets  -> DATA <json>, OK TOOLS <count>
    TOOLS PUT <n> | OFFSETS PUT <n>   then <n> bytes of JSON: replace them -> OK ...
    HOST PUT <n>    then <n> bytes of JSON: what only the cell's host knows (dispatched
                    revisions, jobs) for the OPC UA face -> DATA <json: the face's
                    commands to audit>, OK HOST <jobs>
    QUIT            close

A connection that starts straight with tape (`%`, NUL leader, blank lines) is a READ, so a
plain DNC package sending through a serial-to-TCP bridge works unchanged. A port given a
shared `secret` takes nothing before `AUTH <secret>` (-> OK AUTH) as the connection's first
line; anything else answers `ERR 2011 ...` and closes. Errors answer
`ERR <alarm> <text>`; the ones the seed calls alarms (parity, transfer cut off, memory full,
overrun) also raise the machine alarm through `on_alarm`. A program load (READ) cut off or
abandoned before its closing `%` (a host killed mid-transfer, a client that hangs up) only
discards the partial tape: memory keeps what it had, and the machine is told through
`on_warning`, not an alarm that would take it out of the cell until a reset.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import logging
import re
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from cnc.errors import CncError
from cnc.faces.drip import DripBuffer
from cnc.faces.tape import (
    CR,
    LF,
    NUL,
    PERCENT,
    PUNCH_OFF,
    PUNCH_ON,
    XOFF,
    XON,
    TapeDecoder,
    add_parity,
    encode_program,
    parity_error_at,
    strip_parity,
)
from cnc.faces.tcp_face import TcpFace, secret_matches
from cnc.program_memory import MemoryFull, ProgramMemory, program_number_error

log = logging.getLogger(__name__)

# DNC alarms (number, text). The machine's alarm list shows them with source "DNC".
ALARM_PARITY = 2001
ALARM_MEMORY_FULL = 2002
ALARM_NOT_IN_MEMORY = 2003
ALARM_CUT_OFF = 2004
ALARM_NO_NUMBER = 2005
ALARM_UNKNOWN_COMMAND = 2006
ALARM_TIMEOUT = 2007
ALARM_BLOCK_TOO_LONG = 2008
ALARM_REFUSED = 2009
ALARM_OVERRUN = 2010
ALARM_AUTH = 2011  # no or a wrong AUTH line on a port with a shared secret
ALARM_BAD_DATA = 2012  # machine data refused: the reply names the JSON pointer and why
MACHINE_DATA_MAX = 1 << 20  # bytes of one TOOLS/OFFSETS PUT body
ALARM_EIGHT_BIT = 2013  # a byte with bit 7 set on a port without parity: not tape code
FATAL_TO_CONNECTION = {
    ALARM_PARITY,
    ALARM_CUT_OFF,
    ALARM_MEMORY_FULL,
    ALARM_OVERRUN,
    ALARM_TIMEOUT,
    ALARM_BLOCK_TOO_LONG,
    ALARM_UNKNOWN_COMMAND,
    ALARM_AUTH,
    ALARM_EIGHT_BIT,
}
RAISES_ALARM = {ALARM_PARITY, ALARM_CUT_OFF, ALARM_MEMORY_FULL, ALARM_OVERRUN, ALARM_TIMEOUT}

REMOTE_REQUEST_PROGRAM = 9999
# Any count of digits is read, so that O123456789 is refused as out of range (1..99999999)
# rather than read as "no program number".
_O_WORD = re.compile(r"^\s*(?:N\d+\s*)?[O:]\s*(\d+)", re.I)
_NUMBER_ARG = re.compile(r"^[O:]?(\d+)$", re.I)
_COMMAND_MAX = 80
LINE_BUFFER_BYTES = 4096
# After XOFF, bytes still arriving within this time were on the wire before the sender could
# see the XOFF; bytes after it mean the sender ignores flow control.
XOFF_GRACE_S = 0.5
# A sender that honours XOFF has at most the socket buffers in flight when it sees XOFF: about
# 1.6 KB measured (1 KB writes) on an idle machine, up to ~24 KB (both kernels' buffers and the reader's) on
# a loaded one. More than all of that together means it does not honour XOFF.
IN_FLIGHT_MAX = 64 * 1024
# Punch output is written a receive window at a time, the flow checked between writes: the
# host reads whatever arrives, so smaller writes only cost wake-ups at both ends.
PUNCH_CHUNK = LINE_BUFFER_BYTES

Policy = Callable[[str, int | None], str | None]
"""(operation, program number) -> None to allow, or the reason the machine refuses it."""
MachineDataAccess = Callable[[str, object | None], object]
"""(what: "tools" | "offsets", None to read or a document to write) -> the data (read) or
the stored data (write); raises DncAlarm with the machine's refusal or ALARM_BAD_DATA."""
HostDataAccess = Callable[[object], dict]
"""(the host's document) -> what the machine gives back (the OPC UA face's commands since
the last exchange); raises DncAlarm ALARM_BAD_DATA naming the JSON pointer."""


def program_number(lines: list[str]) -> int | None:
    """The O number of the first block that has one (before any motion)."""
    for line in lines[:5]:
        m = _O_WORD.match(line)
        if m:
            return int(m.group(1))
    return None


def stored_text(lines: list[str]) -> str:
    """The form a received program is kept in: `%`, its blocks, `%`, LF line ends."""
    return "%\n" + "\n".join(lines) + ("\n%\n" if lines else "%\n")


def sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class DncAlarm(CncError):
    """The port's refusal: answered `ERR <alarm> <text>` (the host's refusals are
    dnc.errors.DncError; this is the machine's side of the line)."""

    def __init__(self, alarm: int, text: str, *, warning: bool = False) -> None:
        super().__init__(f"{alarm} {text}")
        self.alarm, self.text, self.warning = alarm, text, warning


@dataclass
class DncPortStats:
    programs_received: int = 0
    programs_punched: int = 0
    drip_blocks: int = 0
    xoff_sent: int = 0
    auth_refused: int = 0
    errors: dict[int, int] = field(default_factory=dict)


class DncPort(TcpFace):
    _what = "DNC port"

    def __init__(
        self,
        memory: ProgramMemory,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        parity: bool = False,
        idle_timeout_s: float = 30.0,
        drip: Callable[[], DripBuffer] | None = None,
        on_alarm: Callable[[int, str], None] | None = None,
        on_warning: Callable[[int, str], None] | None = None,
        policy: Policy | None = None,
        machine_data: MachineDataAccess | None = None,
        host_data: HostDataAccess | None = None,
        xoff_slack_bytes: int = 256,
        max_block: int = 4096,
        secret: str | None = None,
    ) -> None:
        super().__init__()
        self.memory = memory
        self._secret = secret
        self.host, self.port, self.parity = host, port, parity
        self.idle_timeout_s = idle_timeout_s
        self._drip = drip
        self._on_alarm = on_alarm or (lambda n, t: None)
        self._on_warning = on_warning or (lambda n, t: log.warning("DNC %s: %s", n, t))
        self._policy = policy or (lambda op, n: None)
        self._machine_data = machine_data
        self._host_data = host_data
        self.xoff_slack = xoff_slack_bytes
        self.max_block = max_block
        self.stats = DncPortStats()
        self._listeners: set[asyncio.Queue[str]] = set()
        self._loop: asyncio.AbstractEventLoop | None = None

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        # Small buffers make the TCP stream behave like the serial line it stands for: a
        # sender cannot run more than a few kilobytes ahead of what the machine has read.
        await self._serve(self.host, self.port, limit=LINE_BUFFER_BYTES)

    def remote_request(self, number: int) -> int:
        """Ask the host for program `number` (the operator's remote request). Thread-safe.

        Returns how many listening host connections the request went to; 0 means no host is
        listening, which the machine reports to the operator.
        """
        text = f"O{REMOTE_REQUEST_PROGRAM}\n(/REQ {number})"
        if self._loop is None:
            return 0
        for queue in list(self._listeners):
            self._loop.call_soon_threadsafe(queue.put_nowait, text)
        return len(self._listeners)

    # --------------------------------------------------------------------------- sessions

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sock = writer.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, LINE_BUFFER_BYTES)
        conn = _Conn(reader, writer, self.parity)
        try:
            if self._secret is not None and not await self._authenticate(conn):
                return
            while True:
                try:
                    command, arg, pushback = await conn.read_command(self.idle_timeout_s)
                    if command is None or command == "QUIT":
                        return
                    await self._dispatch(conn, command, arg, pushback)
                except TimeoutError:  # idle connection
                    return
                except DncAlarm as exc:
                    self._error(exc)
                    await conn.reply(f"ERR {exc.alarm} {exc.text}")
                    if exc.alarm in FATAL_TO_CONNECTION:
                        # The stream is mid-tape: resynchronising is the host's job.
                        await conn.linger()
                        return
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        except asyncio.CancelledError:
            # stop() ends the open sessions: a quiet end. Python 3.11's start_server asks a
            # finished session task for its exception(), which raises for a cancelled task
            # and logs "Exception in callback" at every stop that found a session open.
            return
        except Exception:  # a bug must cost one connection, never the port
            log.exception("DNC session failed")
        finally:
            with contextlib.suppress(Exception):
                writer.close()

    async def _authenticate(self, conn: _Conn) -> bool:
        """The connection's first line must be `AUTH <secret>`: True when it is, else the
        refusal is answered (no machine alarm: a stray client must not stop the machine)
        and the connection closed."""
        try:
            command, arg, _ = await conn.read_command(self.idle_timeout_s)
        except TimeoutError:
            return False
        except DncAlarm as exc:
            command, arg = "", exc.text
        if command is None:
            return False
        if command == "AUTH" and secret_matches(arg, self._secret or ""):
            await conn.reply("OK AUTH")
            return True
        self.stats.auth_refused += 1
        self.stats.errors[ALARM_AUTH] = self.stats.errors.get(ALARM_AUTH, 0) + 1
        if command == "AUTH":
            why = "authentication failed: wrong secret"
        else:
            what = f"{command} refused" if command else arg
            why = f"authentication required: the first line must be AUTH <secret> ({what})"
        await conn.reply(f"ERR {ALARM_AUTH} {why}")
        await conn.linger()
        return False

    async def _dispatch(self, conn: _Conn, command: str, arg: str, pushback: bytes) -> None:
        if command == "READ":
            await self._read(conn, _number(arg) if arg else None, pushback)
        elif command == "DRIP":
            await self._drip_feed(conn, pushback)
        elif command == "PUNCH":
            await self._punch(conn, _required_number(arg))
        elif command == "DIR":
            entries = self.memory.directory()
            for e in entries:
                await conn.reply(f"O{e.number:04d} {e.size} {e.sha256}")
            await conn.reply(f"OK {len(entries)} programs, {self.memory.free} bytes free")
        elif command == "DELETE":
            number = _required_number(arg)
            self._allow("DELETE", number)
            if number not in self.memory:
                raise DncAlarm(ALARM_NOT_IN_MEMORY, f"program O{number:04d} not in memory")
            self.memory.delete(number)
            await conn.reply(f"OK O{number:04d} deleted")
        elif command == "LISTEN":
            await self._listen(conn)
        elif command == "AUTH":
            # again after the handshake, or on a port without a secret: harmless, answered
            # so a host that always authenticates works with either
            if self._secret is not None and not secret_matches(arg, self._secret):
                raise DncAlarm(ALARM_AUTH, "authentication failed: wrong secret")
            await conn.reply("OK AUTH" if self._secret is not None else "OK AUTH (no secret)")
        elif command in ("TOOLS", "OFFSETS"):
            await self._data(conn, command, arg)
        elif command == "HOST":
            await self._host(conn, arg)
        else:
            raise DncAlarm(ALARM_UNKNOWN_COMMAND, f"unknown command {command!r}")

    async def _data(self, conn: _Conn, command: str, arg: str) -> None:
        """TOOLS / OFFSETS [PUT <bytes>]: the machine data as JSON (cnc.machine_data's
        tools_dict / offsets_dict form), like a control's offset screen read or written
        from outside (FOCAS-style); a write is all or nothing and refused in cycle."""
        what = command.lower()
        word, _, size_text = arg.partition(" ")
        body = None
        if word.upper() == "PUT":
            body = await self._json_body(conn, command, size_text)
        elif arg:
            raise DncAlarm(ALARM_UNKNOWN_COMMAND, f"{command} takes no argument but PUT <n>")
        if self._machine_data is None:
            raise DncAlarm(ALARM_REFUSED, f"{command} refused: this port has no machine data")
        data = self._machine_data(what, body)
        await conn.reply(f"DATA {_json(data)}")
        count = len(data) if what == "tools" else len(data.get("work_offsets", {}))
        await conn.reply(f"OK {command} {count}{' stored' if body is not None else ''}")

    async def _host(self, conn: _Conn, arg: str) -> None:
        """HOST PUT <bytes>: the host's knowledge for the OPC UA face (docs/opcua.md); the
        answer carries what the face's clients did, for the host's audit log."""
        word, _, size_text = arg.partition(" ")
        if word.upper() != "PUT":
            raise DncAlarm(ALARM_UNKNOWN_COMMAND, "HOST takes PUT <n>")
        body = await self._json_body(conn, "HOST", size_text)
        if self._host_data is None:
            raise DncAlarm(ALARM_REFUSED, "HOST refused: this machine serves no OPC UA face")
        answer = self._host_data(body)
        await conn.reply(f"DATA {_json(answer)}")
        jobs = body.get("jobs", []) if isinstance(body, dict) else []
        await conn.reply(f"OK HOST {len(jobs)}")

    async def _json_body(self, conn: _Conn, command: str, size_text: str) -> object:
        if not size_text.strip().isdigit():
            raise DncAlarm(ALARM_UNKNOWN_COMMAND, f"{command} PUT needs the body size")
        size = int(size_text)
        if size > MACHINE_DATA_MAX:
            raise DncAlarm(ALARM_UNKNOWN_COMMAND, f"{command} PUT body over {MACHINE_DATA_MAX}")
        raw = await conn.read_exact(size, self.idle_timeout_s)
        try:
            return json.loads(raw.decode("ascii"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise DncAlarm(ALARM_BAD_DATA, f"body is not ASCII JSON: {exc}") from None

    def _allow(self, op: str, number: int | None) -> None:
        reason = self._policy(op, number)
        if reason:
            raise DncAlarm(ALARM_REFUSED, f"{op} refused: {reason}")

    def _error(self, exc: DncAlarm) -> None:
        self.stats.errors[exc.alarm] = self.stats.errors.get(exc.alarm, 0) + 1
        if exc.warning:
            self._on_warning(exc.alarm, exc.text)
        elif exc.alarm in RAISES_ALARM:
            self._on_alarm(exc.alarm, exc.text)

    async def _receive_tape(self, conn: _Conn, pushback: bytes, on_block, on_blocks=None) -> None:
        """Decode one tape from the connection, handing each block to `on_block`, or each
        run of blocks to `on_blocks` when given (a list per read instead of a call per block).
        """
        decoder = TapeDecoder(parity=self.parity, max_block=self.max_block)
        data = pushback
        while True:
            for ev in decoder.feed_runs(data):
                if ev.kind == "lines":
                    if on_blocks is not None:
                        on_blocks(ev.lines)
                        continue
                    for text in ev.lines:
                        pending = on_block(text)  # a coroutine only when it may have to wait
                        if pending is not None:
                            await pending
                elif ev.kind == "line":
                    pending = on_block(ev.text)
                    if pending is not None:
                        await pending
                elif ev.kind == "parity_error":
                    raise DncAlarm(
                        ALARM_PARITY, f"parity error at byte {ev.offset}; program rejected"
                    )
                elif ev.kind == "eight_bit":
                    raise DncAlarm(
                        ALARM_EIGHT_BIT,
                        f"8-bit byte 0x{ev.code:02X} at byte {ev.offset} (line {ev.line}) on a "
                        "7-bit port without parity; program rejected",
                    )
                elif ev.kind == "overlong":
                    raise DncAlarm(
                        ALARM_BLOCK_TOO_LONG,
                        f"block longer than {self.max_block} characters at byte {ev.offset}",
                    )
                elif ev.kind == "end":
                    conn.unread(data[ev.offset - (decoder.offset - len(data)) + 1 :])
                    return
            try:
                data = await conn.read_raw(self.idle_timeout_s)
            except TimeoutError:
                raise DncAlarm(
                    ALARM_TIMEOUT, f"no data for {self.idle_timeout_s:g} s; transfer abandoned"
                ) from None
            except ConnectionError:  # reset by the sender: cut off as much as a hang-up
                data = b""
            if not data:
                what = "closing %" if decoder.started else "tape start %"
                raise DncAlarm(
                    ALARM_CUT_OFF, f"transfer cut off before the {what} at byte {decoder.offset}"
                )

    async def _read(self, conn: _Conn, number: int | None, pushback: bytes) -> None:
        lines: list[str] = []
        size = 4  # the two % lines

        def fits() -> None:
            if size > self.memory.capacity:
                raise DncAlarm(
                    ALARM_MEMORY_FULL,
                    f"program exceeds the program memory of {self.memory.capacity} bytes; "
                    "use drip-feed (DRIP) for programs larger than memory",
                )

        def keep(block: str) -> None:
            nonlocal size
            size += len(block) + 1
            fits()
            lines.append(block)

        def keep_all(blocks: list[str]) -> None:
            nonlocal size
            size += sum(map(len, blocks)) + len(blocks)
            fits()
            lines.extend(blocks)

        try:
            await self._receive_tape(conn, pushback, keep, keep_all)
        except DncAlarm as exc:
            if exc.alarm not in (ALARM_CUT_OFF, ALARM_TIMEOUT):
                raise
            # Nothing of a load is stored before its closing %, so memory is as it was and
            # the machine is fit to run: a message, not an alarm that needs a reset.
            raise DncAlarm(
                exc.alarm, f"{exc.text}; program discarded, memory unchanged", warning=True
            ) from None
        number = number or program_number(lines)
        if number is None:
            raise DncAlarm(ALARM_NO_NUMBER, "no program number: the first block needs an O word")
        why = program_number_error(number)
        if why is not None:
            raise DncAlarm(ALARM_NO_NUMBER, why)
        self._allow("READ", number)
        text = stored_text(lines)
        try:
            entry = self.memory.store(number, text)
        except MemoryFull as exc:
            raise DncAlarm(ALARM_MEMORY_FULL, str(exc)) from None
        self.stats.programs_received += 1
        await conn.reply(f"OK O{number:04d} {entry.size} {entry.sha256}")

    async def _drip_feed(self, conn: _Conn, pushback: bytes) -> None:
        if self._drip is None:
            raise DncAlarm(ALARM_REFUSED, "DRIP refused: this machine has no drip-feed (BTR) input")
        self._allow("DRIP", None)
        buffer = self._drip()
        count = 0

        async def feed(block: str) -> None:
            nonlocal count
            while buffer.fill and buffer.fill + len(block) + 1 > buffer.high:
                await conn.send_control(XOFF)
                self.stats.xoff_sent += 1
                await conn.hold(buffer, self.xoff_slack, self.idle_timeout_s)
                await conn.send_control(XON)
            try:
                buffer.put(block)
            except OverflowError:
                raise DncAlarm(
                    ALARM_BLOCK_TOO_LONG,
                    f"block of {len(block)} characters exceeds the drip-feed buffer",
                ) from None
            count += 1

        try:
            await self._receive_tape(conn, pushback, feed)
        except DncAlarm as exc:
            buffer.abort(exc.text)
            raise
        buffer.end()
        self.stats.drip_blocks += count
        await conn.reply(f"OK DRIP {count} blocks")

    async def _punch(self, conn: _Conn, number: int) -> None:
        self._allow("PUNCH", number)
        try:
            text = self.memory.get(number)
        except KeyError:
            raise DncAlarm(ALARM_NOT_IN_MEMORY, f"program O{number:04d} not in memory") from None
        if not text.isascii():  # loaded by another way than the tape: say so, do not drop
            at = next(i for i, ch in enumerate(text) if ord(ch) > 0x7F)
            raise DncAlarm(
                ALARM_EIGHT_BIT,
                f"program O{number:04d} holds {text[at]!r} (U+{ord(text[at]):04X}) on line "
                f"{text.count(chr(10), 0, at) + 1}, outside the 7-bit tape code; cannot punch",
            )
        await conn.send_tape(text)
        self.stats.programs_punched += 1

    async def _listen(self, conn: _Conn) -> None:
        queue: asyncio.Queue[str] = asyncio.Queue()
        self._listeners.add(queue)
        command_task: asyncio.Future | None = None
        request_task: asyncio.Future | None = None
        try:
            await conn.reply("OK LISTEN")
            while True:
                if command_task is None:
                    command_task = asyncio.ensure_future(conn.read_command(None))
                request_task = asyncio.ensure_future(queue.get())
                done, _ = await asyncio.wait(
                    {command_task, request_task}, return_when=asyncio.FIRST_COMPLETED
                )
                if request_task in done:
                    # The request program is a few bytes: no flow control, and no second
                    # reader racing the pending command read.
                    await conn.send_tape(request_task.result(), flow_control=False)
                    continue
                request_task.cancel()
                command, arg, pushback = command_task.result()
                command_task = None
                if command is None or command == "QUIT":
                    return
                try:
                    await self._dispatch(conn, command, arg, pushback)
                except DncAlarm as exc:
                    self._error(exc)
                    await conn.reply(f"ERR {exc.alarm} {exc.text}")
                    if exc.alarm in FATAL_TO_CONNECTION:
                        return
        finally:
            self._listeners.discard(queue)
            for pending in (command_task, request_task):
                if pending is not None and not pending.done():
                    pending.cancel()
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await pending


class _Conn:
    """Byte-level I/O of one connection: parity, pushback, XOFF from the peer."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, parity: bool):
        self.reader, self.writer, self.parity = reader, writer, parity
        self._pending = b""

    def unread(self, data: bytes) -> None:
        self._pending = data + self._pending

    async def read_raw(self, timeout: float | None) -> bytes:
        if self._pending:
            data, self._pending = self._pending, b""
            return data
        # asyncio.timeout, not wait_for: wait_for makes a task of every read.
        async with asyncio.timeout(timeout):
            return await self.reader.read(4096)

    async def read_exact(self, size: int, timeout: float | None) -> bytes:
        """`size` bytes of a command's body (parity stripped)."""
        buf = b""
        while len(buf) < size:
            try:
                data = await self.read_raw(timeout)
            except TimeoutError:
                raise DncAlarm(
                    ALARM_TIMEOUT, f"no data for {timeout:g} s after {len(buf)} of {size} bytes"
                ) from None
            if not data:
                raise DncAlarm(ALARM_CUT_OFF, f"body cut off after {len(buf)} of {size} bytes")
            buf += data
        self.unread(buf[size:])
        body = buf[:size]
        if self.parity:
            if parity_error_at(body) is not None:
                raise DncAlarm(ALARM_PARITY, "parity error in the body")
            body = strip_parity(body)
        return body

    async def read_command(self, timeout: float | None) -> tuple[str | None, str, bytes]:
        """The next command, or ("READ", "", tape bytes) when the peer starts with tape."""
        buf = b""
        while True:
            data = await self.read_raw(timeout)
            if not data:
                return None, "", b""
            buf += data
            plain = strip_parity(buf) if self.parity else buf
            lead = plain.lstrip(bytes([NUL, LF, CR, XON, XOFF]))
            if lead[:1] == bytes([PERCENT]):
                return "READ", "", buf
            nl = plain.find(b"\n", len(plain) - len(lead))
            if nl < 0:
                if len(lead) > _COMMAND_MAX:
                    raise DncAlarm(ALARM_UNKNOWN_COMMAND, "command line too long")
                continue
            if self.parity and parity_error_at(buf[: nl + 1]) is not None:
                raise DncAlarm(ALARM_PARITY, "parity error in command line")
            line = plain[len(plain) - len(lead) : nl].decode("ascii", "replace").strip()
            self.unread(buf[nl + 1 :])
            if not line:
                buf = b""
                continue
            word, _, arg = line.partition(" ")
            return word.upper(), arg.strip(), b""

    async def reply(self, text: str) -> None:
        data = (text + "\n").encode("ascii", "replace")
        self.writer.write(add_parity(data) if self.parity else data)
        await self.writer.drain()

    async def linger(self, limit_s: float = 1.0) -> None:
        """Half-close, then discard what the peer still sends until it closes too.

        Closing a socket with unread data makes TCP send a reset, and a reset can destroy
        the ERR reply in flight: the host would see "connection reset" instead of the
        alarm that explains it.
        """
        with contextlib.suppress(Exception):
            self.writer.write_eof()
            deadline = time.monotonic() + limit_s
            while time.monotonic() < deadline:
                if not await asyncio.wait_for(self.reader.read(65536), deadline - time.monotonic()):
                    break

    async def send_control(self, code: int) -> None:
        data = bytes([code])
        self.writer.write(add_parity(data) if self.parity else data)
        await self.writer.drain()

    async def hold(self, buffer: DripBuffer, slack: int, timeout: float) -> None:
        """After XOFF: wait until the NC has drained the buffer to its low-water mark.

        The line keeps being read, as a UART would. What arrives within XOFF_GRACE_S was
        already on its way; more than `slack` bytes after that, or more than IN_FLIGHT_MAX
        bytes in all, is an overrun (Fanuc's "buffer overflow" alarm).
        """
        extra = bytearray()
        late = 0
        start = time.monotonic()
        while not buffer.below_low_water():
            if buffer.aborted:
                raise DncAlarm(ALARM_CUT_OFF, f"drip-feed ended by the machine: {buffer.aborted}")
            try:
                async with asyncio.timeout(0.002):
                    data = await self.reader.read(4096)
            except TimeoutError:
                if time.monotonic() - start > timeout:
                    raise DncAlarm(ALARM_TIMEOUT, "the NC took no block for too long") from None
                continue
            if not data:
                break
            extra += data
            if time.monotonic() - start > XOFF_GRACE_S:
                late += len(data)
            if late > slack or len(extra) > IN_FLIGHT_MAX:
                raise DncAlarm(
                    ALARM_OVERRUN,
                    f"overrun: {late or len(extra)} bytes received after XOFF "
                    "(the sender ignores XOFF)",
                )
        self._pending += bytes(extra)

    async def send_tape(self, text: str, *, flow_control: bool = True) -> None:
        """DC2, the program as tape, DC4 — pausing while the peer has sent XOFF."""
        payload = bytes([PUNCH_ON]) + encode_program(text) + bytes([PUNCH_OFF])
        if self.parity:
            payload = add_parity(payload)
        if not flow_control:
            self.writer.write(payload)
            await self.writer.drain()
            return
        may_send = asyncio.Event()
        may_send.set()
        watcher = asyncio.ensure_future(self._watch_flow(may_send))
        try:
            tape = memoryview(payload)
            for i in range(0, len(payload), PUNCH_CHUNK):
                if not may_send.is_set():
                    try:
                        await asyncio.wait_for(may_send.wait(), 5.0)
                    except TimeoutError:
                        raise DncAlarm(
                            ALARM_TIMEOUT, "the receiver stayed in XOFF for 5 s"
                        ) from None
                if watcher.done() and watcher.exception() is None and watcher.result():
                    raise ConnectionError("peer closed during punch")
                self.writer.write(tape[i : i + PUNCH_CHUNK])
                await self.writer.drain()
                # drain() does not yield while the transport takes everything: let the
                # watcher see an XOFF that came in during the last chunk.
                await asyncio.sleep(0)
        finally:
            watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watcher

    async def _watch_flow(self, may_send: asyncio.Event) -> bool:
        """While punching, follow the peer's XON/XOFF; anything else it sends is kept for
        the next command. Returns True when the peer closed."""
        while True:
            data = await self.reader.read(64)
            if not data:
                may_send.set()
                return True
            rest = bytearray()
            for b in strip_parity(data) if self.parity else data:
                if b == XOFF:
                    may_send.clear()
                elif b == XON:
                    may_send.set()
                else:
                    rest.append(b)
            if rest:
                # Kept in arrival order (parity stripped bytes are re-read as plain text
                # only when parity is off; with parity the raw bytes are kept).
                self._pending += bytes(rest) if not self.parity else add_parity(bytes(rest))


def _json(data: object) -> str:
    return json.dumps(data, separators=(",", ":"), ensure_ascii=True)


def _number(arg: str) -> int:
    m = _NUMBER_ARG.match(arg.strip())
    if not m:
        raise DncAlarm(ALARM_NO_NUMBER, f"not a program number: {arg!r} (expected Onnnn)")
    number = int(m.group(1))
    why = program_number_error(number)
    if why is not None:
        raise DncAlarm(ALARM_NO_NUMBER, why)
    return number


def _required_number(arg: str) -> int:
    if not arg:
        raise DncAlarm(ALARM_NO_NUMBER, "this command needs a program number (Onnnn)")
    return _number(arg)
