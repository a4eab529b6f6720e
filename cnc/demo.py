"""The NC kernel demo `make run` shows until the cell server exists (issue 7)."""

from __future__ import annotations


def run_demo() -> int:
    print("fmscell: the cell server is not built yet; the NC kernel demo is being built (issue 2).")
    return 0
