"""The machine's status -> the MachineTool instance's values (cnc/faces/opcua/values.py):
the OPC 40001-1 MachineryItemState and MachineryOperationMode, the state machines'
CurrentState Id and Number, and every live value from the status field it follows, by
table."""

from __future__ import annotations

from dataclasses import replace

import pytest

from cnc.faces.opcua import model as m
from cnc.faces.opcua.values import status_values
from cnc.status import Alarm, AxisStatus, MachineStatus

ITEM = "Monitoring.MachineTool.MachineryItemState.CurrentState"
MODE = "Monitoring.MachineTool.MachineryOperationMode.CurrentState"
FAULT = Alarm(3040, "drive fault", source="DRIVE", axis="X")
WARNING = Alarm(1500, "lube level low", source="PLC", severity="WARNING")


@pytest.mark.parametrize(
    ("status", "state"),
    [
        (MachineStatus(execution="ACTIVE"), "Executing"),
        (MachineStatus(execution="READY"), "NotExecuting"),
        (MachineStatus(execution="FEED_HOLD"), "NotExecuting"),
        (MachineStatus(execution="ACTIVE", alarms=(WARNING,)), "Executing"),
        (MachineStatus(execution="STOPPED", alarms=(FAULT,)), "OutOfService"),
        (MachineStatus(emergency_stop="TRIGGERED"), "OutOfService"),
        (MachineStatus(availability="UNAVAILABLE", alarms=(FAULT,)), "NotAvailable"),
    ],
)
def test_the_machinery_item_state(status, state):
    assert status_values(status, 0.0)[ITEM] == state


@pytest.mark.parametrize(
    ("mode", "want"),
    [
        ("AUTOMATIC", "Processing"),
        ("MANUAL_DATA_INPUT", "Processing"),
        ("MANUAL", "Setup"),
        ("EDIT", "Setup"),
    ],
)
def test_the_machinery_operation_mode(mode, want):
    assert status_values(MachineStatus(controller_mode=mode), 0.0)[MODE] == want


# Each row changes one thing of a machine at rest and names every value it must move:
# a value the mapping froze (or mapped from the wrong field) fails its row.
BASE = MachineStatus(execution="READY", program="O0040", mode_detail="AUTO")
MT_KEY = "Monitoring.MachineTool"
CH = "Monitoring.Channel1"
SP = "Monitoring.Spindle"
AP = "Production.ActiveProgram"
LAMP = "Monitoring.Stacklight"


@pytest.mark.parametrize(
    ("change", "power_on_s", "want"),
    [
        ({}, 0.0, {f"{SP}.Speed": 0.0, f"{SP}.IsRotating": False, f"{SP}.Override": 100.0}),
        ({"spindle_speed": 1500.0}, 0.0, {f"{SP}.Speed": 1500.0, f"{SP}.IsRotating": True}),
        ({"spindle_speed": -800.0}, 0.0, {f"{SP}.Speed": -800.0, f"{SP}.IsRotating": True}),
        ({"spindle_speed": 0.2}, 0.0, {f"{SP}.IsRotating": False}),  # encoder noise
        ({"spindle_override": 120.0}, 0.0, {f"{SP}.Override": 120.0}),
        (
            {"feed_override": 70.0},
            0.0,
            {f"{MT_KEY}.FeedOverride": 70.0, f"{CH}.FeedOverride": 70.0},
        ),
        ({"rapid_override": 25.0}, 0.0, {f"{CH}.RapidOverride": 25.0}),
        ({"mode_detail": "AUTO"}, 0.0, {f"{CH}.ChannelMode": 0}),
        ({"mode_detail": "MDI"}, 0.0, {f"{CH}.ChannelMode": 1}),
        ({"mode_detail": "JOG"}, 0.0, {f"{CH}.ChannelMode": 2}),
        ({"mode_detail": "REF"}, 0.0, {f"{CH}.ChannelMode": 6}),
        ({"mode_detail": "EDIT"}, 0.0, {f"{CH}.ChannelMode": 7}),
        ({"controller_mode": "MANUAL"}, 0.0, {f"{MT_KEY}.OperationMode": 0}),
        ({"controller_mode": "AUTOMATIC"}, 0.0, {f"{MT_KEY}.OperationMode": 1}),
        ({"controller_mode": "EDIT"}, 0.0, {f"{MT_KEY}.OperationMode": 2}),
        ({}, 3599.0, {f"{MT_KEY}.PowerOnDuration": 0}),  # whole hours (OPC 40501-1)
        ({}, 7200.0, {f"{MT_KEY}.PowerOnDuration": 2}),
        ({}, 0.0, {f"{LAMP}.Red.SignalOn": False, f"{LAMP}.Yellow.SignalOn": False}),
        ({"alarms": (FAULT,)}, 0.0, {f"{LAMP}.Red.SignalOn": True}),
        ({"emergency_stop": "TRIGGERED"}, 0.0, {f"{LAMP}.Red.SignalOn": True}),
        ({"alarms": (WARNING,)}, 0.0, {f"{LAMP}.Yellow.SignalOn": True}),
        ({"execution": "FEED_HOLD"}, 0.0, {f"{LAMP}.Yellow.SignalOn": True}),
        ({"execution": "ACTIVE"}, 0.0, {f"{LAMP}.Green.SignalOn": True}),
        ({}, 0.0, {f"{AP}.Number": 40, f"{AP}.Name": "O0040"}),
        ({"program": "O1234"}, 0.0, {f"{AP}.Number": 1234}),
        ({"program": "MDI"}, 0.0, {f"{AP}.Number": 0}),
        ({"part_count": 7}, 0.0, {f"{AP}.PartCount": 7}),
        ({"line": 30}, 0.0, {f"{AP}.Line": 30, f"{CH}.Line": 30}),
        (
            {"axes": {"X": AxisStatus(actual=-12.5), "Z": AxisStatus(actual=3.0)}},
            0.0,
            {f"{CH}.X.ActualPosition": -12.5, f"{CH}.Z.ActualPosition": 3.0},
        ),
        ({"path_feed_rate": 2500.0}, 0.0, {f"{CH}.PathFeedRate": 2500.0}),
    ],
)
def test_each_live_value_follows_its_status_field(change, power_on_s, want):
    got = status_values(replace(BASE, **change), power_on_s)
    assert {k: got[k] for k in want} == want


@pytest.mark.parametrize(
    ("execution", "alarms", "state"),
    [
        ("READY", (), "Initializing"),
        ("ACTIVE", (), "Running"),
        ("PROGRAM_COMPLETED", (), "Ended"),
        ("FEED_HOLD", (), "Interrupted"),
        ("STOPPED", (FAULT,), "Aborted"),
    ],
)
def test_the_program_states_current_state_with_its_id_and_number(execution, alarms, state):
    got = status_values(replace(BASE, execution=execution, alarms=alarms), 0.0)
    node, number = m.PROGRAM_STATES[state]
    assert got[f"{AP}.State.CurrentState"] == state
    assert got[f"{AP}.State.CurrentState.Id"] == node
    assert got[f"{AP}.State.CurrentState.Number"] == number


def test_the_machinery_state_machines_show_their_states_id_and_number():
    got = status_values(replace(BASE, execution="ACTIVE", controller_mode="MANUAL"), 0.0)
    assert got[f"{ITEM}.Id"] == m.MACHINERY_ITEM_STATES["Executing"][0]
    assert got[f"{ITEM}.Number"] == 3
    assert got[f"{MODE}.Id"] == m.MACHINE_OPERATION_MODES["Setup"][0]
    assert got[f"{MODE}.Number"] == 2
