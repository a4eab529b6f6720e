"""Pure: a `MachineStatus` snapshot -> the values of the MachineTool instance's variables.

The OPC UA face writes what this returns, keyed by the variable's path under the machine
(`Monitoring.Channel1.ChannelState`). Enumerations are their Int32 values (OPC 40501-1).
"""

from __future__ import annotations

from cnc.faces.opcua import model as m
from cnc.status import MachineStatus

_STATE = {n: i for i, n in enumerate(m.CHANNEL_STATE.fields)}
_OPERATION = {n: i for i, n in enumerate(m.MACHINE_OPERATION_MODE.fields)}
_CHANNEL_MODE = {n: i for i, n in enumerate(m.CHANNEL_MODE.fields)}
_COLOR = {n: i for i, n in enumerate(m.SIGNAL_COLOR.fields)}

# MTConnect execution -> ChannelState (Reset: no program in progress)
CHANNEL_STATE_OF = {
    "ACTIVE": "Active",
    "INTERRUPTED": "Interrupted",
    "FEED_HOLD": "Interrupted",
    "STOPPED": "Interrupted",
    "OPTIONAL_STOP": "Interrupted",
    "PROGRAM_STOPPED": "Interrupted",
    "READY": "Reset",
    "PROGRAM_COMPLETED": "Reset",
}
# MTConnect execution -> ProductionProgramStateMachine state
PROGRAM_STATE_OF = {
    "ACTIVE": "Running",
    "INTERRUPTED": "Interrupted",
    "FEED_HOLD": "Interrupted",
    "STOPPED": "Interrupted",
    "OPTIONAL_STOP": "Interrupted",
    "PROGRAM_STOPPED": "Interrupted",
    "READY": "Initializing",
    "PROGRAM_COMPLETED": "Ended",
}
OPERATION_MODE_OF = {
    "AUTOMATIC": "Automatic",
    "MANUAL_DATA_INPUT": "Automatic",
    "MANUAL": "Manual",
    "EDIT": "Setup",
}
CHANNEL_MODE_OF = {
    "AUTO": "Automatic",
    "MDI": "MdaMdi",
    "JOG": "JogManual",
    "REF": "Reference",
    "EDIT": "Other",
}
# controller mode -> OPC 40001-1 MachineryOperationMode (Processing: the machine produces
# or is set to produce; Setup: an operator sets it up by hand)
MACHINERY_OPERATION_MODE_OF = {
    "AUTOMATIC": "Processing",
    "MANUAL_DATA_INPUT": "Processing",
    "MANUAL": "Setup",
    "EDIT": "Setup",
}
#: the stack light's three lamps, top to bottom (NumberInList 0..2)
STACK_LAMPS = (("Red", "Red"), ("Yellow", "Yellow"), ("Green", "Green"))
ROTATING_RPM = 0.5  # below this the spindle is standing (encoder noise)


def program_number(name: str) -> int:
    """O1234 -> 1234; a name without a number (MDI, a drip-feed) -> 0."""
    digits = name[1:] if name[:1] in ("O", "o") else ""
    return int(digits) if digits.isdigit() else 0


def current_state(
    prefix: str, states: dict[str, tuple[m.NodeRef, int]], state: str
) -> dict[str, object]:
    """A state machine's CurrentState with its Id (the state's node, as a NodeRef the face
    resolves to a NodeId) and Number (the StateNumber)."""
    node, number = states[state]
    return {
        f"{prefix}.CurrentState": state,
        f"{prefix}.CurrentState.Id": node,
        f"{prefix}.CurrentState.Number": number,
    }


def status_values(status: MachineStatus, power_on_s: float) -> dict[str, object]:
    faults = any(a.severity == "FAULT" for a in status.alarms)
    warnings = any(a.severity == "WARNING" for a in status.alarms)
    program_state = PROGRAM_STATE_OF[status.execution]
    if faults and status.execution != "ACTIVE" and status.program:
        program_state = "Aborted"
    lamps = {
        "Red": faults or status.emergency_stop == "TRIGGERED",
        "Yellow": warnings or CHANNEL_STATE_OF[status.execution] == "Interrupted",
        "Green": status.execution == "ACTIVE",
    }
    if status.availability != "AVAILABLE":
        item_state = "NotAvailable"
    elif faults or status.emergency_stop == "TRIGGERED":
        item_state = "OutOfService"  # 40501 Annex B: an alarm of severity >= 667 (FAULT: 800)
    else:
        item_state = "Executing" if status.execution == "ACTIVE" else "NotExecuting"
    out: dict[str, object] = {
        **current_state(
            "Monitoring.MachineTool.MachineryItemState", m.MACHINERY_ITEM_STATES, item_state
        ),
        **current_state(
            "Monitoring.MachineTool.MachineryOperationMode",
            m.MACHINE_OPERATION_MODES,
            MACHINERY_OPERATION_MODE_OF[status.controller_mode],
        ),
        "Monitoring.MachineTool.OperationMode": _OPERATION[
            OPERATION_MODE_OF[status.controller_mode]
        ],
        "Monitoring.MachineTool.PowerOnDuration": int(power_on_s // 3600),  # hours (40501)
        "Monitoring.MachineTool.FeedOverride": float(status.feed_override),
        "Monitoring.Channel1.ChannelState": _STATE[CHANNEL_STATE_OF[status.execution]],
        "Monitoring.Channel1.ChannelMode": _CHANNEL_MODE[CHANNEL_MODE_OF[status.mode_detail]],
        "Monitoring.Channel1.FeedOverride": float(status.feed_override),
        "Monitoring.Channel1.RapidOverride": float(status.rapid_override),
        "Monitoring.Channel1.Line": int(status.line),
        "Monitoring.Channel1.PathFeedRate": float(status.path_feed_rate),
        "Monitoring.Spindle.IsRotating": abs(status.spindle_speed) >= ROTATING_RPM,
        "Monitoring.Spindle.Override": float(status.spindle_override),
        "Monitoring.Spindle.Speed": float(status.spindle_speed),
        "Production.ActiveProgram.Name": status.program,
        "Production.ActiveProgram.Number": program_number(status.program),
        "Production.ActiveProgram.Line": int(status.line),
        **current_state("Production.ActiveProgram.State", m.PROGRAM_STATES, program_state),
        "Production.ActiveProgram.PartCount": int(status.part_count),
    }
    for name, _color in STACK_LAMPS:
        out[f"Monitoring.Stacklight.{name}.SignalOn"] = lamps[name]
    for axis, ax in status.axes.items():
        out[f"Monitoring.Channel1.{axis}.ActualPosition"] = float(ax.actual)
    return out


def color(name: str) -> int:
    return _COLOR[name]
