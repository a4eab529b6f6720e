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


def load(path: str | Path) -> MachineData:
    """Read a file `save` wrote; a bad file is an NcError naming the file and the place."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise NcError(f"cannot read machine data: {e.strerror}", file=str(path)) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise NcError(f"not JSON: {e.msg}", e.lineno, e.colno, str(path)) from None
    try:
        return MachineData.from_dict(doc)
    except MachineDataError as e:
        raise NcError(f"{e.pointer or '/'}: {e.message}", 0, 0, str(path)) from None


def load_or(path: str | Path, default: MachineData) -> MachineData:
    """The file's data when it exists, else `default` (a machine's first start)."""
    return load(path) if Path(path).exists() else default
