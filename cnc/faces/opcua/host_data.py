"""What only the DNC host knows about a machine (the library revision it dispatched, the
cell's jobs on the machine, the cell's users for a secured face), and what the OPC UA face did for its clients that the host
audits (method calls). Pure: the records and their JSON form on the DNC port's `HOST PUT`
(docs/dnc_port.md), checked field by field with the JSON pointer of what is wrong."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from cnc.errors import CncError

#: ProductionJobStateMachine states a host may give a job (OPC 40501-1)
JOB_STATES = ("Initializing", "Running", "Interrupted", "Ended", "Aborted")
MAX_JOBS = 500  # one machine's plan; more is a host bug, not a plan
#: the cell's roles, lowest first (web_api.settings.Role: viewer 1 .. admin 4)
ROLES = ("viewer", "operator", "programmer", "admin")
MAX_USERS = 1000  # API keys of one cell; more is a host bug


@dataclass(frozen=True)
class ProductionJob:
    """A cell job as the host sees it (OPC 40501 ProductionJob)."""

    identifier: str
    program: str
    runs_planned: int
    runs_completed: int
    parts_completed: int
    state: str  # one of JOB_STATES


@dataclass(frozen=True)
class FaceUser:
    """One of the cell's API keys as an OPC UA user: user name, cell role (one of ROLES)
    and the sha256 of the key (the password), never the key itself."""

    user: str
    role: str
    key_sha256: str

    @property
    def role_level(self) -> int:
        return ROLES.index(self.role) + 1


@dataclass
class HostData:
    """What only the DNC host knows: the dispatched revision of each program, the cell's
    jobs on this machine and the cell's users (for a secured face that has no user source
    of its own). Replaced as a whole (`OpcUaFace.set_host_data`)."""

    revision_by_program: dict[str, str] = field(default_factory=dict)
    jobs: tuple[ProductionJob, ...] = ()
    sha256_by_program: dict[str, str] = field(default_factory=dict)
    users: tuple[FaceUser, ...] = ()


@dataclass(frozen=True)
class FaceCommand:
    """A method an OPC UA client called on the machine (Start, Stop, Acknowledge): who,
    what, and how it ended, for the machine's event log and the host's audit log."""

    user: str
    command: str  # cycle_start | feed_hold | acknowledge
    result: str  # "done" or the status code's name
    detail: str = ""
    at: float = 0.0  # wall clock, s


class HostDataError(CncError, ValueError):
    def __init__(self, pointer: str, message: str) -> None:
        super().__init__(f"{pointer}: {message}")
        self.pointer, self.message = pointer, message


def to_doc(data: HostData) -> dict:
    """The JSON form sent on the DNC port (`HOST PUT <n>`)."""
    programs = {
        name: {
            "revision": data.revision_by_program.get(name, ""),
            "sha256": data.sha256_by_program.get(name, ""),
        }
        for name in sorted(set(data.revision_by_program) | set(data.sha256_by_program))
    }
    return {
        "programs": programs,
        "jobs": [asdict(j) for j in data.jobs],
        "users": [asdict(u) for u in data.users],
    }


def from_doc(doc: object) -> HostData:
    """The JSON form back into HostData; HostDataError names the first bad field."""
    if not isinstance(doc, dict):
        raise HostDataError("/", "an object with programs and jobs")
    unknown = set(doc) - {"programs", "jobs", "users"}
    if unknown:
        raise HostDataError(f"/{sorted(unknown)[0]}", "unknown key (programs, jobs, users)")
    programs = doc.get("programs", {})
    if not isinstance(programs, dict):
        raise HostDataError("/programs", "an object: program name -> revision, sha256")
    revisions, digests = {}, {}
    for name, entry in programs.items():
        where = f"/programs/{name}"
        _text(name, where, 64)
        if not isinstance(entry, dict) or set(entry) - {"revision", "sha256"}:
            raise HostDataError(where, "an object with revision and sha256 only")
        revisions[name] = _text(entry.get("revision", ""), f"{where}/revision", 64)
        sha = _text(entry.get("sha256", ""), f"{where}/sha256", 64)
        if sha and (len(sha) != 64 or any(c not in "0123456789abcdef" for c in sha)):
            raise HostDataError(f"{where}/sha256", "64 lower-case hex digits")
        digests[name] = sha
    jobs_doc = doc.get("jobs", [])
    if not isinstance(jobs_doc, list):
        raise HostDataError("/jobs", "a list of jobs")
    if len(jobs_doc) > MAX_JOBS:
        raise HostDataError("/jobs", f"{len(jobs_doc)} jobs, at most {MAX_JOBS}")
    jobs, seen = [], set()
    for i, job in enumerate(jobs_doc):
        where = f"/jobs/{i}"
        if not isinstance(job, dict):
            raise HostDataError(where, "a job object")
        names = {f for f in ProductionJob.__dataclass_fields__}
        if set(job) != names:
            missing = sorted(names - set(job)) or sorted(set(job) - names)
            raise HostDataError(f"{where}/{missing[0]}", f"a job has exactly {sorted(names)}")
        ident = _text(job["identifier"], f"{where}/identifier", 64, name=True)
        if ident in seen:
            raise HostDataError(f"{where}/identifier", f"{ident!r} twice")
        seen.add(ident)
        if job["state"] not in JOB_STATES:
            raise HostDataError(f"{where}/state", f"one of {', '.join(JOB_STATES)}")
        counts = {}
        for key in ("runs_planned", "runs_completed", "parts_completed"):
            value = job[key]
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < 2**32:
                raise HostDataError(f"{where}/{key}", "an integer 0 .. 2^32-1")
            counts[key] = value
        jobs.append(
            ProductionJob(
                identifier=ident,
                program=_text(job["program"], f"{where}/program", 64, name=True),
                state=job["state"],
                **counts,
            )
        )
    return HostData(
        revision_by_program=revisions,
        jobs=tuple(jobs),
        sha256_by_program=digests,
        users=_users(doc.get("users", [])),
    )


def _users(doc: object) -> tuple[FaceUser, ...]:
    if not isinstance(doc, list):
        raise HostDataError("/users", "a list of users")
    if len(doc) > MAX_USERS:
        raise HostDataError("/users", f"{len(doc)} users, at most {MAX_USERS}")
    users, keys = [], set()
    names = {"user", "role", "key_sha256"}
    for i, entry in enumerate(doc):
        where = f"/users/{i}"
        if not isinstance(entry, dict):
            raise HostDataError(where, "a user object")
        if "key" in entry:  # a key in clear is never taken (nor kept, nor echoed)
            raise HostDataError(f"{where}/key", "the key's sha256 only (key_sha256), never the key")
        if set(entry) != names:
            odd = sorted(names - set(entry)) or sorted(set(entry) - names)
            raise HostDataError(f"{where}/{odd[0]}", f"a user has exactly {sorted(names)}")
        user = _text(entry["user"], f"{where}/user", 64)
        if not user or not user.isprintable():
            raise HostDataError(f"{where}/user", "1 to 64 printable characters")
        if entry["role"] not in ROLES:
            raise HostDataError(f"{where}/role", f"one of {', '.join(ROLES)}")
        key = _text(entry["key_sha256"], f"{where}/key_sha256", 64)
        if len(key) != 64 or any(c not in "0123456789abcdef" for c in key):
            raise HostDataError(f"{where}/key_sha256", "64 lower-case hex digits")
        if key in keys:
            raise HostDataError(f"{where}/key_sha256", "the same key twice")
        keys.add(key)
        users.append(FaceUser(user, entry["role"], key))
    return tuple(users)


def _text(value: object, where: str, limit: int, *, name: bool = False) -> str:
    """A string of at most `limit` characters; `name`: usable in a node id and browse name
    (letters, digits, `_`, `-`: no `.`, which separates the node id's path)."""
    if not isinstance(value, str) or len(value) > limit:
        raise HostDataError(where, f"a string of at most {limit} characters")
    if name and (not value or not all(c.isalnum() or c in "_-" for c in value)):
        raise HostDataError(where, "letters, digits, '_' or '-' only")
    return value
