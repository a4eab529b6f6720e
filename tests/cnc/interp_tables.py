"""Helpers of the interpreter's table tests: named cases and refusals as (message, line, col)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from cnc.errors import NcError


def cases(argnames: str, table: list[tuple]):
    """`pytest.mark.parametrize` over rows (name, *values), the name as the test id."""
    return pytest.mark.parametrize(
        argnames, [row[1:] for row in table], ids=[row[0] for row in table]
    )


def refused(run: Callable[[], object]) -> tuple[str, int, int]:
    """The NcError `run()` raises, as (message, line, column)."""
    with pytest.raises(NcError) as ei:
        run()
    return ei.value.message, ei.value.line, ei.value.col
