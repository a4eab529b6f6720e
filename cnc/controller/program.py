"""Block sources for a program run: program memory, MDI text, drip-feed (BTR).

The interpreter pulls lines lazily, and a drip-feed may have none yet. A Python generator
cannot pause its caller, so when the interpreter asks for a line the buffer does not have,
`DripLines` hands it a no-op marker block (`G4 P0`) and the controller drops the dwell that
comes out of it. The interpreter numbers lines as it reads them, markers included;
`real_line` maps a number back to the tape's line for the status and for error messages.
"""

from __future__ import annotations

from collections import OrderedDict, deque

from cnc.faces.drip import DripBuffer

MARKER = "G4P0"
LOOKAHEAD_LINES = 2  # lines taken from the drip buffer ahead of the interpreter
_MAP_KEEP = 512  # recent interpreter line -> tape line entries kept (memory stays bounded)
BLOCK_RING = 64  # recent drip lines kept for the status display


class DripLines:
    """An endless line iterator over a DripBuffer (see the module docstring)."""

    def __init__(self, buffer: DripBuffer) -> None:
        self.buffer = buffer
        self.pending: deque[str] = deque()
        self.ended = False
        self.fed = 0  # lines handed to the interpreter, markers included
        self.real = 0  # tape lines handed to the interpreter
        self.markers: set[int] = set()
        self._map: OrderedDict[int, int] = OrderedDict()
        self.recent: OrderedDict[int, str] = OrderedDict()
        self.waiting = False  # the last fill found no data: the NC waits for the sender

    def fill(self) -> bool:
        """Take blocks from the buffer; True when a line (or the end) is ready."""
        while len(self.pending) < LOOKAHEAD_LINES and not self.ended:
            block = self.buffer.take()
            if block is False:
                break
            if block is None:
                self.ended = True
                break
            self.pending.append(block)
        ready = bool(self.pending) or self.ended
        self.waiting = not ready
        return ready

    def __iter__(self) -> DripLines:
        return self

    def __next__(self) -> str:
        self.fed += 1
        if self.pending:
            self.real += 1
            text = self.pending.popleft()
            self._map[self.fed] = self.real
            self.recent[self.real] = text
            if len(self._map) > _MAP_KEEP:
                self._map.popitem(last=False)
            if len(self.recent) > BLOCK_RING:
                self.recent.popitem(last=False)
            return text
        if self.ended:
            self.fed -= 1
            raise StopIteration
        self.markers.add(self.fed)
        return MARKER

    def is_marker(self, line: int) -> bool:
        if line in self.markers:
            self.markers.discard(line)
            return True
        return False

    def real_line(self, line: int) -> int:
        return self._map.get(line, line)

    @property
    def starved(self) -> bool:
        return self.waiting
