"""One error hierarchy per package (docs/architecture.md): every exception class a package
defines derives from the package's root, so a user of the package catches one class.
Private classes (a leading `_`: control flow inside a module) and warnings are left out."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

from cam.errors import CamError
from cnc.errors import CncError
from dnc.cell import CellError
from dnc.errors import DncError
from drives.errors import DrivesError
from mtconnect.errors import AgentError
from plc.errors import PlcError
from server.errors import ServerError
from web_api.errors import WebApiError

ROOTS: dict[str, tuple[type[Exception], ...]] = {
    "drives": (DrivesError,),
    "plc": (PlcError,),
    "cnc": (CncError,),
    "cam": (CamError,),
    "mtconnect": (AgentError,),
    "dnc": (DncError, CellError),  # the host's refusals; the running cell's (dnc.cell)
    "web_api": (WebApiError,),
    "server": (ServerError,),
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


def test_every_package_has_a_root():
    """Every top-level package of ours is in ROOTS (the layering's list of packages)."""
    from tests.test_architecture import ALLOWED

    assert set(ROOTS) == set(ALLOWED)


# Re-rooting kept each error's message and the builtin base its callers catch.
KEPT = [
    ("cam.apt.geometry", "GeometryError", ("the lines are parallel",), ValueError,
     "the lines are parallel"),
    ("mtconnect.path", "PathError", ("bad path",), ValueError, "bad path"),
    ("mtconnect.agent", "RestError", ("INVALID_REQUEST", "no such device", 404), Exception,
     "INVALID_REQUEST: no such device"),
    ("server.host", "StartRefused", ("m1: the PLC refused cycle start",), CellError,
     "m1: the PLC refused cycle start"),
    ("web_api.event_hub", "HubClosed", ("the server is shutting down",), WebApiError,
     "the server is shutting down"),
]  # fmt: skip


@pytest.mark.parametrize(("module", "name", "args", "base", "text"), KEPT)
def test_a_re_rooted_error_keeps_its_message_and_base(module, name, args, base, text):
    cls = getattr(importlib.import_module(module), name)
    err = cls(*args)
    assert isinstance(err, base) and str(err) == text
