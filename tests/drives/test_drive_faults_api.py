"""drives.faults: one injection API by axis name, seen by the axis group as AxisFaults."""

from __future__ import annotations

import json

import pytest

from drives import VirtualDrive
from drives.bus import CanHub
from drives.cia402 import INJECT_KINDS
from drives.faults import FAULT_KINDS, FaultInjector, describe
from drives.master import AxisConfig, AxisGroup


@pytest.fixture
def cell():
    hub = CanHub()
    drives = {n: VirtualDrive(i + 1, hub.endpoint(n), substep=1e-3) for i, n in enumerate("XY")}
    group = AxisGroup(hub.endpoint("m"), [AxisConfig(n, i + 1) for i, n in enumerate("XY")])
    group.boot()
    group.configure()
    group.enable()
    yield hub, drives, group, FaultInjector(drives)
    hub.close()


def test_catalogue_covers_every_drive_injection_and_is_json():
    assert set(INJECT_KINDS) <= set(FAULT_KINDS)
    assert {"drop", "corrupt", "delay", "bus_off", "babble", "power_cycle"} <= set(FAULT_KINDS)
    data = json.loads(json.dumps(describe(), default=str))
    mains = next(k for k in data if k["kind"] == "mains_voltage")
    assert mains["params"][0]["name"] == "volts" and mains["target"] == "drive"


@pytest.mark.parametrize(
    ("axis", "kind", "params", "error", "match"),
    [
        ("Q", "blocked", {}, KeyError, "unknown axis 'Q'"),
        ("X", "gremlins", {}, ValueError, "unknown fault kind"),
        ("X", "mains_voltage", {}, ValueError, "volts .* is required"),
        ("X", "mains_voltage", {"volts": -5}, ValueError, "outside"),
        ("X", "blocked", {"force": 1}, ValueError, "unknown parameter"),
        ("X", "load_force", {"newtons": "a lot"}, ValueError, "must be a number"),
    ],
)
def test_bad_requests_are_named(cell, axis, kind, params, error, match):
    inj = cell[3]
    with pytest.raises(error, match=match):
        inj.inject(axis, kind, **params)


def test_drive_fault_reaches_the_master_then_clears(cell):
    hub, drives, group, inj = cell
    inj.inject("Y", "encoder_break")
    faults = []
    for _ in range(5):
        faults += group.cycle().faults
    assert [(f.axis, f.emcy_code) for f in faults] == [("Y", 0x7305)]
    assert ("Y", "encoder_break") in inj.active
    inj.clear("Y", "encoder_break")
    group.fault_reset()
    group.enable()
    assert group.state("Y") == "OPERATION ENABLED"


def test_bus_fault_drop_makes_feedback_stale_and_clear_restores(cell):
    hub, drives, group, inj = cell
    inj.inject("X", "drop", count=0)  # 0 = until cleared
    fb = group.cycle()
    assert fb.fresh == {"X": False, "Y": True}
    inj.clear("X", "drop")
    assert group.cycle().fresh == {"X": True, "Y": True}


def test_corrupt_and_delay_tpdo(cell):
    hub, drives, group, inj = cell
    inj.inject("Y", "corrupt", count=1)
    assert group.cycle().fresh["Y"] is False
    assert hub.error_frames == 1
    assert group.cycle().fresh["Y"] is True
    inj.inject("Y", "delay", delay_ms=5.0, count=1)
    assert group.cycle().fresh["Y"] is False


def test_bus_off_leads_to_heartbeat_loss(cell):
    hub, drives, group, inj = cell
    inj.inject("X", "bus_off")
    faults = []
    for _ in range(200):
        faults += group.cycle().faults
    assert ("X", "heartbeat") in {(f.axis, f.source) for f in faults}
    inj.clear("X", "bus_off")
    assert not drives["X"].bus.bus_off


def test_power_cycle_is_seen_as_a_boot_up(cell):
    hub, drives, group, inj = cell
    inj.inject("X", "power_cycle")
    fb = group.cycle()
    assert [(f.axis, f.source) for f in fb.faults] == [("X", "bootup")]
    assert drives["X"].state_name == "SWITCH ON DISABLED"  # rebooted: disabled, unreferenced
    assert not drives["X"].drive.homed


def test_babble_starves_the_line(cell):
    hub, drives, group, inj = cell
    inj.inject("X", "babble", can_id=0x001)
    fb = group.cycle()
    assert not fb.all_fresh
    inj.clear_all()
    assert inj.active == {}
    for _ in range(3):
        fb = group.cycle()
    assert fb.all_fresh
