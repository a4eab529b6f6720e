"""What only the DNC host knows, fed into each machine's OPC UA face: the library revision
(id and sha256) of each program it dispatched to the machine, the cell's open jobs with
an allocation on it, and the cell's users (API keys as sha256 digests, with their roles)
for a secured face (docs/opcua.md, "Where it runs", "Security"). Back come the method calls the face's
clients made (Start, Stop, Acknowledge, refused writes), for the host's audit log.

A machine in this process gets them by a direct call; a machine in its own process (or on
another host) through its DNC port (`HOST PUT`), authenticated with the port's shared
secret like every other operation the host makes there."""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

from cnc.faces.opcua import FaceUser, HostData, ProductionJob
from cnc.faces.opcua.host_data import to_doc
from dnc.jobs import OPEN_STATES

log = logging.getLogger(__name__)

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
            mine = [a for a in jobs.allocations(job.id) if a["machine"] == machine]
            if not mine:
                continue
            # an allocation is one run of the program making one part (dnc/allocation.py):
            # the machine's job counts its own, the job's quantity is the plan's
            completed = sum(1 for a in mine if a["status"] == "completed")
            if job.revision_id not in programs:
                rev = library.get_revision(job.revision_id)
                programs[job.revision_id] = f"O{library.get_program(rev.program_id).number:04d}"
            found.append(
                ProductionJob(
                    identifier=f"job{job.id}",
                    program=programs[job.revision_id],
                    runs_planned=job.quantity,
                    runs_completed=completed,
                    parts_completed=completed,
                    state=JOB_STATE[job.status],
                )
            )
    found.sort(key=lambda j: int(j.identifier[3:]))
    return HostData(revision_by_program=revisions, jobs=tuple(found), sha256_by_program=digests)


class OpcUaFeed:
    """The host loop's step (`tick`, every second): each machine with an OPC UA face gets
    the host's data, and the calls its clients made go to the audit log as
    `machine.command` (done) or `machine.command_refused`, the actor being the OPC UA
    user, as the REST commands are recorded."""

    def __init__(
        self,
        library,
        dispatches,
        jobs,
        links: Mapping,
        client: Callable[[str], object],
        users: Callable[[], tuple[FaceUser, ...]] | None = None,
    ) -> None:
        """`client(name)`: a DncClient for the machine's DNC port (with its secret);
        `users()`: the cell's OPC UA users (server.cell.OpcUaUsers.records)."""
        self.library, self.dispatches, self.jobs = library, dispatches, jobs
        self.links, self.client = links, client
        self.users = users
        self.unreachable: dict[str, str] = {}  # machine -> why the last exchange failed

    def tick(self) -> None:
        users = self.users() if self.users is not None else ()
        for name, link in self.links.items():
            if not link.ports.get("opcua"):
                continue
            data = host_data(self.library, self.dispatches, self.jobs, name)
            data.users = users
            try:
                commands = self._exchange(name, link, data)
            except Exception as exc:  # noqa: BLE001 - one machine down must not stop the rest
                if self.unreachable.get(name) != str(exc):
                    log.info("OPC UA host data for %s not delivered: %s", name, exc)
                self.unreachable[name] = str(exc)
                continue
            self.unreachable.pop(name, None)
            for command in commands:
                self._audit(name, command)

    def _exchange(self, name: str, link, data: HostData) -> list[dict]:
        face = getattr(link.local, "opcua", None)
        if face is not None:
            face.set_host_data(data)
            return [vars(c) for c in face.take_commands()]
        with self.client(name) as client:
            return list(client.host_data(to_doc(data)).get("commands", []))

    def _audit(self, name: str, command: dict) -> None:
        detail = {"command": str(command.get("command", "")), "face": "opcua"}
        detail["detail"] = str(command.get("detail", ""))
        action = "machine.command"
        if command.get("result") != "done":
            action = "machine.command_refused"
            detail["reason"] = str(command.get("result", ""))
        actor = str(command.get("user") or "anonymous")
        self.library.note_transfer(name, action, actor=actor, **detail)
