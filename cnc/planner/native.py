"""`mypyc_attr` for the planner's compiled classes; without mypy installed, a no-op.

`@mypyc_attr(acyclic=True)` tells mypyc that instances of a class never take part in a
reference cycle, so they are not tracked by the cyclic garbage collector: the planner
makes a few such objects per path segment, and the collector's passes over them cost
more than the planning itself. Only classes whose attributes hold numbers, tuples of
numbers and other such objects use it (a cycle through one of them would never be freed);
`Segment.sync_after` also holds the canon commands to run after it, which are plain values
(cnc/canon.py) that never refer back to the planner.
This module is not compiled; in plain Python the decorator changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

_T = TypeVar("_T")

try:
    from mypy_extensions import mypyc_attr
except ImportError:  # pragma: no cover - plain Python without mypy: no effect

    def mypyc_attr(*attrs: str, **kwattrs: object) -> Callable[[_T], _T]:  # type: ignore[misc]
        return lambda cls: cls


__all__ = ["mypyc_attr"]
