"""Machine data on disk: one JSON file in the machine's state directory, written atomically.

The shell around the pure core: `save` writes a sibling temporary file, flushes and fsyncs
it, renames it over the target with os.replace (atomic on POSIX and Windows) and fsyncs the
directory, so a crash at any point leaves either the old file or the new one, never a mix.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from cnc.errors import NcError
from cnc.machine_data.core import MachineData, MachineDataError

FILE_SUFFIX = ".machine-data.json"


def state_file(state_dir: str | Path, machine: str) -> Path:
    """Where machine `machine` keeps its machine data in `state_dir`."""
    return Path(state_dir) / f"{machine}{FILE_SUFFIX}"


def write_atomically(path: str | Path, text: str) -> None:
    """Replace `path` by `text` so that a reader or a crash sees the old or the new text."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    try:  # the rename itself survives a power loss only once the directory is on disk
        dfd = os.open(path.parent, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


def save(path: str | Path, data: MachineData) -> None:
    write_atomically(path, json.dumps(data.to_dict(), indent=1, sort_keys=False) + "\n")


def _read_json(path: Path, what: str):
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise NcError(f"cannot read {what}: {e.strerror}", file=str(path)) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise NcError(f"not JSON: {e.msg}", e.lineno, e.colno, str(path)) from None


def load(path: str | Path) -> MachineData:
    """Read a file `save` wrote; a bad file is an NcError naming the file and the place."""
    path = Path(path)
    doc = _read_json(path, "machine data")
    try:
        return MachineData.from_dict(doc)
    except MachineDataError as e:
        raise NcError(f"{e.pointer or '/'}: {e.message}", 0, 0, str(path)) from None


def load_or(path: str | Path, default: MachineData) -> MachineData:
    """The file's data when it exists, else `default` (a machine's first start)."""
    return load(path) if Path(path).exists() else default


# The part counter is kept in a file of its own: it changes at every M30, while a program is
# in cycle, where the machine data is saved only between programs; and a small file is cheap
# to write synchronously at each count.
COUNTERS_SUFFIX = ".counters.json"


def counters_file(state_dir: str | Path, machine: str) -> Path:
    """Where machine `machine` keeps its part counter in `state_dir`."""
    return Path(state_dir) / f"{machine}{COUNTERS_SUFFIX}"


def save_part_count(path: str | Path, part_count: int) -> None:
    """Keep the part counter, atomically (the old count or the new, never neither)."""
    write_atomically(path, json.dumps({"part_count": part_count}) + "\n")


def load_part_count(path: str | Path) -> int:
    """The part counter `save_part_count` kept; 0 when there is no file yet (a new machine).
    A bad file is an NcError naming the file and the JSON pointer of the bad value."""
    path = Path(path)
    if not path.exists():
        return 0
    doc = _read_json(path, "the part counter")
    if not isinstance(doc, dict):
        raise NcError(f"/: must be an object, got {type(doc).__name__}", 0, 0, str(path))
    count = doc.get("part_count")
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise NcError(f"/part_count: must be an integer >= 0, got {count!r}", 0, 0, str(path))
    return count
