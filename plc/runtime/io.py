"""I/O providers (where inputs come from and outputs go) and the input debounce filter."""

from __future__ import annotations

from typing import Protocol

from plc.image import ImageSize


class IOProvider(Protocol):
    """The field side of the PLC. The runtime calls it once per scan, from the scan thread."""

    def read_inputs(self, ix: list[bool], iw: list[int], now_ms: int) -> None:
        """Fill the raw input lists (same sizes as the image's %IX/%IW)."""

    def write_outputs(self, qx: list[bool], qw: list[int], now_ms: int) -> None:
        """Take the scan's outputs (read-only lists owned by the runtime)."""


class SimulatedIO:
    """Field I/O held in lists: a simulation (or a test) sets inputs and reads outputs."""

    def __init__(self, size: ImageSize | None = None) -> None:
        s = size or ImageSize()
        self.ix = [False] * s.ix
        self.iw = [0] * s.iw
        self.qx = [False] * s.qx
        self.qw = [0] * s.qw

    def set_input(self, index: int, value: bool) -> None:
        self.ix[index] = bool(value)

    def set_word(self, index: int, value: int) -> None:
        self.iw[index] = int(value)

    def read_inputs(self, ix: list[bool], iw: list[int], now_ms: int) -> None:
        # slices of the shorter length: the image's lists never change size
        n, m = min(len(ix), len(self.ix)), min(len(iw), len(self.iw))
        ix[:n] = self.ix[:n]
        iw[:m] = self.iw[:m]

    def write_outputs(self, qx: list[bool], qw: list[int], now_ms: int) -> None:
        n, m = min(len(qx), len(self.qx)), min(len(qw), len(self.qw))
        self.qx[:n] = qx[:n]
        self.qw[:m] = qw[:m]


class Debounce:
    """Input filter after the GE 1050 digital filter: a change of an input counts only after
    it has been sampled at the new level `samples` times in a row (4 by default).

    Pure: `filter(raw, stable)` updates `stable` in place from one new sample `raw`.
    """

    def __init__(self, samples: int = 4) -> None:
        if samples < 1:
            raise ValueError("debounce needs at least 1 sample")
        self.samples = samples
        self.pending: dict[int, int] = {}  # bit index -> identical samples at the new level

    def filter(self, raw: list[bool], stable: list[bool]) -> None:
        pending = self.pending
        for i in [i for i in pending if raw[i] == stable[i]]:
            del pending[i]  # glitch: back at the stable level before it counted
        if raw == stable:
            return
        for i, (r, s) in enumerate(zip(raw, stable, strict=True)):
            if r != s:
                n = pending.get(i, 0) + 1
                if n >= self.samples:
                    stable[i] = r
                    pending.pop(i, None)
                else:
                    pending[i] = n
