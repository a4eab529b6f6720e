"""The controller owns its machine data: G10 outlives the program, G43/G41 on a running
machine read the table, the operator's input is refused in cycle, the machine keeps it in
its state directory across restarts."""

from __future__ import annotations

import json

import pytest

from cnc.controller import CommandRefused
from cnc.machine_data import MachineData, MachineDataError, ToolData
from tests.cnc.test_controller import Rig

SET_OFFSETS = """%
O1001
G90 G10 L2 P2 X-100 Y-50 Z-200
G10 L10 P7 R-120
M30
%
"""
USE_OFFSETS = """%
O1002
G90 G55 G0 X0 Y0
G43 H7 Z10
M30
%
"""
LONG = """%
O1003
G90 G0 X-10 Y-10 Z-10
G1 X-300 F600
M30
%
"""


def _rig(**kw) -> Rig:
    rig = Rig(programs={1001: SET_OFFSETS, 1002: USE_OFFSETS, 1003: LONG}, **kw)
    rig.home()
    return rig


def test_g10_in_one_program_is_seen_by_the_next() -> None:
    rig = _rig(machine_data=MachineData())
    rig.run_program(1001)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    md = rig.ctl.machine_data
    assert md.work_offsets[2] == (-100.0, -50.0, -200.0)
    assert md.tools[7].length == -120.0
    rig.run_program(1002)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    # G55 X0 Y0, then G43 H7 Z10: Z = -200 + 10 - 120
    assert (rig.pos("X"), rig.pos("Y"), rig.pos("Z")) == pytest.approx((-100.0, -50.0, -310.0))


def test_g43_h7_on_a_running_machine_uses_tool_7s_length() -> None:
    md = MachineData({7: ToolData(length=-80.0, length_wear=-0.5)}, {2: (-100.0, -50.0, -200.0)})
    rig = _rig(machine_data=md)
    rig.run_program(1002)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert rig.pos("Z") == pytest.approx(-200.0 + 10.0 - 80.5)


def test_machine_data_comes_from_the_config_section() -> None:
    from cnc.config import builtin_machine
    from cnc.controller import Controller
    from cnc.program_memory import ProgramMemory

    cfg = builtin_machine("mill3")
    ctl = Controller(cfg, ProgramMemory(4096))
    assert ctl.machine_data == cfg.machine_data.initial()
    assert ctl.machine_data.work_offsets[1] == (-300.0, -200.0, -300.0)
    assert Controller(Rig().config, ProgramMemory(4096)).machine_data == MachineData()


def test_operator_input_refused_in_cycle_and_validated() -> None:
    rig = _rig(machine_data=MachineData())
    rig.cmd("select_program", number=1003)
    rig.cmd("cycle_start")
    rig.until(lambda: rig.ctl.execution == "ACTIVE", 5)
    before = rig.ctl.machine_data.to_dict()
    with pytest.raises(CommandRefused, match="in cycle|ACTIVE"):
        rig.ctl.put_machine_data("tools", {"1": {"length": 5.0}})
    rig.until(lambda: rig.ctl.execution == "PROGRAM_COMPLETED", 60)
    with pytest.raises(MachineDataError) as ei:
        rig.ctl.put_machine_data("tools", {"1": {"length": 5.0}, "2": {"radius": "x"}})
    assert ei.value.pointer == "/2/radius"
    assert rig.ctl.machine_data.to_dict() == before
    rig.ctl.put_machine_data("offsets", {"work_offsets": {"G54.1P3": [1, 2, 3]}})
    assert rig.ctl.machine_data.work_offsets[9] == (1.0, 2.0, 3.0)


def test_tool_change_counts_a_use_and_feed_moves_its_cutting_time() -> None:
    prog = "%\nO1004\nT3 M6\nG90 G0 X-10 Y-10 Z-10\nG1 X-110 F3000\nT4 M6\nM30\n%\n"
    md = MachineData({3: ToolData(life_uses=5), 4: ToolData()})
    rig = Rig(programs={1004: prog}, machine_data=md)
    rig.home()
    rig.run_program(1004)
    t3, t4 = md.tools[3], md.tools[4]
    assert (t3.uses, t4.uses) == (1, 1)
    # 100 mm at 3000 mm/min: 2 s, a little more with the ramps
    assert 1.9 < t3.cut_time_s < 2.5 and t4.cut_time_s == 0.0
    assert rig.ctl.cutting_time == pytest.approx(t3.cut_time_s)


def test_machine_keeps_machine_data_across_restarts(tmp_path) -> None:
    from cnc.config import builtin_machine
    from cnc.machine import Machine

    cfg = builtin_machine("mill3")
    m = Machine(cfg, "m1", ideal=True, state_dir=str(tmp_path))
    try:
        path = tmp_path / "m1.machine-data.json"
        assert json.loads(path.read_text())["tools"] == m.controller.machine_data.tools_dict()
        m.controller.put_machine_data("tools", {"7": {"length": 123.0}})
        m.step(m.plc_every)  # saved at the next scan boundary, out of cycle
        assert json.loads(path.read_text())["tools"]["7"]["length"] == 123.0
        m.controller.put_machine_data("offsets", {"work_offsets": {"G56": [1, 2, 3]}})
    finally:
        m.close()  # saves what changed since
    m2 = Machine(cfg, "m1", ideal=True, state_dir=str(tmp_path))
    try:
        md = m2.controller.machine_data
        assert md.tools[7].length == 123.0 and md.work_offsets[3] == (1.0, 2.0, 3.0)
    finally:
        m2.close()


@pytest.mark.parametrize(
    "section,key,fragment",
    [
        ({"work_offsets": {"G60": [0.0, 0.0, 0.0]}}, "machine_data.work_offsets.G60", "G60"),
        ({"work_offsets": {"G54": [0.0, 0.0]}}, "machine_data.work_offsets.G54", "[x, y, z]"),
        ({"tools": {1000: {"length": 1.0}}}, "machine_data.tools.1000", "1 .. 999"),
        ({"tools": {1: {"length": 5000.0}}}, "machine_data.tools.1.length", "within"),
        ({"tools": {1: {"lenght": 1.0}}}, "machine_data.tools.1.lenght", ""),
        ({"power_on_units": "cm"}, "machine_data.power_on_units", ""),
    ],
)
def test_config_machine_data_errors_name_the_key(section, key, fragment) -> None:
    from cnc.config import ConfigError, load_machine_config

    with pytest.raises(ConfigError) as ei:
        load_machine_config({"machines": {"m": {"base": "mill3", "machine_data": section}}})
    text = str(ei.value)
    assert f"machines.m.{key}" in text and fragment in text, text


# --- Macro B variables kept across power cycles (#500-#999) and across programs (#100) ---

SET_VARIABLES = """%
O1004
#500 = -42.5
#100 = 7
M30
%
"""
USE_VARIABLES = """%
O1005
G90 G0 X#500 Y-[#100]
M30
%
"""


def test_macro_variables_500_and_100_outlive_their_program() -> None:
    rig = Rig(programs={1004: SET_VARIABLES, 1005: USE_VARIABLES}, machine_data=MachineData())
    rig.home()
    rig.run_program(1004)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert dict(rig.ctl.machine_data.macro_variables) == {500: -42.5}
    rig.run_program(1005)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert (rig.pos("X"), rig.pos("Y")) == pytest.approx((-42.5, -7.0))


def test_kept_variables_are_saved_with_the_machine_data_and_checked() -> None:
    md = MachineData()
    before = md.revision
    md.macro_variables[999] = 1.25
    assert md.revision > before
    assert md.to_dict()["macro_variables"] == {"999": 1.25}
    again = MachineData.from_dict(json.loads(json.dumps(md.to_dict())))
    assert dict(again.macro_variables) == {999: 1.25} and again == md
    assert dict(md.copy().macro_variables) == {999: 1.25}
    for number, value, fragment in [
        (100, 1.0, "#500-#999"),
        (1000, 1.0, "#500-#999"),
        (500, float("nan"), "finite"),
        (500, True, "number"),
    ]:
        with pytest.raises(MachineDataError, match=fragment) as err:
            md.macro_variables[number] = value
        assert err.value.pointer == f"/macro_variables/{number}"
    with pytest.raises(MachineDataError) as err:
        MachineData.from_dict({"macro_variables": {"500": 1.0, "77": 2.0}})
    assert err.value.pointer == "/macro_variables/77"


PART = "%\nO0100\nG90 G0 X-100 Y-100 Z-20\nM30\n%\n"


class _CountOnDisk:
    """An SHDR face that checks, at each publish, that the count it shows is on disk."""

    def __init__(self, path) -> None:
        self.path, self.published = path, []

    def publish(self, status, timestamp) -> None:
        kept = json.loads(self.path.read_text())["part_count"] if self.path.exists() else 0
        assert kept == status.part_count, (kept, status.part_count)
        self.published.append(status.part_count)


def test_machine_keeps_its_part_counter_across_restarts(tmp_path) -> None:
    """A part counted at M30 is on disk before any face reports it, and a machine started
    again on the same state directory counts on from there (a process killed just after a
    part is not made to count it again)."""
    from cnc.config import builtin_machine
    from cnc.machine import Machine

    cfg = builtin_machine("mill3")
    path = tmp_path / "m1.counters.json"
    m = Machine(cfg, "m1", ideal=True, state_dir=str(tmp_path))
    try:
        assert m.controller.part_count == 0 and not path.exists()  # a new machine
        m.shdr = face = _CountOnDisk(path)
        m.power_on()
        m.command("mode", mode="AUTO")
        number = m.load_program(PART)
        m.command("select_program", number=number)
        for part in (1, 2):
            m.press("PanelCycleStart")
            assert m.run_until(lambda mm, n=part: mm.controller.part_count == n, 60)
            m.step(2 * m.plc_every)
        assert m.controller.part_count == 2 and face.published[-1] == 2
        assert json.loads(path.read_text()) == {"part_count": 2}
    finally:
        m.shdr = None
        m.close()
    # as after a kill: nothing but the state directory carried over
    m2 = Machine(cfg, "m1", ideal=True, state_dir=str(tmp_path))
    try:
        assert m2.controller.part_count == 2
        assert m2.step(1).part_count == 2  # what its faces report from the first cycle on
    finally:
        m2.close()


@pytest.mark.parametrize(
    "text,where",
    [
        ('{"part_count": -1}', "/part_count: must be an integer >= 0, got -1"),
        ('{"part_count": 1.5}', "/part_count: must be an integer >= 0, got 1.5"),
        ('{"part_count": true}', "/part_count: must be an integer >= 0, got True"),
        ("[3]", "/: must be an object, got list"),
        ('{"part_count": 3', "1:17: not JSON"),
    ],
)
def test_a_damaged_part_counter_file_stops_the_machine_saying_where(tmp_path, text, where):
    from cnc.config import builtin_machine
    from cnc.errors import NcError
    from cnc.machine import Machine

    (tmp_path / "m1.counters.json").write_text(text)
    with pytest.raises(NcError) as err:
        Machine(builtin_machine("mill3"), "m1", ideal=True, state_dir=str(tmp_path))
    assert str(tmp_path / "m1.counters.json") in str(err.value)
    assert where in str(err.value)
