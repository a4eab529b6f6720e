"""The simulation face: a local text channel for fault injection, operator actions, clock.

Off unless enabled (`ports.simulation`, `fmscell machine --simulation`). One command per line,
one answer line per command, `OK ...` or `ERR <reason>`:

    FAULT <spec>              inject now (-> `OK injected <spec> t=<machine time>`), or at
                              machine time t when the spec ends in @t
    CLEAR <spec>              clear an injected fault (a tripped drive still needs a reset;
                              -> `OK cleared <spec> t=<machine time>`)
    DOOR OPEN | DOOR CLOSE    operator pulls / shuts the guard door (refused while locked)
    ESTOP PRESS | ESTOP RELEASE
    PRESS PanelCycleStart | PanelFeedHold | PanelReset     a panel key for one scan
    PAUSE | RESUME | STEP <n> | SPEED <factor>             clock (realtime runner only)
    STATUS                    t, cycle, execution, mode, alarms
    SPECS                     the valid fault specs
    QUIT

With a shared secret (`ports.secret`) the first line must be `AUTH <secret>` (-> `OK AUTH`);
any other first line, or a wrong secret, answers `ERR authentication ...` and closes, so no
fault, E-stop or clock command runs for a client that does not know it.

Machine actions run on the machine's thread at the start of its next cycle, so the answer
comes once the machine has taken them.
"""

from __future__ import annotations

import asyncio

from cnc.faces.tcp_face import TcpFace, secret_matches
from cnc.machine.faults import FaultSpecError, parse_fault_spec, valid_specs

MAX_LINE = 1024


class SimulationFace(TcpFace):
    _what = "simulation face"

    def __init__(
        self,
        machine,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        timeout_s: float = 10.0,
        secret: str | None = None,
    ) -> None:
        super().__init__()
        self.machine = machine
        self._secret = secret
        self.auth_refused = 0
        self.host, self.port = host, port
        self.timeout_s = timeout_s

    async def start(self) -> None:
        await self._serve(self.host, self.port)

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        authenticated = self._secret is None
        try:
            while True:
                try:
                    raw = await reader.readline()
                except (ValueError, asyncio.LimitOverrunError):
                    writer.write(b"ERR line too long\n")
                    break
                if not raw:
                    break
                if len(raw) > MAX_LINE:
                    writer.write(b"ERR line too long\n")
                    break
                line = raw.decode("ascii", "replace").strip()
                if not line:
                    continue
                if line.upper() == "QUIT":
                    break
                word, _, rest = line.partition(" ")
                if word.upper() == "AUTH":
                    if self._secret is not None and not secret_matches(rest.strip(), self._secret):
                        self.auth_refused += 1
                        writer.write(b"ERR authentication failed: wrong secret\n")
                        await writer.drain()
                        break
                    authenticated = True
                    writer.write(b"OK AUTH\n" if self._secret else b"OK AUTH (no secret)\n")
                    await writer.drain()
                    continue
                if not authenticated:
                    self.auth_refused += 1
                    writer.write(
                        b"ERR authentication required: the first line must be AUTH <secret>\n"
                    )
                    await writer.drain()
                    break
                answer = await self.execute(line)
                writer.write((answer + "\n").encode())
                await writer.drain()
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            writer.close()

    async def execute(self, line: str) -> str:
        word, _, rest = line.partition(" ")
        word, rest = word.upper(), rest.strip()
        m = self.machine
        try:
            if word == "SPECS":
                return "OK " + " ".join(valid_specs())
            if word in ("PAUSE", "RESUME", "STEP", "SPEED"):
                return await self._clock(word, rest)
            if word == "FAULT":
                spec = parse_fault_spec(rest, m.axis_names)
                if "@" in rest:
                    return await self._on_machine(
                        lambda: m.schedule.add(spec), f"OK scheduled {spec}"
                    )
                return await self._on_machine(lambda: self._done(m.inject, spec, "injected"), None)
            if word == "CLEAR":
                spec = parse_fault_spec(rest, m.axis_names)
                return await self._on_machine(
                    lambda: self._done(m.clear_fault, spec, "cleared"), None
                )
            if word == "DOOR" and rest.upper() in ("OPEN", "CLOSE"):
                if rest.upper() == "CLOSE":
                    return await self._on_machine(m.close_door, "OK door closed")
                opened = await self._on_machine(m.open_door, None)
                return (
                    "OK door open" if opened else "ERR door is locked (spindle or changer active)"
                )
            if word == "ESTOP" and rest.upper() in ("PRESS", "RELEASE"):
                fn = m.press_estop if rest.upper() == "PRESS" else m.release_estop
                return await self._on_machine(fn, f"OK E-stop {rest.lower()}ed")
            if word == "PRESS":
                return await self._on_machine(lambda: m.press(rest), f"OK {rest} pressed")
            if word == "STATUS":
                return await self._on_machine(self._status, None)
        except (FaultSpecError, ValueError, KeyError) as exc:
            return "ERR " + str(exc).replace("\n", " ")
        return (
            f"ERR unknown command {line[:40]!r}; commands: FAULT CLEAR DOOR ESTOP PRESS "
            "PAUSE RESUME STEP SPEED STATUS SPECS QUIT"
        )

    def _done(self, fn, spec, what: str) -> str:
        """Run `fn(spec)` on the machine's thread; the answer carries the machine time it took
        effect (a bench judges detection bounds in machine time, not in a loaded host's wall
        time)."""
        fn(spec)
        return f"OK {what} {spec} t={self.machine.t:.4f}"

    def _status(self) -> str:
        m = self.machine
        s = m.full_status()
        alarms = (
            ",".join(f"{a.source}{a.number}" + (f"/{a.axis}" if a.axis else "") for a in s.alarms)
            or "-"
        )
        return (
            f"OK t={m.t:.4f} cycle={m.cycle} execution={s.execution} mode={s.mode_detail} "
            f"line={s.line} alarms={alarms}"
        )

    async def _clock(self, word: str, rest: str) -> str:
        runner = getattr(self.machine, "runner", None)
        if runner is None:
            return (
                "ERR clock control needs the realtime runner (this machine is stepped by its owner)"
            )
        if word == "PAUSE":
            runner.pause()
            for _ in range(int(self.timeout_s / 0.001)):
                if runner.paused_ack.is_set():
                    return f"OK pause {self.machine.cycle}"
                await asyncio.sleep(0.001)
            return "ERR the runner did not pause in time"
        elif word == "RESUME":
            runner.resume()
        elif word == "STEP":
            n = int(rest or "1")
            if not 1 <= n <= 1_000_000:
                return "ERR STEP takes 1..1000000 cycles"
            if not runner.paused:
                return "ERR STEP needs a paused clock (PAUSE first)"
            goal = runner.step(n)
            for _ in range(int(self.timeout_s / 0.001)):
                if runner.stepped >= goal:
                    return f"OK step {self.machine.cycle}"
                await asyncio.sleep(0.001)
            return "ERR the machine did not complete the steps in time"
        else:
            factor = float(rest)
            if not 0.01 <= factor <= 100.0:
                return "ERR SPEED takes a factor 0.01..100"
            runner.speed = factor
        return f"OK {word.lower()}"

    async def _on_machine(self, fn, ok: str | None):
        loop = asyncio.get_running_loop()
        done: asyncio.Future = loop.create_future()

        def run() -> None:
            try:
                result = fn()
            except Exception as exc:  # reported to the client, the machine keeps running
                loop.call_soon_threadsafe(_set, done, exc, True)
            else:
                loop.call_soon_threadsafe(_set, done, result, False)

        self.machine.call_soon(run)
        try:
            result = await asyncio.wait_for(done, self.timeout_s)
        except TimeoutError:
            return "ERR the machine is not stepping (paused or stopped)"
        if isinstance(result, _Failed):
            return "ERR " + str(result.exc).replace("\n", " ")
        return ok if ok is not None else result


class _Failed:
    def __init__(self, exc: Exception) -> None:
        self.exc = exc


def _set(fut: asyncio.Future, value, failed: bool) -> None:
    if not fut.done():
        fut.set_result(_Failed(value) if failed else value)
