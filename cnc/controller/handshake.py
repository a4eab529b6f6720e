"""Strobe/finish handshakes of the NC<->PLC signal table (docs/machine_plc.md).

The NC writes the code register, raises the strobe and waits for the finish; then it drops
the strobe and waits for the finish to drop, so that the PLC has seen the strobe low in at
least one scan before the next function raises it again (a strobe raised again before the
PLC scanned would be no edge at all).
"""

from __future__ import annotations

IDLE, STROBE, RELEASE = 0, 1, 2


class Handshake:
    """One channel: M (MStrobe/MCode/MFinish), S or T."""

    __slots__ = ("code", "code_signal", "finish_signal", "phase", "strobe_signal")

    def __init__(self, letter: str) -> None:
        self.strobe_signal = f"{letter}Strobe"
        self.code_signal = f"{letter}Code"
        self.finish_signal = f"{letter}Finish"
        self.code = 0
        self.phase = IDLE

    def start(self, code: int) -> None:
        self.code = int(code)
        self.phase = STROBE

    @property
    def busy(self) -> bool:
        return self.phase != IDLE

    def step(self, finish: bool) -> bool:
        """Advance on the PLC's finish; True once the handshake is complete."""
        if self.phase == STROBE and finish:
            self.phase = RELEASE
        elif self.phase == RELEASE and not finish:
            self.phase = IDLE
            return True
        return False

    def abort(self) -> None:
        self.phase = IDLE

    def write(self, out: dict) -> None:
        out[self.strobe_signal] = self.phase == STROBE
        out[self.code_signal] = self.code
