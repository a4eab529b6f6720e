"""The host's data for the OPC UA face in its JSON form (cnc/faces/opcua/host_data.py): the
round trip, and each bad document refused with the JSON pointer of what is wrong."""

from __future__ import annotations

import pytest

from cnc.faces.opcua import FaceUser, HostData, HostDataError, ProductionJob
from cnc.faces.opcua.host_data import MAX_JOBS, MAX_USERS, from_doc, to_doc

JOB = {
    "identifier": "job5",
    "program": "O1001",
    "runs_planned": 4,
    "runs_completed": 1,
    "parts_completed": 1,
    "state": "Running",
}


USER = {"user": "ann", "role": "operator", "key_sha256": "b" * 64}


def test_the_round_trip_keeps_everything():
    data = HostData(
        revision_by_program={"O1001": "12", "O2000": "3"},
        sha256_by_program={"O1001": "a" * 64},
        jobs=(ProductionJob("job5", "O1001", 4, 1, 1, "Running"),),
        users=(FaceUser("ann", "operator", "b" * 64), FaceUser("ann", "admin", "c" * 64)),
    )
    back = from_doc(to_doc(data))
    assert back.jobs == data.jobs
    assert back.users == data.users
    assert [u.role_level for u in back.users] == [2, 4]
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
        ({"users": {}}, "/users", "a list"),
        ({"users": [USER] * (MAX_USERS + 1)}, "/users", f"at most {MAX_USERS}"),
        ({"users": ["ann"]}, "/users/0", "a user object"),
        # a key in clear is never taken: the host sends the digest only
        (
            {"users": [{"user": "ann", "role": "operator", "key": "k" * 20}]},
            "/users/0/key",
            "never the key",
        ),
        ({"users": [{**USER, "key": "k" * 20}]}, "/users/0/key", "never the key"),
        ({"users": [{**USER, "admin": True}]}, "/users/0/admin", "exactly"),
        ({"users": [{**USER, "user": ""}]}, "/users/0/user", "printable"),
        ({"users": [{**USER, "user": "a\nb"}]}, "/users/0/user", "printable"),
        ({"users": [{**USER, "role": "boss"}]}, "/users/0/role", "one of viewer"),
        ({"users": [{**USER, "key_sha256": "B" * 64}]}, "/users/0/key_sha256", "hex"),
        ({"users": [{**USER, "key_sha256": "b" * 63}]}, "/users/0/key_sha256", "hex"),
        ({"users": [USER, {**USER, "user": "bob"}]}, "/users/1/key_sha256", "twice"),
    ],
)
def test_a_bad_document_names_the_field(doc, pointer, why):
    with pytest.raises(HostDataError) as err:
        from_doc(doc)
    assert err.value.pointer == pointer
    assert why in err.value.message
