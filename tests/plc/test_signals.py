"""The declared NC<->PLC signal table against the machine-tool program's tag table, the NC
port's direction rules, and the program passing `fmscell plc check`."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from plc.ladder import load_file
from plc.machine_io import PROGRAM_PATH
from plc.signals import (
    DIRECTIONS,
    HOST_TO_PLC,
    NC_TO_PLC,
    PLC_TO_NC,
    SIGNALS,
    NcPort,
    Signal,
    signal,
    signals,
)

ROOT = Path(__file__).resolve().parents[2]
PROGRAM = load_file(PROGRAM_PATH)


def test_every_signal_is_declared_in_the_program_with_the_same_address_and_type():
    for s in SIGNALS:
        tag = PROGRAM.tags.get(s.name.upper())
        assert tag is not None, f"{s.name} missing from the program's tag table"
        assert tag.name == s.name, f"spelling differs: {tag.name} vs {s.name}"
        assert (tag.area, tag.index, tag.type) == (s.area, s.index, s.type), s.name


def test_every_addressed_tag_of_the_program_is_a_declared_signal():
    declared = {s.name.upper() for s in SIGNALS}
    addressed = {k for k, t in PROGRAM.tags.items() if t.area not in (None, "V")}
    assert addressed - declared == set()


def test_addresses_are_unique():
    seen: dict[tuple[str, int], str] = {}
    for s in SIGNALS:
        assert (s.area, s.index) not in seen, f"{s.name} and {seen[(s.area, s.index)]} overlap"
        seen[(s.area, s.index)] = s.name


def test_every_direction_is_used_and_lives_in_its_area():
    for d in DIRECTIONS:
        assert signals(d), d
    assert {s.area for s in signals(NC_TO_PLC)} == {"IX", "IW"}
    assert {s.area for s in signals(PLC_TO_NC)} == {"QX", "QW"}
    assert {s.area for s in signals(HOST_TO_PLC)} == {"MX", "MW"}


def test_program_alarms_are_documented_with_their_text():
    doc = (ROOT / "docs" / "machine_plc.md").read_text(encoding="utf-8")
    for a in PROGRAM.alarms:
        row = re.search(rf"^\| {a.number} \|[^|]*\| (.+?) \|", doc, re.M)
        assert row is not None, f"alarm {a.number} not in docs/machine_plc.md"
        assert row.group(1) == a.text, a.number
    for s in SIGNALS:
        assert f"| {s.name} |" in doc, f"{s.name} not in the signal table of the docs"


def test_fmscell_plc_check_accepts_the_program():
    from server.cli import app

    result = CliRunner().invoke(app, ["plc", "check", PROGRAM_PATH])
    assert result.exit_code == 0, result.output
    assert "OK" in result.output and "0 warning(s)" in result.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("X", NC_TO_PLC, "%QX0.0", "BOOL", ""), "cannot live in %QX"),
        (("X", NC_TO_PLC, "%IX0.8", "BOOL", ""), "malformed"),
        (("X", NC_TO_PLC, "%IW3", "BOOL", ""), "holds INT"),
        (("X", NC_TO_PLC, "%IW3.1", "INT", ""), "bit/word"),
        (("X", "sideways", "%IX0.0", "BOOL", ""), "unknown direction"),
    ],
)
def test_bad_declarations_are_refused(args, message):
    with pytest.raises(ValueError, match=message):
        Signal(*args)


def test_lookup_and_modbus_addresses():
    assert signal("mstrobe").address == "%IX0.3"
    assert signal("MStrobe").modbus == ("discrete input", 3)
    assert signal("RemCycleStart").modbus == ("coil", 8192)
    assert signal("RemFeedOvr").modbus == ("holding register", 1024)
    assert signal("FeedOverride").modbus == ("holding register", 1)
    with pytest.raises(KeyError, match="NoSuch"):
        signal("NoSuch")
    with pytest.raises(ValueError, match="unknown direction"):
        signals("up")


def test_nc_port_directions():
    port = NcPort()
    port.set("MCode", 6)
    port.set("MStrobe", 1)
    assert port.get("MStrobe") is True and port.get("MCode") == 6
    with pytest.raises(ValueError, match="can only set NC->PLC"):
        port.set("MFinish", True)
    with pytest.raises(ValueError, match="not part of the NC interface"):
        port.get("SpindleFwd")
    with pytest.raises(ValueError, match="does not fit an INT"):
        port.set("SCode", 40000)
    ix, iw = [False] * 64, [0] * 16
    port.apply_inputs(ix, iw)
    assert ix[signal("MStrobe").index] and iw[signal("MCode").index] == 6
    qx, qw = [False] * 64, [0] * 16
    qx[signal("MFinish").index] = True
    qw[signal("FeedOverride").index] = 80
    port.take_outputs(qx, qw)
    assert port.get("MFinish") is True and port.outputs()["FeedOverride"] == 80
