"""Host asyncio services (the machine's faces) on one event loop in a daemon thread.

The machine itself steps synchronously (lockstep or realtime); its network faces are asyncio
servers. One loop thread per machine serves all of its faces, so a machine costs one thread,
not one per face.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Awaitable, Callable
from typing import TypeVar

T = TypeVar("T")


class LoopThread:
    def __init__(self, name: str = "faces") -> None:
        self._name = name
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise RuntimeError("LoopThread is not started")
        return self._loop

    def start(self) -> LoopThread:
        if self._thread is not None:
            return self
        ready = threading.Event()
        loop = asyncio.new_event_loop()

        def run() -> None:
            asyncio.set_event_loop(loop)
            loop.call_soon(ready.set)
            loop.run_forever()
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

        self._loop = loop
        self._thread = threading.Thread(target=run, name=self._name, daemon=True)
        self._thread.start()
        ready.wait()
        return self

    def run(self, factory: Callable[[], Awaitable[T]], timeout: float = 10.0) -> T:
        """Run a coroutine on the loop from another thread and return its result.

        Past `timeout` the coroutine is cancelled (not left to run later, or never, on a
        loop that stops) and TimeoutError raised."""
        future = asyncio.run_coroutine_threadsafe(_call(factory), self.loop)
        try:
            return future.result(timeout)
        except TimeoutError:
            future.cancel()
            raise

    def stop(self, timeout: float = 5.0) -> None:
        thread, self._thread = self._thread, None
        if thread is None:
            return
        self.loop.call_soon_threadsafe(self.loop.stop)
        thread.join(timeout)
        self._loop = None


async def _call(factory: Callable[[], Awaitable[T]]) -> T:
    return await factory()
