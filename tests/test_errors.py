"""One error hierarchy per package (docs/architecture.md): every exception class a package
defines derives from the package's root, so a user of the package catches one class.
Private classes (a leading `_`: control flow inside a module) and warnings are left out."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

from cnc.errors import CncError
from dnc.cell import CellError
from dnc.errors import DncError
from drives.errors import DrivesError
from plc.errors import PlcError

ROOTS: dict[str, tuple[type[Exception], ...]] = {
    "drives": (DrivesError,),
    "plc": (PlcError,),
    "cnc": (CncError,),
    "dnc": (DncError, CellError),  # the host's refusals; the running cell's (dnc.cell)
}


def exception_classes(package: str) -> list[type[BaseException]]:
    root = importlib.import_module(package)
    found = {}
    for info in pkgutil.walk_packages(root.__path__, f"{package}."):
        if ".migrations" in info.name:
            continue
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (
                inspect.isclass(value)
                and issubclass(value, BaseException)
                and not issubclass(value, Warning)  # a warning is not an error
                and value.__module__ == info.name
                and not name.startswith("_")
            ):
                found[f"{info.name}.{name}"] = value
    return [found[k] for k in sorted(found)]


@pytest.mark.parametrize("package", sorted(ROOTS))
def test_every_error_of_a_package_derives_from_its_root(package):
    classes = exception_classes(package)
    assert classes, package
    stray = [
        f"{c.__module__}.{c.__qualname__}" for c in classes if not issubclass(c, ROOTS[package])
    ]
    assert stray == []


def test_the_roots_are_distinct():
    roots = [r for rs in ROOTS.values() for r in rs]
    for a in roots:
        assert [b for b in roots if issubclass(a, b)] == [a]
