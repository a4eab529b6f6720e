"""The host's data for the OPC UA face in its JSON form (cnc/faces/opcua/host_data.py): the
round trip, and each bad document refused with the JSON pointer of what is wrong."""

from __future__ import annotations

import pytest

from cnc.faces.opcua import HostData, HostDataError, ProductionJob
from cnc.faces.opcua.host_data import MAX_JOBS, from_doc, to_doc

JOB = {
    "identifier": "job5",
    "program": "O1001",
    "runs_planned": 4,
    "runs_completed": 1,
    "parts_completed": 1,
    "state": "Running",
}


def test_the_round_trip_keeps_everything():
    data = HostData(
        revision_by_program={"O1001": "12", "O2000": "3"},
        sha256_by_program={"O1001": "a" * 64},
        jobs=(ProductionJob("job5", "O1001", 4, 1, 1, "Running"),),
    )
    back = from_doc(to_doc(data))
    assert back.jobs == data.jobs
    assert back.revision_by_program == data.revision_by_program
    assert back.sha256_by_program == {"O1001": "a" * 64, "O2000": ""}


@pytest.mark.parametrize(
    ("doc", "pointer", "why"),
    [
        ([], "/", "an object"),
        ({"jobz": []}, "/jobz", "unknown key"),
        ({"programs": []}, "/programs", "an object"),
        ({"programs": {"O1": "12"}}, "/programs/O1", "revision and sha256 only"),
        ({"programs": {"O1": {"revision": 12}}}, "/programs/O1/revision", "a string"),
        ({"programs": {"O1": {"sha256": "A" * 64}}}, "/programs/O1/sha256", "hex"),
        ({"jobs": {}}, "/jobs", "a list"),
        ({"jobs": [JOB] * (MAX_JOBS + 1)}, "/jobs", f"at most {MAX_JOBS}"),
        ({"jobs": ["job5"]}, "/jobs/0", "a job object"),
        ({"jobs": [{k: v for k, v in JOB.items() if k != "state"}]}, "/jobs/0/state", "exactly"),
        ({"jobs": [{**JOB, "extra": 1}]}, "/jobs/0/extra", "exactly"),
        ({"jobs": [{**JOB, "identifier": "job.5"}]}, "/jobs/0/identifier", "letters"),
        ({"jobs": [{**JOB, "program": ""}]}, "/jobs/0/program", "letters"),
        ({"jobs": [JOB, JOB]}, "/jobs/1/identifier", "twice"),
        ({"jobs": [{**JOB, "state": "Done"}]}, "/jobs/0/state", "one of Initializing"),
        ({"jobs": [{**JOB, "runs_planned": True}]}, "/jobs/0/runs_planned", "an integer"),
        ({"jobs": [{**JOB, "runs_completed": 2**32}]}, "/jobs/0/runs_completed", "an integer"),
        ({"jobs": [{**JOB, "parts_completed": 1.5}]}, "/jobs/0/parts_completed", "an integer"),
    ],
)
def test_a_bad_document_names_the_field(doc, pointer, why):
    with pytest.raises(HostDataError) as err:
        from_doc(doc)
    assert err.value.pointer == pointer
    assert why in err.value.message
