"""Posting at dispatch for a mill5 with the cell's machine configuration: the post takes
the machine's own kinematics and travel (cam.machine5.from_nc_config) and the NC kernel
checks the posted program with the machine's setup; a program beyond a rotary or a linear
limit is refused with the CL line, nothing dispatched."""

from __future__ import annotations

import pytest

from cam.machine5 import MILL5_FILE, from_nc_config, load_mill5
from cnc.config import builtin_machine
from dnc import models as m
from dnc.dispatch import Dispatches
from dnc.library import Library
from dnc.posting import PostRefused

from .conftest import fake_checker
from .test_posting import count, released

# a tilt to B = 60 deg (k = 0.75), then B beyond 90 (k = 0.3, B = 113.6 deg)
CL = """PARTNO TILT 51
MACHIN/MILL5
UNITS/MM
MULTAX/ON
LOADTL/1
RAPID
GOTO/0,0,250,0,0.6614378278,0.75
FEDRAT/800
GOTO/10,0,250,0,0.6614378278,0.75
GOTO/20,0,250,0,0.9539392014,0.3
FINI
"""
STEEP_LINE = 10  # the GOTO whose orientation needs B beyond 90 degrees


def mill5_with(*, b_max: float = 185.0, ext_z: float = 0.0):
    cfg = builtin_machine("mill5")
    axes = dict(cfg.axes)
    axes["B"] = axes["B"].model_copy(update={"max_mm": b_max})
    data = cfg.machine_data.model_copy(
        update={"work_offsets": {**cfg.machine_data.work_offsets, "EXT": [0.0, 0.0, ext_z]}}
    )
    return cfg.model_copy(update={"axes": axes, "machine_data": data})


@pytest.fixture
def lib(sessions):
    machines = {"five1": mill5_with(), "five2": mill5_with(b_max=90.0),
                "five3": mill5_with(ext_z=450.0)}  # fmt: skip

    lib = Library(sessions, checker=fake_checker, machine_configs=lambda n, k: machines.get(n))
    for name in (*machines, "five9"):  # five9: the host has no configuration for it
        lib.register_machine(name, "mill5")
    return lib


def test_the_post_takes_the_nc_machines_kinematics_and_travel():
    nc = builtin_machine("mill5")
    post = from_nc_config(nc)
    shipped = load_mill5(MILL5_FILE)
    assert post == shipped.model_copy(update={"description": nc.description})
    g54 = nc.machine_data.model_copy(update={"work_offsets": {"G54": [10.0, -20.0, 30.0]}})
    moved = from_nc_config(nc.model_copy(update={"machine_data": g54}))
    # the program runs in G54: its travel is the machine's less the offset
    assert (moved.axes.X.min, moved.axes.Y.max, moved.axes.Z.max) == (-510.0, 470.0, 570.0)
    assert moved.axes.C.continuous and moved.axes.B.max == 185.0


def test_a_mill5_within_its_limits_is_posted_and_checked(lib, sessions):
    src = released(lib, CL, kind="cl", number=51)
    assert src.post_kinds == ["mill5"]
    for name in ("five1", "five9"):  # its own configuration, and the shipped machine's
        text = lib.posted_preview(src.id, name).text
        assert "G00 X214.33 Y-87.5 Z162.5 B60." in text and " B113.5782 " in text


def test_beyond_the_machines_own_rotary_limit_is_refused_with_the_cl_line(lib, sessions):
    src = released(lib, CL, kind="cl", number=51)
    with pytest.raises(PostRefused) as err:
        Dispatches(sessions, machine_configs=lib.machine_configs).request(
            key="k", revision_id=src.id, machine="five2"
        )
    assert err.value.detail["line"] == STEEP_LINE and err.value.detail["machine"] == "five2"
    assert "B" in err.value.detail["reason"] and "90" in err.value.detail["reason"]
    assert count(sessions, m.Dispatch) == count(sessions, m.DerivedRevision) == 0


def test_beyond_the_linear_travel_with_the_machines_setup_is_refused_by_the_nc_check(lib, sessions):
    """five3's EXT shift lifts every work offset by 450 mm: the first move's joint Z162.5
    is Z612.5 in machine coordinates, past Z's 600. The post cannot see it (it knows G54); the NC kernel's check
    of the posted program with the machine's setup does, and names the CL line."""
    src = released(lib, CL, kind="cl", number=51)
    with pytest.raises(PostRefused) as err:
        Dispatches(sessions, machine_configs=lib.machine_configs).request(
            key="k", revision_id=src.id, machine="five3"
        )
    d = err.value.detail
    assert d["line"] == 7 and d["machine"] == "five3"  # the first GOTO
    assert d["reason"].startswith("posted block") and "Z" in d["reason"]
    assert count(sessions, m.Dispatch) == count(sessions, m.DerivedRevision) == 0
