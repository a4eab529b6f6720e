"""The status face of rotary machines: degrees, an endless C modulo 360, mill5's tool tip."""

from __future__ import annotations

from cnc.faces.shdr import ShdrFormatter, shdr_items
from cnc.status import AxisStatus, MachineStatus, ToolTipStatus

AXES5 = ("X", "Y", "Z", "B", "C")


def test_mill5_items_add_the_tool_tip_and_its_deviation():
    keys = {i.key: i for i in shdr_items(AXES5, tool_tip=True)}
    assert keys["tip"].type == "PATH_POSITION" and keys["tip"].units == "MILLIMETER_3D"
    assert keys["tip_dev_peak"].sub_type == "MAXIMUM"
    assert keys["Bact"].type == "ANGLE" and keys["Bact"].units == "DEGREE"
    assert "tip" not in {i.key for i in shdr_items(("X", "Y", "Z", "A"))}


def test_mill5_state_reports_tip_and_wraps_the_endless_c():
    fmt = ShdrFormatter(AXES5, tool_tip=True, continuous=("C",))
    status = MachineStatus(
        axes={"B": AxisStatus(30.0, 30.0), "C": AxisStatus(725.5, -10.0)},
        tool_tip=ToolTipStatus((1.5, -2.0, 30.25), 0.00312, 0.00975, 0.02),
    )
    st = fmt.state(status)
    assert st["tip"] == "1.5000 -2.0000 30.2500"
    assert (st["tip_dev"], st["tip_dev_peak"]) == ("0.00312", "0.00975")
    assert (st["Cact"], st["Ccmd"]) == ("5.5000", "350.0000")
    assert st["Bact"] == "30.0000"
    assert fmt.state(MachineStatus())["tip"] == "UNAVAILABLE"


def test_mill5_device_model_has_the_tool_tip_items():
    from mtconnect.model import build_device

    dev = build_device("mill5", AXES5, tool_tip=True)
    assert {"tip", "tip_dev", "tip_dev_peak"} <= set(dev.by_key)
    assert "tip" not in build_device("mill4", ("X", "Y", "Z", "A")).by_key
    tip = dev.by_key["tip"]
    # a three-space sample: 'X Y Z' (ThreeSpaceValueType), exactly three xs:float
    assert tip.accepts("1.5000 -2.0000 30.2500") and tip.accepts("UNAVAILABLE")
    assert not tip.accepts("1.5 -2.0") and not tip.accepts("1.5 -2.0 x")
    assert not tip.accepts("1.5 -2.0 3 4") and not dev.by_key["tip_dev"].accepts("1 2 3")
