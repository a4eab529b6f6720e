"""The machine's face loop: a call that times out is cancelled, not left to run later."""

from __future__ import annotations

import asyncio
import threading

import pytest

from cnc.faces.loop_thread import LoopThread


def test_a_call_past_its_timeout_is_cancelled_and_says_timeout():
    loop = LoopThread("t").start()
    ended = threading.Event()
    outcome: list[str] = []

    async def slow():
        try:
            await asyncio.sleep(3600)
            outcome.append("finished")
        except asyncio.CancelledError:
            outcome.append("cancelled")
            raise
        finally:
            ended.set()

    try:
        with pytest.raises(TimeoutError):
            loop.run(slow, timeout=0.05)
        assert ended.wait(30.0), "the timed-out call was left running"
        assert outcome == ["cancelled"]
        assert loop.run(lambda: asyncio.sleep(0, result=7)) == 7  # the loop still serves
    finally:
        loop.stop()
