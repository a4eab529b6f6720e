"""The agent's circular buffer of observations, with sequence numbers and checkpoints.

Semantics follow the reference agent (cppagent `CircularBuffer`/`Checkpoint`):

- every observation gets the next sequence number, starting at 1; numbers are Python ints,
  so they never wrap (the reference agent uses 64 bits);
- the buffer keeps the last `size` observations: `first_sequence` is the oldest still held,
  `next_sequence` the number the next observation will get, `last_sequence` = next - 1;
- `first` is the state of every data item just before `first_sequence` (observations that
  fall out of the buffer are folded into it), `latest` the state after the newest; a
  checkpoint every `checkpoint_frequency` sequences makes `current?at=` cheap;
- a condition's state is the list of its active activations (by native code); NORMAL
  without a code or UNAVAILABLE clears them all.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

from mtconnect.model import DataItem

UNAVAILABLE = "UNAVAILABLE"
DEFAULT_BUFFER_SIZE = 131_072  # 2**17, the reference agent's BufferSize 17
DEFAULT_CHECKPOINT_FREQUENCY = 1000


@dataclass(frozen=True, slots=True)
class Observation:
    item: DataItem
    timestamp: str
    value: str  # sample/event value; a condition's text
    sequence: int = 0
    level: str = ""  # conditions: NORMAL WARNING FAULT UNAVAILABLE
    native_code: str = ""
    native_severity: str = ""
    qualifier: str = ""

    @property
    def unavailable(self) -> bool:
        if self.item.category == "CONDITION":
            return self.level == UNAVAILABLE
        return self.value == UNAVAILABLE


class Checkpoint:
    """The state of every data item at one point in the sequence."""

    __slots__ = ("_values",)

    def __init__(self, other: Checkpoint | None = None) -> None:
        self._values: dict[str, Observation | tuple[Observation, ...]] = (
            dict(other._values) if other is not None else {}
        )

    def add(self, obs: Observation) -> None:
        item = obs.item
        if item.category != "CONDITION":
            self._values[item.id] = obs
            return
        active = self._values.get(item.id, ())
        if obs.level == UNAVAILABLE or (obs.level == "NORMAL" and not obs.native_code):
            self._values[item.id] = (obs,)
        elif obs.level == "NORMAL":
            kept = tuple(
                a for a in active if a.native_code != obs.native_code and a.level != "NORMAL"
            )
            kept = tuple(a for a in kept if a.level != UNAVAILABLE)
            self._values[item.id] = kept or (obs,)
        else:
            kept = [a for a in active if a.level not in ("NORMAL", UNAVAILABLE)]
            for i, a in enumerate(kept):
                if a.native_code == obs.native_code:
                    kept[i] = obs
                    break
            else:
                kept.append(obs)
            self._values[item.id] = tuple(kept)

    def get(self, item_id: str) -> Observation | tuple[Observation, ...] | None:
        return self._values.get(item_id)

    def observations(self, wanted: set[str] | None = None) -> list[Observation]:
        out: list[Observation] = []
        for item_id, value in self._values.items():
            if wanted is not None and item_id not in wanted:
                continue
            if isinstance(value, tuple):
                out.extend(value)
            else:
                out.append(value)
        return out


class CircularBuffer:
    def __init__(
        self,
        size: int = DEFAULT_BUFFER_SIZE,
        checkpoint_frequency: int = DEFAULT_CHECKPOINT_FREQUENCY,
    ) -> None:
        if size < 1:
            raise ValueError(f"buffer size must be >= 1, got {size}")
        if checkpoint_frequency < 1:
            raise ValueError(f"checkpoint frequency must be >= 1, got {checkpoint_frequency}")
        self.size = size
        self.checkpoint_frequency = checkpoint_frequency
        self.next_sequence = 1
        self.first_sequence = 1
        self._ring: deque[Observation] = deque(maxlen=size)
        self.first = Checkpoint()
        self.latest = Checkpoint()
        # (sequence, checkpoint including that sequence); only those still in the ring matter
        self._checkpoints: deque[tuple[int, Checkpoint]] = deque(
            maxlen=max(1, size // checkpoint_frequency + 1)
        )

    @property
    def last_sequence(self) -> int:
        return self.next_sequence - 1

    def add(self, obs: Observation) -> Observation:
        """Append an observation; returns it with its sequence number."""
        seq = self.next_sequence
        obs = Observation(
            obs.item,
            obs.timestamp,
            obs.value,
            seq,
            obs.level,
            obs.native_code,
            obs.native_severity,
            obs.qualifier,
        )
        if len(self._ring) == self.size:
            self.first.add(self._ring[0])
            self.first_sequence += 1
        self._ring.append(obs)
        self.latest.add(obs)
        if seq % self.checkpoint_frequency == 0:
            self._checkpoints.append((seq, Checkpoint(self.latest)))
        self.next_sequence += 1
        return obs

    def get(self, seq: int) -> Observation | None:
        off = seq - self.first_sequence
        if 0 <= off < len(self._ring):
            return self._ring[off]
        return None

    def checkpoint_at(self, at: int) -> Checkpoint:
        """The state just after sequence `at` (first_sequence <= at < next_sequence)."""
        base, start = self.first, self.first_sequence
        for seq, cp in reversed(self._checkpoints):
            if self.first_sequence <= seq <= at:
                base, start = cp, seq + 1
                break
        check = Checkpoint(base)
        for seq in range(start, at + 1):
            check.add(self._ring[seq - self.first_sequence])
        return check

    def observations(
        self,
        count: int,
        wanted: set[str] | None,
        start: int | None,
        to: int | None,
    ) -> tuple[list[Observation], int, int, bool]:
        """The reference agent's `getObservations`: (observations in sequence order, end,
        first, end_of_buffer). `end` is the header's nextSequence, `first` its
        firstSequence (it becomes `from` when both from and to are given, as in cppagent).
        """
        first_seq = self.first_sequence
        ring, n = self._ring, len(self._ring)
        if count >= 0:
            if to is not None:
                if start is not None and start > self.first_sequence:
                    first_seq = start
                first, inc = to, -1
            else:
                first = start if (start is not None and start > first_seq) else first_seq
                inc = 1
            limit = count
        else:
            first = (
                start
                if (start is not None and start < self.next_sequence)
                else (self.next_sequence - 1)
            )
            limit, inc = -count, -1
        lo = first_seq - self.first_sequence
        i = first - self.first_sequence
        out: list[Observation] = []
        while len(out) < limit and 0 <= i < n and i >= lo:
            obs = ring[i]
            if wanted is None or obs.item.id in wanted:
                out.append(obs)
            i += inc
        if to is not None:
            end = first + 1 if first < self.next_sequence else self.next_sequence
        else:
            end = self.first_sequence + i
        if count >= 0:
            end_of_buffer = i + self.first_sequence >= self.next_sequence
        else:
            end_of_buffer = i + self.first_sequence <= self.first_sequence
        if inc < 0:
            out.reverse()
        return out, end, first_seq, end_of_buffer

    def extend(self, observations: Iterable[Observation]) -> None:
        for obs in observations:
            self.add(obs)
