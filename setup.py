"""Build hook: compile the hot pure-Python modules with mypyc.

The NC planner and the drive model run tens of thousands of times per machine second; mypyc
turns their typed Python into C extensions with the same behaviour. Each package that wants
this lists its modules, one path per line relative to the list's folder, in a `mypyc.list`
file. The Python sources stay the reference: with `FMSCELL_PURE_PYTHON=1` at install time
(or without mypy in the build environment) nothing is compiled and the same code runs as
plain Python. `tests/test_compiled.py` checks that the compiled modules are not older than
their sources, so an edit is never shadowed by a stale extension.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from setuptools import setup

ROOT = Path(__file__).resolve().parent


def compiled_sources() -> list[str]:
    """Every module named in a `mypyc.list`, as a path relative to the project root."""
    sources: list[str] = []
    for listing in sorted(ROOT.glob("*/**/mypyc.list")):
        for line in listing.read_text().splitlines():
            line = line.split("#", 1)[0].strip()
            if line:
                path = listing.parent / line
                if not path.is_file():
                    raise SystemExit(f"{listing}: no such module {line!r}")
                sources.append(str(path.relative_to(ROOT)))
    return sources


def compile_notice(sources: list[str]) -> str:
    """What the build is about to do, and about how long it takes."""
    return (
        f"fmscell: compiling {len(sources)} modules with mypyc (typically 3-10 minutes;"
        " FMSCELL_PURE_PYTHON=1 skips it): " + ", ".join(sources)
    )


def ext_modules() -> list:
    if os.environ.get("FMSCELL_PURE_PYTHON") == "1":
        return []
    sources = compiled_sources()
    if not sources:
        return []
    try:
        from mypyc.build import mypycify
    except ImportError:  # a build without mypy: the plain Python modules are used
        return []
    # Imported modules that are not compiled are read for their types only: their own type
    # errors must not stop the build. A compiled class whose base class mypy cannot see
    # (a library missing from the build environment, so its type is Any) would be laid out
    # as a native class and crash at run time: --disallow-subclassing-any makes that a build
    # error. The libraries compiled classes derive from (python-can's BusABC, canopen) are
    # therefore in pyproject's build requirements, pinned as in its dependencies.
    # pip shows this with -v (the Makefile says the same before it calls pip)
    print(compile_notice(sources), file=sys.stderr, flush=True)
    return mypycify(
        [
            "--follow-imports=silent",
            "--ignore-missing-imports",
            "--disallow-subclassing-any",
            *sources,
        ],
        opt_level="3",
        debug_level="0",
    )


setup(ext_modules=ext_modules())
