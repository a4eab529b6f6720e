"""The axis group brings drives back after a reboot or a lost line, and watches the cyclic
traffic: fault reset restarts a rebooted drive (NMT reset communication, configuration,
NMT start), a fault the drive raises after the reset stays, an axis whose TPDO1 stops is
reported within its cycle bound, and a drive whose RPDO stops faults on its deadline."""

from __future__ import annotations

import pytest

from drives.master import AxisError
from tests.drives.test_axis_group import Rig


@pytest.fixture
def make():
    made = []

    def build(**kwargs) -> Rig:
        r = Rig(master_node_id=100, **kwargs)
        made.append(r)
        return r.up()

    yield build
    for r in made:
        r.group.close()
        r.hub.close()


def test_fault_reset_restarts_a_power_cycled_drive_and_it_enables_again(make):
    rig = make()
    g = rig.group
    g.cycle()
    rig.drives["X"].power_cycle()
    faults = []
    for _ in range(3):
        faults += g.cycle().faults
    assert ("X", "bootup") in [(f.axis, f.source) for f in faults]
    assert rig.drives["X"].nmt_state == "PRE-OPERATIONAL"  # its PDO mapping is gone
    with pytest.raises(AxisError, match="axis X"):
        g.enable()  # no TPDO from it: it cannot be enabled as it is
    g.fault_reset()
    assert rig.drives["X"].nmt_state == "OPERATIONAL"
    od = rig.drives["X"].slave.od
    assert [od.get(0x1600, 1), od.get(0x1600, 2)] == [0x60400010, 0x607A0020]
    assert g.faults == []  # the master's own boot-up request is not a new fault
    g.enable()
    assert g.state("X") == "OPERATION ENABLED"
    fb = g.cycle({"X": g.position_mm("X") + 0.01})
    assert fb.fresh["X"] and not fb.faults


def test_a_fault_raised_after_the_reset_stays_and_the_statusword_agrees(make):
    """The drive acknowledges the first fault and raises a second one at once (its brake
    chopper failed while it was in FAULT; the brake check reports it as soon as it may): the
    master keeps the second with its EMCY, rather than 'FAULT without an EMCY', and its
    reset needs its own cause gone."""
    rig = make(n_axes=1)
    g = rig.group
    d = rig.drives["X"]
    d.inject("encoder_break")
    for _ in range(3):
        g.cycle()
    d.clear_injection("encoder_break")
    d.inject("chopper_failure")
    for _ in range(60):  # longer than the brake check's period
        g.cycle()
    g.fault_reset()  # 0x7305 acknowledged; 0x7111 follows in the next tick, with its EMCY
    for _ in range(3):
        g.cycle()
    assert [(f.axis, f.emcy_code) for f in g.faults] == [("X", 0x7111)]
    assert not [f for f in g.fault_log if f.source == "statusword"]
    with pytest.raises(AxisError, match=r"in FAULT .*0x603F=0x7111"):
        g.enable()
    d.clear_injection("chopper_failure")
    g.fault_reset()  # its cause is gone: one reset
    g.enable()
    assert g.state("X") == "OPERATION ENABLED"


@pytest.mark.parametrize("fault", ["drop", "corrupt", "delay"])
def test_an_axis_whose_tpdo1_stops_is_reported_within_its_cycles(make, fault):
    rig = make(feedback_timeout_cycles=5)
    g = rig.group
    for _ in range(3):
        g.cycle()
    if fault == "drop":
        rig.hub.drop(0x182, count=None)
    elif fault == "corrupt":
        rig.hub.corrupt(0x182, count=None)
    else:
        rig.hub.delay(0x182, 0.05, count=None)
    t0 = g.time
    got = []
    for _ in range(10):
        got += [f for f in g.cycle().faults if f.source == "feedback"]
        if got:
            break
    assert [(f.axis, f.emcy_code) for f in got] == [("Y", 0x8100)]
    assert got[0].time - t0 <= 5 * 0.002 + 0.002 + 1e-9
    rig.hub.clear_faults()
    for _ in range(40):  # a delayed frame still in flight arrives, then fresh ones
        g.cycle()
    assert [f for f in g.faults if f.source == "feedback"] == []


def test_one_lost_tpdo_is_tolerated(make):
    rig = make(feedback_timeout_cycles=5)
    g = rig.group
    g.cycle()
    rig.hub.drop(0x181, count=1)
    faults = []
    for _ in range(10):
        faults += g.cycle().faults
    assert faults == []


def test_a_drive_whose_rpdo_stops_faults_on_its_deadline(make):
    rig = make(rpdo_deadline_ms=20)
    g = rig.group
    assert rig.drives["Z"].slave.od.get(0x1400, 5) == 20
    for _ in range(3):
        g.cycle()
    rig.hub.drop(0x203, count=None)  # the master's RPDO1 to node 3
    t0 = g.time
    got = []
    for _ in range(30):
        got += [f for f in g.cycle().faults if f.source == "emcy"]
        if got:
            break
    assert [(f.axis, f.emcy_code) for f in got] == [("Z", 0x8250)]
    assert got[0].time - t0 <= 0.020 + 2 * 0.002 + 1e-9
    g.cycle()  # the statusword of the next TPDO1
    assert g.state("Z") == "FAULT"
    rig.hub.clear_faults()
    g.cycle()
    g.fault_reset()
    g.enable()
    assert g.state("Z") == "OPERATION ENABLED"


def test_monitoring_is_off_by_default_and_checked():
    rig = Rig(master_node_id=100)
    try:
        rig.up()
        assert rig.drives["X"].slave.od.get(0x1400, 5) == 0
        with pytest.raises(ValueError, match="rpdo_deadline_ms"):
            Rig(rpdo_deadline_ms=70000)
        with pytest.raises(ValueError, match="feedback_timeout_cycles"):
            Rig(feedback_timeout_cycles=-1)
    finally:
        rig.group.close()
        rig.hub.close()


def test_drives_that_lost_the_master_heartbeat_come_back_with_one_reset(make):
    """The master falls silent (a stalled host): every drive's heartbeat consumer trips
    (0x8130 through 0x6007 = 1, FAULT); once the master runs again one fault reset and an
    enable bring every axis back."""
    rig = make()
    g = rig.group
    for _ in range(5):
        g.cycle()  # the first master heartbeat starts the drives' consumers
    rig.hub.run_for(0.5, 0.002)  # no SYNC, no RPDO, no heartbeat from the master
    fb = g.cycle()
    assert {(f.axis, f.emcy_code) for f in fb.faults} == {(a, 0x8130) for a in "XYZ"}
    for _ in range(60):  # the master's heartbeat is back (every 100 ms)
        g.cycle()
    g.fault_reset()
    g.enable()
    assert all(g.state(a) == "OPERATION ENABLED" for a in "XYZ")
    assert g.faults == []
