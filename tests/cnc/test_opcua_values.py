"""The machine's status -> the MachineTool instance's values (cnc/faces/opcua/values.py):
the OPC 40001-1 MachineryItemState and MachineryOperationMode, by table."""

from __future__ import annotations

import pytest

from cnc.faces.opcua.values import status_values
from cnc.status import Alarm, MachineStatus

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
