"""The drives' own configuration sections (`drives`, `can`), used without the NC: the
package validates them alone; the machine loader only places their problems."""

from __future__ import annotations

import dataclasses

import pytest
from pydantic import ValidationError

from drives.config import CAN_BITRATES, CanConfig, DrivesConfig
from drives.plant.params import PlantParams


def test_a_drives_section_checks_itself_against_the_machines_axes():
    section = DrivesConfig.model_validate(
        {"axes": {"X": {"node_id": 2}, "Q": {"node_id": 9}}, "plant": {"screw": {"leed": 0.01}}}
    )
    # Y defaults to node 2 (its index + 1), which X already holds
    assert section.problems(("X", "Y", "Z")) == [
        (("axes", "Q"), "no such axis (axes: X Y Z)"),
        (("axes", "Y", "node_id"), "node-ID 2 already used by axis X"),
        (
            ("plant", "screw", "leed"),
            "unknown plant parameter (did you mean 'lead'? known: "
            + ", ".join(f.name for f in dataclasses.fields(PlantParams().screw))
            + ")",
        ),
    ]


@pytest.mark.parametrize(
    ("plant", "reason"),
    [
        ({"screw": {"lead": True}}, "must be a number, got true"),
        ({"encoder": {"counts_per_rev": 1.5}}, "must be an integer, got 1.5"),
        ({"screw": {"lead": "fine"}}, "must be a finite number, got 'fine'"),
    ],
)
def test_plant_override_values_keep_their_type(plant, reason):
    problems = DrivesConfig.model_validate({"plant": plant}).problems(("X",))
    assert [r for _, r in problems] == [reason]


def test_a_valid_section_has_no_problems_and_merges_overrides():
    section = DrivesConfig.model_validate(
        {
            "plant": {"loops": {"kv": 30.0}},
            "axes": {"Z": {"node_id": 7, "plant": {"loops": {"kv": 20.0}}}},
        }
    )
    assert section.problems(("X", "Y", "Z")) == []
    assert section.node_id("Z", 2) == 7 and section.node_id("X", 0) == 1
    assert section.plant_overrides("Z") == {"loops": {"kv": 20.0}}


def test_can_bitrate_is_a_cia301_rate():
    assert CanConfig().problems() == []
    assert all(CanConfig(bitrate=r).problems() == [] for r in CAN_BITRATES)
    ((path, reason),) = CanConfig(bitrate=300_000).problems()
    assert path == ("bitrate",) and reason.startswith("must be one of 10000, 20000")


def test_sections_are_strict():
    with pytest.raises(ValidationError):
        CanConfig.model_validate({"bitrate": "500000"})
    with pytest.raises(ValidationError):
        DrivesConfig.model_validate({"axez": {}})
