"""The dashboard's status mapping (web_api/static/status.js) under node, table-driven.

The page reads the cell's status (server.host.MonitoringModel.status) and a machine's own
snapshot (cnc.status.MachineStatus as a dict) through one pure module; these cases pin how
each state is coloured and worded, and how the cell's names map to the tiles'.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

STATUS_JS = Path(__file__).resolve().parents[2] / "web_api" / "static" / "status.js"
NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="node is not installed")

RUNNER = """
const { statusView, machineState, busLoad } = await import(process.argv[1]);
const cases = JSON.parse(process.argv[2]);
const out = cases.map((s) => {
  const v = statusView(s);
  return { view: v, state: machineState(v), bus: busLoad(v) };
});
console.log(JSON.stringify(out));
"""


def run(*statuses: dict | None) -> list[dict]:
    r = subprocess.run(
        [NODE, "--input-type=module", "-e", RUNNER, STATUS_JS.as_uri(), json.dumps(statuses)],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    return json.loads(r.stdout)


def cell(**over) -> dict:
    """A status in the cell's shape (MonitoringModel.status)."""
    return {
        "connected": True,
        "availability": "AVAILABLE",
        "emergency_stop": "ARMED",
        "mode": "AUTOMATIC",
        "mode_detail": "AUTO",
        "execution": "READY",
        "program": "O0100",
        "line": 12,
        "block": "N90 X80.",
        "actual": {"X": -1.5, "Y": 2.0},
        "commanded": {"X": -1.25, "Y": 2.0},
        "feed_mm_min": 400.0,
        "overrides": {"feed": 90.0, "rapid": 50.0, "spindle": 110.0},
        "spindle": {"speed_rpm": 2000.0, "load_percent": 12.0, "mode": "SPINDLE"},
        "alarms": [],
        "counters": {"part_count": 7},
        "bus_load": {"mean_percent": 46.5, "peak_percent": 100.0},
        "plc": {"scan_time_ms": 0.25},
        **over,
    }


FAULT = {"condition": "nc_cond", "level": "FAULT", "code": "3010", "text": "following error"}
WARNING = {"condition": "plc_cond", "level": "WARNING", "code": "2001", "text": "lube low"}


@pytest.mark.parametrize(
    ("status", "state"),
    [
        (None, ["offline", "OFFLINE"]),
        (cell(connected=False), ["offline", "OFFLINE"]),
        (cell(availability="UNAVAILABLE"), ["offline", "OFFLINE"]),
        (cell(), ["idle", "READY"]),
        (cell(execution="PROGRAM_COMPLETED"), ["idle", "PROGRAM_COMPLETED"]),
        (cell(execution="ACTIVE"), ["active", "ACTIVE"]),
        (cell(execution="FEED_HOLD"), ["hold", "FEED_HOLD"]),
        (cell(execution="INTERRUPTED"), ["hold", "INTERRUPTED"]),
        (cell(execution="OPTIONAL_STOP"), ["hold", "OPTIONAL_STOP"]),
        (cell(execution="ACTIVE", alarms=[WARNING]), ["active", "ACTIVE"]),
        (cell(execution="READY", alarms=[WARNING]), ["warning", "READY"]),
        (cell(execution="ACTIVE", alarms=[FAULT]), ["alarm", "ALARM"]),
        (cell(emergency_stop="TRIGGERED"), ["alarm", "E-STOP"]),
        # reset gave READY with no alarm, but the axes lost their reference
        (cell(referenced=False, unreferenced_axes=["X", "Z"]), ["warning", "NOT REFERENCED"]),
        (cell(referenced=True, unreferenced_axes=[]), ["idle", "READY"]),
        (cell(unreferenced_axes=["Y"], alarms=[FAULT]), ["alarm", "ALARM"]),
        (
            {"availability": "AVAILABLE", "unreferenced": ["X"], "alarms": []},
            ["warning", "NOT REFERENCED"],
        ),
        # a machine's own snapshot (MachineStatus names)
        ({"availability": "AVAILABLE", "execution": "ACTIVE", "alarms": []}, ["active", "ACTIVE"]),
        ({"availability": "AVAILABLE", "alarms": [{"severity": "FAULT"}]}, ["alarm", "ALARM"]),
    ],
)
def test_state_colour_and_word(status, state):
    assert run(status)[0]["state"] == state


def test_the_cells_names_map_to_the_tiles():
    (got,) = run(cell(alarms=[FAULT, {**WARNING, "condition": "Yservo"}]))
    view = got["view"]
    assert view["controller_mode"] == "AUTOMATIC" and view["mode_detail"] == "AUTO"
    assert view["axes"] == {
        "X": {"actual": -1.5, "commanded": -1.25},
        "Y": {"actual": 2.0, "commanded": 2.0},
    }
    assert (view["path_feed_rate"], view["feed_override"], view["rapid_override"]) == (
        400.0,
        90.0,
        50.0,
    )
    assert (view["spindle_speed"], view["spindle_override"], view["spindle_load"]) == (
        2000.0,
        110.0,
        12.0,
    )
    assert view["part_count"] == 7 and view["plc_scan_time_ms"] == 0.25
    assert got["bus"] == {"mean": 46.5, "peak": 100.0}
    assert view["alarms"] == [
        {
            "source": "NC",
            "axis": None,
            "number": "3010",
            "text": "following error",
            "severity": "FAULT",
        },
        {
            "source": "DRIVE",
            "axis": "Y",
            "number": "2001",
            "text": "lube low",
            "severity": "WARNING",
        },
    ]


@pytest.mark.parametrize(
    ("bus_load", "expected"),
    [
        ({"mean_percent": None, "peak_percent": None}, None),
        ({"mean_percent": 0.0, "peak_percent": 3.0}, {"mean": 0.0, "peak": 3.0}),
        (None, None),
    ],
)
def test_bus_load_unknown_is_none_not_zero(bus_load, expected):
    assert run(cell(bus_load=bus_load))[0]["bus"] == expected


def test_condition_sources():
    conditions = ["nc_cond", "plc_cond", "bus_cond", "dnc_cond", "servo", "Zservo"]
    (got,) = run(cell(alarms=[{**FAULT, "condition": c} for c in conditions]))
    assert [(a["source"], a["axis"]) for a in got["view"]["alarms"]] == [
        ("NC", None),
        ("PLC", None),
        ("BUS", None),
        ("DNC", None),
        ("DRIVE", None),
        ("DRIVE", "Z"),
    ]


TIP_RUNNER = """
const { statusView, tipAxes } = await import(process.argv[1]);
const cases = JSON.parse(process.argv[2]);
console.log(JSON.stringify(cases.map((s) => tipAxes(statusView(s)?.tool_tip))));
"""


def test_mill5_status_gives_the_plot_the_tool_tip_and_others_none():
    with_tip = cell(
        tool_tip={"position": [1.5, -2.0, 30.0], "deviation_mm": 0.004, "peak_deviation_mm": 0.009}
    )
    r = subprocess.run(
        [NODE, "--input-type=module", "-e", TIP_RUNNER, STATUS_JS.as_uri(),
         json.dumps([with_tip, cell(tool_tip=None), cell()])],
        capture_output=True, text=True, timeout=30, check=True,
    )  # fmt: skip
    tip, none1, none2 = json.loads(r.stdout)
    assert tip == {
        "X": {"actual": 1.5, "commanded": 1.5},
        "Y": {"actual": -2.0, "commanded": -2.0},
        "Z": {"actual": 30.0, "commanded": 30.0},
    }
    assert none1 is None and none2 is None
