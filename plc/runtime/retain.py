"""Retentive memory stores: where RETAIN tags and the retained %MW range survive a restart.

A store keeps one JSON-able dict. `FileRetainStore` writes atomically (temp file + rename)
so a crash during a save leaves the previous image intact, as battery-backed RAM would.
"""

from __future__ import annotations

import json
import os
import tempfile
from typing import Protocol


class RetainStore(Protocol):
    def load(self) -> dict | None: ...

    def save(self, data: dict) -> None: ...


class MemoryRetainStore:
    """Keeps the retained data in memory (tests; a restart within one process)."""

    def __init__(self) -> None:
        self.data: dict | None = None
        self.saves = 0

    def load(self) -> dict | None:
        return json.loads(json.dumps(self.data)) if self.data is not None else None

    def save(self, data: dict) -> None:
        self.data = json.loads(json.dumps(data))
        self.saves += 1


class FileRetainStore:
    """Keeps the retained data in a JSON file."""

    def __init__(self, path: str) -> None:
        self.path = path

    def load(self) -> dict | None:
        try:
            with open(self.path, encoding="utf-8") as f:
                return json.load(f)
        except FileNotFoundError:
            return None

    def save(self, data: dict) -> None:
        folder = os.path.dirname(os.path.abspath(self.path))
        fd, tmp = tempfile.mkstemp(prefix=".retain-", dir=folder)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(data, f)
            os.replace(tmp, self.path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
