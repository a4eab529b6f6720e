"""What only the DNC host knows, fed into each in-process machine's OPC UA face: the library
revision (id and sha256) of each program it dispatched to the machine, and the cell's open
jobs with an allocation on it (docs/opcua.md, "Where it runs")."""

from __future__ import annotations

from cnc.faces.opcua import HostData, ProductionJob
from dnc.jobs import OPEN_STATES

# cell job status -> ProductionJobStateMachine state
JOB_STATE = {"queued": "Initializing", "running": "Running", "interrupted": "Interrupted"}
DISPATCHES_SEEN = 50  # the newest dispatches to a machine looked at per refresh


def host_data(library, dispatches, jobs, machine: str) -> HostData:
    revisions: dict[str, str] = {}
    digests: dict[str, str] = {}
    programs: dict[int, str] = {}  # revision id -> O-number name
    for d in dispatches.list(machine=machine, limit=DISPATCHES_SEEN):  # newest first
        if d.state != "done" or d.revision_id in programs:
            continue
        rev = library.get_revision(d.revision_id)
        name = f"O{library.get_program(rev.program_id).number:04d}"
        programs[d.revision_id] = name
        revisions.setdefault(name, str(rev.id))
        digests.setdefault(name, rev.sha256)
    found = []
    for status in OPEN_STATES:
        for job in jobs.list(status=status, limit=500):
            if not any(a["machine"] == machine for a in jobs.allocations(job.id)):
                continue
            if job.revision_id not in programs:
                rev = library.get_revision(job.revision_id)
                programs[job.revision_id] = f"O{library.get_program(rev.program_id).number:04d}"
            found.append(
                ProductionJob(
                    identifier=f"job{job.id}",
                    program=programs[job.revision_id],
                    runs_planned=job.quantity,
                    runs_completed=job.done,
                    parts_completed=job.done,
                    state=JOB_STATE[job.status],
                )
            )
    found.sort(key=lambda j: int(j.identifier[3:]))
    return HostData(revision_by_program=revisions, jobs=tuple(found), sha256_by_program=digests)
