"""Request and response bodies of the REST API (pydantic models; the OpenAPI schemas).

Strings that end up in database columns refuse control characters (NUL would break
PostgreSQL, and names with line breaks break logs and tapes); integers that end up in
INTEGER columns are bounded to 32 bits, so a request can never fail inside the database.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import AwareDatetime, BaseModel, BeforeValidator, ConfigDict, Field, StringConstraints

from dnc.tape import MAX_PROGRAM_NUMBER  # O1..O99999999

DbId = Annotated[int, Field(ge=1, le=2**31 - 1)]
Name = Annotated[str, StringConstraints(pattern=r"^[^\x00-\x1f\x7f]*$", max_length=200)]
Text = Annotated[str, StringConstraints(pattern=r"^[^\x00]*$", max_length=4000)]
Tag = Annotated[
    str, StringConstraints(pattern=r"^[^\x00-\x1f\x7f,]+$", min_length=1, max_length=64)
]
MachineKind = Annotated[
    str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]+$", min_length=1, max_length=32)
]
MachineName = Annotated[
    str, StringConstraints(pattern=r"^[A-Za-z0-9_.:-]+$", min_length=1, max_length=64)
]
Comment = Annotated[str, StringConstraints(pattern=r"^[^\x00]*$", max_length=2000)]


def _datetime_text(value: Any) -> Any:
    if value is None or isinstance(value, (str, datetime)):
        return value
    raise ValueError("a date and time is an ISO 8601 string with a UTC offset, not a number")


#: JSON has no datetime: the ISO 8601 string is parsed (lax), anything else refused (a
#: number is no "seconds since 1970" guess)
DateTimeText = Annotated[AwareDatetime, BeforeValidator(_datetime_text), Field(strict=False)]


class _In(BaseModel):
    """Request bodies are strict: JSON `true` is no program number and `"1"` no revision id
    (lax pydantic made them 1). A JSON integer is still a valid float. Only a datetime is
    taken from its JSON string form (JSON has no datetime type)."""

    model_config = ConfigDict(extra="forbid", strict=True)


RevisionKind = Literal["gcode", "apt", "cl"]
KIND_HELP = (
    "gcode (the NC program), apt (APT source) or cl (CL data): apt and cl are posted for "
    "each machine at dispatch. Left out: by the file name's suffix (.apt; .cl .cls "
    ".aptsource .cldata .clf), else gcode"
)
POST_KINDS_HELP = (
    "apt/cl: the machine kinds the source is meant for (trial-posted on upload); left out: "
    "the kind its MACHIN/ statement names, else every kind in the cell"
)


class ProgramCreate(_In):
    """A new program with its first revision (JSON form of the upload)."""

    number: int = Field(ge=1, le=MAX_PROGRAM_NUMBER, description="O number", examples=[1001])
    name: Annotated[Name, Field(min_length=1)]
    text: str = Field(description="the part program (ISO 6983 text)")
    machine_kind: MachineKind = "mill"
    description: Text = ""
    tags: list[Tag] = Field(default_factory=list, max_length=32)
    comment: Comment = ""
    kind: RevisionKind | None = Field(default=None, description=KIND_HELP, examples=["apt"])
    post_kinds: list[MachineKind] = Field(
        default_factory=list, max_length=16, description=POST_KINDS_HELP, examples=[["mill"]]
    )


class RevisionCreate(_In):
    text: str = Field(description="the part program (ISO 6983 text)")
    comment: Comment = ""
    kind: RevisionKind | None = Field(default=None, description=KIND_HELP)
    post_kinds: list[MachineKind] = Field(
        default_factory=list, max_length=16, description=POST_KINDS_HELP
    )


class ReleaseRequest(_In):
    comment: Annotated[Comment, Field(min_length=1, description="approval comment")]


class DispatchRequest(_In):
    revision_id: DbId
    machine: MachineName
    mode: Literal["memory", "drip_feed"] = "memory"
    start: bool = False


class JobCreate(_In):
    revision_id: DbId
    quantity: int = Field(ge=1, le=1_000_000)
    due_at: DateTimeText | None = None
    priority: int = Field(default=0, ge=-1000, le=1000)
    machine_group: MachineName | None = None
    cycle_time_s: float = Field(default=60.0, gt=0, le=1e7, allow_inf_nan=False)


class CheckError(BaseModel):
    line: int | None = None
    col: int | None = None
    message: str
    machine_kind: str | None = None  # an APT/CL revision's trial post for this kind failed


class Program(BaseModel):
    id: int
    number: int
    name: str
    machine_kind: str
    description: str
    tags: list[str]
    created_at: datetime
    released_revision_id: int | None
    latest_revision_id: int | None


class Revision(BaseModel):
    id: int
    program_id: int
    seq: int
    sha256: str
    size: int
    lines: int
    author: str
    comment: str
    source: str
    status: Literal["draft", "released", "obsolete"]
    created_at: datetime
    status_changed_at: datetime | None
    approved_by: str | None
    approval_comment: str | None
    check_ok: bool
    check_errors: list[CheckError]
    kind: RevisionKind = "gcode"
    post_kinds: list[str] = Field(default_factory=list)
    axes: list[str] | None = Field(
        default=None,
        description="G-code: the axes a machine needs to run it (its kind's linear axes and"
        " the rotary axes its blocks move), from the upload check; null for APT/CL sources"
        " (their post_kinds say what they need) and when not known",
    )


class DerivedRevision(BaseModel):
    """The G-code an APT/CL revision was posted to for a machine kind at dispatch."""

    id: int
    source_revision_id: int
    machine_kind: str
    machine: str = Field(description="the machine it was first posted for")
    post_name: str
    post_version: str
    tolerance_mm: float | None = Field(description="5-axis linearisation tolerance T, mm")
    sha256: str
    size: int
    lines: int
    created_at: datetime


class ProgramCreated(BaseModel):
    program: Program
    revision: Revision


class Resource(BaseModel):
    id: int
    kind: str
    code: str
    description: str
    data: dict[str, Any]


class ProgramCall(BaseModel):
    """A call of another program (M98 P, G65 P, G66 P) in a revision, and what it reaches."""

    code: Literal["M98", "G65", "G66"]
    number: int = Field(description="the O number called")
    line: int
    col: int
    program_id: int | None = Field(description="the program called; null: not in the library")
    released_revision_id: int | None = Field(
        description="its released revision, which a dispatch brings along; null: none (a "
        "dispatch is refused)"
    )


class ProgramCaller(BaseModel):
    """A program whose current revision (released, else newest) calls this one."""

    program_id: int
    number: int
    name: str
    revision_id: int
    seq: int
    status: Literal["draft", "released", "obsolete"]
    code: Literal["M98", "G65", "G66"]
    line: int


class ProgramDetail(Program):
    revisions: list[Revision]
    resources: list[Resource]
    calls: list[ProgramCall] = Field(
        description="the programs the current revision (released, else newest) calls"
    )
    called_by: list[ProgramCaller]


class ProgramPage(BaseModel):
    items: list[Program]
    next_cursor: str | None


class Dispatch(BaseModel):
    id: int
    idempotency_key: str
    revision_id: int
    machine: str
    mode: str
    start: bool
    state: Literal["pending", "transferring", "verifying", "starting", "done", "failed"]
    attempts: int
    bytes_sent: int
    verified: bool | None
    error: str | None
    requested_by: str
    created_at: datetime
    updated_at: datetime
    derived_id: int | None = Field(
        default=None, description="an APT/CL revision: the derived revision (posted G-code) sent"
    )


class DispatchPage(BaseModel):
    items: list[Dispatch]
    next_cursor: str | None


class JobNeeds(BaseModel):
    kinds: list[str] = Field(description="the machine kinds its program is for (one of them)")
    axes: list[str] = Field(description="the axes the machine must have (all of them)")


class Job(BaseModel):
    id: int
    revision_id: int
    quantity: int
    done: int
    priority: int
    due_at: datetime | None
    machine_kind: str
    machine_group: str | None
    cycle_time_s: float
    status: Literal["queued", "running", "interrupted", "completed", "cancelled"]
    created_at: datetime
    updated_at: datetime
    needs: JobNeeds | None = Field(
        default=None,
        description="what a machine must be and have to make its parts; the scheduler"
        " allocates only to machines that match (null: a job queued before the host knew)",
    )


class Allocation(BaseModel):
    id: int
    machine: str
    # dnc/allocation.py: dispatched, running, completed, interrupted, rerouted, failed
    status: str
    dispatch_id: int | None
    reason: str | None
    note: str = ""  # an alarm or warning noted while the machine cut on
    rerouted_to: int | None = None  # the allocation that makes this one's part again


class Decision(BaseModel):
    at: datetime
    rule: str
    action: str
    job_id: int | None
    machine: str | None
    reason: str | None


class JobDetail(Job):
    allocations: list[Allocation]
    decisions: list[Decision]


class JobPage(BaseModel):
    items: list[Job]
    next_cursor: str | None


class Machine(BaseModel):
    name: str
    kind: str
    dnc_address: str
    modbus_address: str
    status_address: str
    opcua_address: str | None = Field(
        default=None,
        description="the machine's OPC UA (OPC 40501 MachineTool) endpoint; null when off",
    )
    memory_bytes: int
    dnc_profile: dict[str, Any]
    axes: list[str] | None = Field(
        default=None, description="its configured axes (null: not known to the host)"
    )
    status: dict[str, Any] | None = Field(
        default=None, description="live status from the cell, when the cell provides it"
    )


class Health(BaseModel):
    status: Literal["ok"]
    database: Literal["ok"]
    insecure_open: bool
    faults_enabled: bool


class WhoAmI(BaseModel):
    user: str
    role: Literal["viewer", "operator", "programmer", "admin"]


class EventMessage(BaseModel):
    """One outbox event as sent on the WebSocket (the SSE `data` carries the same JSON)."""

    event_id: int
    at: datetime
    topic: str
    model_config = ConfigDict(extra="allow")
