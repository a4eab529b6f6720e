"""Host operations on one machine's DNC port besides dispatch: punch (upload), remote requests,
and drip-feed resumed from a block."""

from __future__ import annotations

import re
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator

from dnc.errors import DncError, NotFound, WorkflowError
from dnc.library import Library, RevisionInfo
from dnc.posting import PostRefused
from dnc.transfer import CHUNK, DncClient, TransferError

#: Remote requests remembered per listener (the last ones served and refused, for a look at
#: what the machine asked lately); the audit log keeps them all, so memory stays flat.
REMOTE_REQUESTS_KEPT = 100

_SEQUENCE = re.compile(r"^\s*/?\s*N(\d+)", re.I)

ClientFactory = Callable[[], DncClient]


def client_for(library: Library, machine: str, **overrides) -> DncClient:
    """A DncClient for a registered machine, with its DNC profile (parity, time-outs).

    The port's shared secret is not in the registry (the API shows profiles): the host
    passes it as the override `secret=`."""
    info = library.machine(machine)
    host, _, port = info["dnc_address"].rpartition(":")
    if not host or not port.isdigit():
        raise NotFound(f"machine {machine!r} has no DNC address in the registry")
    profile = {**info["dnc_profile"], **overrides}
    return DncClient(
        host,
        int(port),
        parity=bool(profile.get("parity", False)),
        timeout_s=float(profile.get("timeout_s", 10.0)),
        xoff_timeout_s=float(profile.get("xoff_timeout_s", 30.0)),
        chunk=int(profile.get("chunk", CHUNK)),
        secret=profile.get("secret"),
    )


def upload_from_machine(
    library: Library, machine: str, number: int, *, secret: str | None = None
) -> RevisionInfo:
    """Punch program `number` from the machine; it lands as a candidate (draft) revision."""
    with client_for(library, machine, secret=secret) as client:
        text = client.punch(number)
    return library.receive_from_machine(machine, text)


def blocks_from(
    blocks: Iterable[str], *, block: int | None = None, line: int | None = None
) -> Iterator[str]:
    """Resume a drip-feed: the program's first block (its O number) then everything from
    sequence number N`block` or from 1-based source line `line` on.

    The O block is kept so the machine knows what it runs; the operator is responsible for
    the modal state at the restart point, as with any DNC package's restart.
    """
    if (block is None) == (line is None):
        raise ValueError("give exactly one of block= or line=")
    it = iter(blocks)
    started = False
    for number, text in enumerate(it, start=1):
        if number == 1 and text.strip().upper().startswith(("O", ":")):
            yield text
            continue
        if not started:
            m = _SEQUENCE.match(text)
            started = (line is not None and number >= line) or (
                block is not None and m is not None and int(m.group(1)) == block
            )
        if started:
            yield text
    if not started:
        where = f"block N{block}" if block is not None else f"line {line}"
        raise DncError(f"cannot resume: {where} is not in the program")


class RemoteRequests:
    """Answers a machine's remote requests with the released revision, from a thread.

    A request for a program that has no released revision for the machine's kind is
    refused (nothing is sent) and recorded, so the operator sees why nothing arrived.
    """

    def __init__(
        self, library: Library, machine: str, *, client: ClientFactory | None = None
    ) -> None:
        self.library, self.machine = library, machine
        self._client = client or (lambda: client_for(library, machine))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        # the last REMOTE_REQUESTS_KEPT of each, and how many there were since the start
        self.served: deque[int] = deque(maxlen=REMOTE_REQUESTS_KEPT)
        self.refused: deque[tuple[int, str]] = deque(maxlen=REMOTE_REQUESTS_KEPT)
        self.served_count = self.refused_count = 0
        self.error: Exception | None = None

    def answer(self, number: int) -> str | None:
        kind = self.library.machine(self.machine)["kind"]
        try:
            rev = self.library.released_revision(number, kind)
            # an APT/CL revision is posted for this machine (dnc/posting.py)
            text = self.library.text_for_machine(rev.id, self.machine, actor="remote-request")
        except (NotFound, PostRefused, WorkflowError) as exc:
            self.refused.append((number, exc.message))
            self.refused_count += 1
            self.library.note_transfer(
                self.machine, "remote_request.refused", number=number, reason=exc.message
            )
            return None
        self.served.append(number)
        self.served_count += 1
        self.library.note_transfer(
            self.machine, "remote_request.served", number=number, revision_id=rev.id
        )
        return text

    def start(self) -> RemoteRequests:
        def run() -> None:
            try:
                with self._client() as client:
                    client.listen(self.answer, until=self._stop.is_set)
            except (TransferError, DncError) as exc:
                self.error = exc

        self._thread = threading.Thread(
            target=run, name=f"remote-requests-{self.machine}", daemon=True
        )
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
