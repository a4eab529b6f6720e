"""What every line-oriented TCP face of a machine shares: the bound port, the sessions it
tracks, and a stop that ends every session before the listener goes away."""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac


def secret_matches(presented: str, secret: str) -> bool:
    """Whether `presented` is the face's shared secret, in time independent of where they
    differ and of the presented length (both are hashed to 32 bytes first)."""
    a = hashlib.sha256(presented.encode("utf-8", "surrogateescape")).digest()
    b = hashlib.sha256(secret.encode("utf-8")).digest()
    return hmac.compare_digest(a, b)


class TcpFace:
    """Base of the DNC port and the simulation face; subclasses serve `_session`."""

    _what = "face"

    def __init__(self) -> None:
        self._server: asyncio.Server | None = None
        self._sessions: set[asyncio.Task] = set()

    @property
    def bound_port(self) -> int:
        """The TCP port actually bound (differs from the configured one when that was 0)."""
        if self._server is None:
            raise RuntimeError(f"{self._what} not started")
        return self._server.sockets[0].getsockname()[1]

    async def _serve(self, host: str, port: int, **kwargs) -> None:
        self._server = await asyncio.start_server(self._tracked, host, port, **kwargs)

    async def _tracked(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        self._sessions.add(task)
        try:
            await self._session(reader, writer)
        finally:
            self._sessions.discard(task)

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        raise NotImplementedError

    async def stop(self) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        for task in list(self._sessions):
            task.cancel()
        for task in list(self._sessions):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        with contextlib.suppress(Exception):
            await asyncio.wait_for(server.wait_closed(), 1.0)
