"""The simulated machine on its own: outputs in, plant stepped, sensors out."""

from __future__ import annotations

import pytest

from plc.machine_io import FAULTS, MachineIO, MachineParams
from plc.signals import signal

P = MachineParams()


def drive(io: MachineIO, ms: int, **outputs) -> None:
    """Hold `outputs` (signal name -> value) for `ms`, in 10 ms steps."""
    qx, qw = [False] * 1024, [0] * 1024
    for name, value in outputs.items():
        s = signal(name)
        (qx if s.area == "QX" else qw)[s.index] = value
    io.write_outputs(qx, qw, 0)
    for _ in range(ms // 10):
        io.step(10)


def test_spindle_ramp_speed_arrival_and_zero_speed():
    io = MachineIO()
    drive(io, 190, SpindleEnable=True)
    assert not io.input("SpindleDriveReady")
    drive(io, 10, SpindleEnable=True)
    assert io.input("SpindleDriveReady") and io.input("SpindleZeroSpeed")
    run = {"SpindleEnable": True, "SpindleFwd": True, "SpindleSpeedRef": 5000}
    drive(io, 480, **run)
    assert io.state.spindle_rpm == 4800 and not io.input("SpindleAtSpeedFb")
    drive(io, 10, **run)  # 4900: within 2 % of 5000
    assert io.input("SpindleAtSpeedFb") and io.input("SpindleSpeedFb") == 4900
    drive(io, 1000, **run)
    assert io.state.spindle_rpm == 5000
    drive(io, 1000, SpindleEnable=True, SpindleRev=True, SpindleSpeedRef=5000)
    assert io.state.spindle_rpm == -5000 and io.input("SpindleSpeedFb") == -5000
    drive(io, 500, SpindleEnable=True)
    assert io.state.spindle_rpm == 0 and io.input("SpindleZeroSpeed")
    assert not io.input("SpindleAtSpeedFb")


def test_speed_reference_is_limited_to_the_machine_maximum():
    io = MachineIO()
    drive(io, 3000, SpindleEnable=True, SpindleFwd=True, SpindleSpeedRef=20000)
    assert io.state.spindle_rpm == P.spindle_max_rpm


def test_orientation_needs_standstill():
    io = MachineIO()
    drive(io, 500, SpindleEnable=True, SpindleFwd=True, SpindleSpeedRef=1000)
    drive(io, 100, SpindleEnable=True, SpindleOrient=True)  # ramps down in 100 ms
    assert not io.input("SpindleOriented")
    drive(io, P.orient_ms, SpindleEnable=True, SpindleOrient=True)
    assert io.input("SpindleOriented")
    drive(io, 10, SpindleEnable=True)
    assert not io.input("SpindleOriented")


def test_stall_and_drive_faults():
    io = MachineIO()
    io.inject("spindle_stall")
    drive(io, 3000, SpindleEnable=True, SpindleFwd=True, SpindleSpeedRef=4000)
    assert io.state.spindle_rpm == 2000 and not io.input("SpindleAtSpeedFb")
    io.inject("spindle_drive_fault")
    drive(io, 10, SpindleEnable=True, SpindleFwd=True, SpindleSpeedRef=4000)
    assert not io.input("SpindleDriveReady")


def test_carousel_takes_the_short_way_at_its_index_time():
    io = MachineIO()
    drive(io, 600, CarouselGo=True, CarouselTarget=18)  # 1 -> 20 -> 19 -> 18
    assert io.state.carousel_pocket == 18 and io.input("CarouselInPos")
    drive(io, 100, CarouselGo=True, CarouselTarget=19)
    assert not io.input("CarouselInPos") and io.input("CarouselPocket") == 18
    drive(io, 100, CarouselGo=False, CarouselTarget=19)  # stopped between two pockets
    assert not io.input("CarouselInPos")
    drive(io, 100, CarouselGo=True, CarouselTarget=19)
    assert io.input("CarouselInPos") and io.input("CarouselPocket") == 19
    io.inject("carousel_jam")
    drive(io, 2000, CarouselGo=True, CarouselTarget=5)
    assert io.state.carousel_pocket == 19


def _orient(io: MachineIO) -> dict:
    out = {"SpindleEnable": True, "SpindleOrient": True}
    drive(io, P.drive_ready_ms + P.orient_ms + 10, **out)
    assert io.input("SpindleOriented")
    return out


def test_arm_motions_and_the_tool_swap():
    io = MachineIO(MachineParams(tool_in_spindle=5))
    assert io.state.pockets[4] == 0
    drive(io, 400, CarouselGo=True, CarouselTarget=3)
    held = _orient(io)
    for position, ms in P.arm_ms:
        name = "ArmTo" + position.capitalize()
        drive(io, ms - 10, **held, **{name: True})
        assert io.state.arm_position is None, position
        drive(io, 10, **held, **{name: True})
        assert io.input("ArmAt" + position.capitalize()), position
    assert io.state.tool_in_spindle == 3 and io.state.pockets[2] == 5
    assert io.state.crashes == []


def test_arm_crash_and_jams_are_recorded():
    io = MachineIO()
    drive(io, 300, ArmToGrip=True)  # spindle not oriented
    assert io.state.crashes and "not oriented" in io.state.crashes[0]
    io = MachineIO()
    held = _orient(io)
    io.inject("air_pressure_loss")
    drive(io, 1000, **held, ArmToGrip=True)
    assert io.state.arm_position is None and not io.input("AirPressureOk")
    io.clear("air_pressure_loss")
    drive(io, P.arm_time("grip"), **held, ArmToGrip=True)
    assert io.input("ArmAtGrip")
    drive(io, 1000, **held, ArmToGrip=True, ArmToExtract=True)  # two valves: holds
    assert io.input("ArmAtGrip")


def test_door_lock_and_forced_opening():
    io = MachineIO()
    drive(io, 90, DoorLock=True)
    assert io.input("DoorClosedSw") and not io.input("DoorLockedSw")
    drive(io, 10, DoorLock=True)
    assert io.input("DoorLockedSw") and not io.open_door()
    io.inject("door_open")
    assert not io.input("DoorClosedSw") and not io.input("DoorLockedSw")
    io.close_door()
    assert not io.input("DoorClosedSw"), "a forced-open door stays open until cleared"
    io.clear("door_open")
    drive(io, 10)
    assert io.input("DoorClosedSw") and io.open_door() and not io.input("DoorClosedSw")


def test_pumps_estop_and_buttons():
    io = MachineIO()
    drive(io, P.coolant_pressure_ms, CoolantPump=True, LubePump=True)
    assert io.input("CoolantPressureOk") and io.input("LubePressureOk")
    io.inject("coolant_pump_fail")
    io.inject("lube_level_low")
    drive(io, 10, CoolantPump=True, LubePump=True)
    assert not io.input("CoolantPressureOk") and not io.input("LubePressureOk")
    assert not io.input("LubeLevelOk")
    assert io.input("EStopChainOk")
    io.press_estop()
    assert not io.input("EStopChainOk")
    io.release_estop()
    io.inject("estop_chain")
    assert not io.input("EStopChainOk")
    io.press("PanelCycleStart")
    assert io.input("PanelCycleStart")
    io.release("PanelCycleStart")
    assert not io.input("PanelCycleStart")


def test_bad_names_are_refused_clearly():
    io = MachineIO()
    with pytest.raises(ValueError, match="unknown fault 'smoke'"):
        io.inject("smoke")
    with pytest.raises(ValueError, match="unknown fault"):
        io.clear("smoke")
    with pytest.raises(ValueError, match="unknown panel button"):
        io.press("Start")
    with pytest.raises(ValueError, match="not a PLC->field output"):
        io.output("MFinish")
    with pytest.raises(ValueError, match="not a field->PLC input"):
        io.input("SpindleFwd")
    assert set(FAULTS) >= {"door_open", "air_pressure_loss", "estop_button", "changer_jam"}


def test_read_inputs_steps_the_plant_to_the_scan_time():
    io = MachineIO()
    ix, iw = [False] * 1024, [0] * 1024
    qx, qw = [False] * 1024, [0] * 1024
    qx[signal("CarouselGo").index] = True
    qw[signal("CarouselTarget").index] = 2
    io.read_inputs(ix, iw, 1000)
    io.write_outputs(qx, qw, 1000)
    io.read_inputs(ix, iw, 1000 + P.pocket_index_ms)
    assert io.state.time_ms == P.pocket_index_ms
    assert iw[signal("CarouselPocket").index] == 2 and ix[signal("CarouselInPos").index]
    io.nc.set("MStrobe", True)
    io.read_inputs(ix, iw, 1000 + P.pocket_index_ms)
    assert ix[signal("MStrobe").index] and io.state.time_ms == P.pocket_index_ms


def test_every_field_fault_has_a_detection_bound_counted_from_a_known_event():
    """/api/fault-types and the soak read each PLC fault's bound from DETECTION: a fault
    kind added to FAULTS without one would be judged by nothing."""
    from drives.fault_registry import DETECT_FROM
    from plc.machine_io import DETECTION

    assert set(DETECTION) == set(FAULTS)
    for name, (bound, since, how) in DETECTION.items():
        assert bound > 0 and since in DETECT_FROM and how, name


def test_every_field_fault_has_a_recovery_procedure_and_class():
    """Detected is half of it: the operator must also be told how to bring the machine back
    (/api/fault-types `recovery`, docs/recovery.md)."""
    from plc.machine_io import RECOVERY, RECOVERY_CLASS

    assert set(RECOVERY) == set(FAULTS) == set(RECOVERY_CLASS)
    for name, procedure in RECOVERY.items():
        assert "RESET" in procedure or "CYCLE START" in procedure, name
        assert "hom" in procedure, f"{name}: say whether homing is needed"


def test_docs_recovery_lists_every_field_fault_with_its_bound_and_recovery():
    """docs/recovery.md's PLC field fault table says what DETECTION and RECOVERY say, row for
    row, and its class table names each fault in the row of its RECOVERY_CLASS."""
    from pathlib import Path

    from drives.fault_registry import number
    from plc.machine_io import DETECTION, RECOVERY, RECOVERY_CLASS

    doc = (Path(__file__).resolve().parents[2] / "docs" / "recovery.md").read_text()
    for name, (bound, since, how) in DETECTION.items():
        frm = "" if since == "injection" else f" from {since}"
        assert f"| `{name}` | {number(bound)} s{frm} | {how} | {RECOVERY[name]} |" in doc, name
    classes = {
        line.split("|")[1].strip(): line.split("|")[2]
        for line in doc.splitlines()
        if line.startswith("| ") and line.count("|") == 7
    }
    for name, cls in RECOVERY_CLASS.items():
        assert f"`{name}`" in classes.get(cls, ""), f"{name} not in the class row {cls!r}"
