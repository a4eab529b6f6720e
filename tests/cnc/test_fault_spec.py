"""Fault specs: `target:kind@time` parsing (table of cases), errors, the virtual-time schedule."""

from __future__ import annotations

import pytest

from cnc.machine.faults import (
    FaultSchedule,
    FaultSpecError,
    parse_fault_spec,
    parse_time,
    valid_specs,
)

AXES = ("X", "Y", "Z")


@pytest.mark.parametrize(
    ("text", "target", "kind", "axis", "params", "at_s"),
    [
        ("drive:X:encoder@1.5s", "drive", "encoder_break", "X", {}, 1.5),
        ("drive:Y:following_error@2s", "drive", "blocked", "Y", {}, 2.0),
        ("drive:Z:overtemperature@1", "drive", "winding_temperature", "Z", {"celsius": 160.0}, 1.0),
        (
            "drive:Z:mains_voltage:volts=250@1s",
            "drive",
            "mains_voltage",
            "Z",
            {"volts": 250.0},
            1.0,
        ),
        (
            "drive:X:load_force:newtons=-800@250ms",
            "drive",
            "load_force",
            "X",
            {"newtons": -800.0},
            0.25,
        ),
        ("drive:X:power_cycle@3s", "node", "power_cycle", "X", {}, 3.0),
        ("bus:bus_off:X@3s", "bus", "bus_off", "X", {}, 3.0),
        ("bus:drop:Y:count=0@2s", "bus", "drop", "Y", {"count": 0.0}, 2.0),
        (
            "bus:delay:Z:delay_ms=5,count=10@0.5s",
            "bus",
            "delay",
            "Z",
            {"delay_ms": 5.0, "count": 10.0},
            0.5,
        ),
        ("plc:door_open@2s", "plc", "door_open", None, {}, 2.0),
        ("plc:estop@4s", "plc", "estop_button", None, {}, 4.0),
        ("plc:air_pressure_loss@1s", "plc", "air_pressure_loss", None, {}, 1.0),
        ("plc:estop_chain", "plc", "estop_chain", None, {}, 0.0),
    ],
)
def test_valid_specs_parse(text, target, kind, axis, params, at_s):
    spec = parse_fault_spec(text, AXES)
    assert (spec.target, spec.kind, spec.axis, spec.params) == (target, kind, axis, params)
    assert spec.at_s == pytest.approx(at_s)
    assert str(spec) == text


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("drive:X:bogus@1s", "unknown drive fault 'bogus'"),
        ("plc:flood@1s", "unknown PLC fault 'flood'"),
        ("motor:X:encoder@1s", "unknown target 'motor'"),
        ("drive:Q:encoder@1s", "'Q' is not an axis name"),
        ("drive:A:encoder@1s", "axis A is not on this machine"),
        ("drive:X:encoder@soon", "time 'soon' is not a number"),
        ("drive:X:encoder@-1s", "is not a number"),
        ("drive:X:mains_voltage@1s", "mains_voltage needs volts"),
        ("drive:X:mains_voltage:volts=5000@1s", "outside"),
        ("drive:X:mains_voltage:amps=5@1s", "takes no parameter 'amps'"),
        ("drive:X:mains_voltage:volts=abc@1s", "is not a number"),
        ("drive:X:bus_off@1s", "bus_off is a bus fault: write it as bus:bus_off:X"),
        ("bus:encoder_break:X@1s", "is a drive fault"),
        ("plc:door_open:X@1s", "plc:<kind>@<time>"),
        ("drive:X@1s", "names an axis and a kind"),
    ],
)
def test_bad_specs_are_refused_with_the_reason_and_the_valid_list(text, why):
    with pytest.raises(FaultSpecError) as err:
        parse_fault_spec(text, AXES)
    message = str(err.value)
    assert repr(text) in message
    assert why in message
    assert "valid specs:" in message and "plc:door_open@<t>" in message


def test_valid_specs_cover_every_drive_bus_and_plc_kind():
    from drives.faults import FAULT_KINDS
    from plc.machine_io import FAULTS

    listed = " ".join(valid_specs())
    for kind in (*FAULT_KINDS, *FAULTS):
        assert f":{kind}" in listed


def test_times():
    assert parse_time("1.5s") == 1.5
    assert parse_time("200ms") == pytest.approx(0.2)
    assert parse_time("3") == 3.0


def test_schedule_hands_out_each_spec_once_in_time_order():
    specs = [
        parse_fault_spec(s, AXES)
        for s in ("plc:estop@4s", "drive:X:encoder@1.5s", "plc:door_open@2s")
    ]
    schedule = FaultSchedule(specs)
    assert schedule.due(1.0) == []
    assert [s.kind for s in schedule.due(1.5)] == ["encoder_break"]
    assert schedule.due(1.9) == []
    assert [s.kind for s in schedule.due(10.0)] == ["door_open", "estop_button"]
    assert schedule.due(20.0) == [] and schedule.pending == ()
    # a cycle time that is 2.0 in floating point error still counts as 2.0
    schedule.add(parse_fault_spec("plc:door_open@2s", AXES))
    assert len(schedule.due(0.002 * 1000 - 1e-9)) == 1
