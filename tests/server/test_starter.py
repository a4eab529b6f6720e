"""The transfer worker's cycle start (server.host.make_starter) presses cycle start once.

The host's view of a machine trails it by seconds on a loaded host; a starter that pressed
again when the view still showed READY after 5 s made a part twice (a host-restart run at
load 20: 9 parts for a job of 8). Here the view is held stale on purpose and the machine's
own face says what the NC does.
"""

from __future__ import annotations

import contextlib

import pytest

from server.host import make_starter
from server.supervisor import MachineLink, MachineUnavailable
from tests.server.test_supervisor import ScriptedPanel, link


class StaleView:
    """A monitoring view that saw the program selected and nothing since."""

    def __init__(self, parts: int = 3) -> None:
        self.parts = parts

    def status(self, machine: str) -> dict:
        return {
            "mode": "AUTOMATIC",
            "execution": "READY",
            "program": "O0042",
            "counters": {"part_count": self.parts},
            "cycle_start_refused": "",
            "alarms": [],
        }


@pytest.fixture
def panel(monkeypatch):
    p = ScriptedPanel()
    monkeypatch.setattr(
        MachineLink, "remote_panel", lambda self, timeout_s=3.0: contextlib.nullcontext(p)
    )
    return p


def test_a_start_the_view_does_not_show_yet_is_not_pressed_again(panel):
    start = make_starter({"m1": link(modbus=1)}, StaleView(), 0.3, 0.05)
    with pytest.raises(MachineUnavailable, match=r"m1: O0042 running not seen within 0.3 s"):
        start("m1", 42)
    assert panel.requests.count(("cycle_start",)) == 1, panel.requests


def test_the_nc_in_cycle_on_its_face_is_running_before_the_view_says_so(panel):
    def take_start():  # the NC takes the start; the view does not catch up
        panel.requests.append(("cycle_start",))
        panel.in_cycle = True

    panel.cycle_start = take_start
    start = make_starter({"m1": link(modbus=1)}, StaleView(parts=3), 30.0, 0.05)
    assert start("m1", 42) == 3  # the counter before the press: the allocation's baseline
    assert panel.requests == [("select", 42), ("cycle_start",)]
