"""The host's memory reaches a steady state: what grew in the soak (issue 14) is bounded.

The soak's host grew about 10 MB an hour after its warm-up. tracemalloc snapshots of the
cell in realtime (jobs looping, SSE clients churning, status polled; in-process and in
`bench/bench_soak.py --trace`), minutes apart after warm-up, named one growing structure:
the MTConnect agent's buffer, 131072 observations (the reference agent's default) of some
220 bytes each, filling for minutes to hours. The buffer is
`host.mtconnect_buffer_size`: bounded, and its cost per observation known. A later look
(3-frame tracebacks, and the code) found three more structures that grew for an hour or
more, each now flat or bounded where it is tested: the PLC's scan statistics
(tests/plc/test_scan_stats.py), the event hub's ring (tests/web_api/test_event_hub.py) and
the host's pending requests (tests/cell/test_cycle_audit.py)."""

from __future__ import annotations

import gc
import tracemalloc

import pytest

from cnc.config import ConfigError
from mtconnect import Agent
from server.cell import default_cell
from server.config import load_cell_config


def feed(agent: Agent, device: str, keys: list[str], n: int, start: int) -> None:
    """`n` observations shaped like the cell's: a few positions per SHDR line, each line
    with its own timestamp, values that change every time."""
    for i in range(start, start + n, len(keys)):
        ts = f"2026-11-26T06:{(i // 60_000) % 60:02d}:{(i // 1000) % 60:02d}.{i % 1000:03d}000Z"
        line = "|".join(f"{k}|{(i + j) * 0.0137 % 800 - 400:.4f}" for j, k in enumerate(keys))
        agent.ingest_line(device, f"{ts}|{line}")


def test_the_host_agents_buffer_grows_no_more_once_full_at_its_documented_cost():
    config = default_cell(free_ports=True)
    assert config.host.mtconnect_buffer_size == 131072  # docs/configuration.md
    size = 8192  # the same agent with a smaller buffer: the test's time, not its shape
    agent = Agent.from_cell(config, buffer_size=size)
    device = next(iter(config.machines))
    samples = [
        k
        for k, item in agent.device(device).by_key.items()
        if item.category == "SAMPLE" and item.type == "POSITION"
    ][:3]
    assert samples, "the device has position samples"
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        feed(agent, device, samples, size, 0)  # full
        feed(agent, device, samples, size, size)  # turned over once
        gc.collect()
        full = tracemalloc.get_traced_memory()[0]
        feed(agent, device, samples, 2 * size, 2 * size)  # twice more
        gc.collect()
        later = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert agent.buffer.last_sequence >= 4 * size - len(samples)
    # the cost docs/configuration.md states (about 220 bytes an observation) ...
    per_observation = (full - before) / size
    assert per_observation < 260, f"{per_observation:.0f} bytes an observation"
    # ... and nothing more once the buffer is full
    assert later - full < 0.02 * (full - before), f"{(later - full) / 1024:.0f} kB more"


def test_the_buffer_size_is_a_host_key_with_its_bounds():
    machines = {"mill1": {"base": "mill3"}}
    config = load_cell_config({"machines": machines, "host": {"mtconnect_buffer_size": 16384}})
    assert config.host.mtconnect_buffer_size == 16384
    with pytest.raises(ConfigError, match="mtconnect_buffer_size"):
        load_cell_config({"machines": machines, "host": {"mtconnect_buffer_size": 10}})
