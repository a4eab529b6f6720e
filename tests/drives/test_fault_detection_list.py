"""Every injectable drive and bus fault states how it is detected (and within which bound)
or why it is not, and how the machine recovers: the fault list the REST API publishes."""

from drives.faults import DETECTION, FAULT_KINDS, RECOVERY, describe


def test_every_fault_kind_states_its_detection_and_recovery():
    assert set(DETECTION) == set(FAULT_KINDS)
    assert set(RECOVERY) == set(FAULT_KINDS)
    for row in describe():
        assert row["detection"] and row["recovery"], row["kind"]


def test_backlash_is_documented_as_undetectable_with_the_reason():
    assert "UNDETECTABLE BY DESIGN" in DETECTION["backlash"]
    assert "second (linear) encoder" in DETECTION["backlash"]
