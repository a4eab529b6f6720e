"""What a machine writes down: the event log and the per-IPO-cycle position trace."""

from __future__ import annotations

import json
from collections import deque
from dataclasses import asdict, dataclass
from typing import TextIO


@dataclass(frozen=True)
class Event:
    t: float  # machine time, s
    kind: str  # alarm, alarm_cleared, fault_injected, command, refused, operator, face
    text: str
    data: dict | None = None


class EventLog:
    """Bounded ring of events (oldest dropped) plus an optional JSONL file, one line each."""

    def __init__(self, capacity: int = 10_000, path: str | None = None) -> None:
        self.events: deque[Event] = deque(maxlen=capacity)
        self._file: TextIO | None = open(path, "w", encoding="utf-8") if path else None  # noqa: SIM115

    def add(self, t: float, kind: str, text: str, data: dict | None = None) -> Event:
        event = Event(round(t, 6), kind, text, data)
        self.events.append(event)
        if self._file is not None:
            self._file.write(json.dumps(asdict(event), sort_keys=True) + "\n")
        return event

    def of_kind(self, kind: str) -> list[Event]:
        return [e for e in self.events if e.kind == kind]

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class TraceWriter:
    """CSV, one row per IPO cycle: t, commanded and actual per axis, the program line.

    Streamed to the file as the machine runs (bounded memory); numbers in fixed formats so
    two lockstep runs of the same scenario give byte-identical files.
    """

    def __init__(self, stream: TextIO, axes: tuple[str, ...]) -> None:
        self.stream = stream
        self.axes = axes
        cols = ["t"] + [f"{a}_cmd" for a in axes] + [f"{a}_act" for a in axes] + ["line"]
        stream.write(",".join(cols) + "\n")

    def row(self, t: float, commanded, actual, line: int) -> None:
        parts = [f"{t:.4f}"]
        parts += [f"{commanded.get(a, 0.0):.4f}" for a in self.axes]
        parts += [f"{actual.get(a, 0.0):.4f}" for a in self.axes]
        parts.append(str(line))
        self.stream.write(",".join(parts).replace("-0.0000", "0.0000") + "\n")
