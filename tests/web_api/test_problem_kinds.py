"""One mapping from errors to problem+json (web_api/problems.py): every error class the
services and the API raise (the host's DncError, the cell's CellError, the API's own
WebApiError) maps to exactly one problem type of `PROBLEM_TYPES`, which gives its status and
title and has its row in docs/api.md; no router names an HTTP error status or turns a
service's error into another one itself (checked on the routers' syntax trees)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from dnc.cell import (
    CellError,
    CommandRefused,
    FaultRefused,
    InvalidFault,
    InvalidMachineData,
    MachineUnavailable,
)
from dnc.errors import Conflict, DncError, InvalidUpload, NotFound, UploadTooLarge
from dnc.transfer import TransferError
from tests.test_errors import exception_classes
from web_api import errors as api_errors
from web_api.event_hub import HubClosed
from web_api.problems import (
    _KIND_OF_STATUS,
    ERROR_ROOTS,
    PROBLEM_TYPES,
    install_problem_handlers,
    problem_kind,
)

ROOT = Path(__file__).resolve().parents[2]
API_DOC = ROOT / "docs" / "api.md"
ROUTERS = ROOT / "web_api" / "routers"
BASE = "https://fmscell.dev/problems/"


def answered_classes() -> list[type[BaseException]]:
    """Every error class of the packages whose errors the API answers (dnc: the host and
    the cell; web_api: its own refusals)."""
    return [c for p in ("dnc", "web_api") for c in exception_classes(p)]


def test_every_error_the_api_answers_maps_to_exactly_one_problem_type():
    classes = answered_classes()
    assert len(classes) > 20
    for cls in classes:
        roots = [r for r in ERROR_ROOTS if issubclass(cls, r)]
        assert len(roots) == 1, f"{cls.__qualname__}: under {roots} (needs exactly one)"
        assert problem_kind(cls) in PROBLEM_TYPES, f"{cls.__qualname__}: {problem_kind(cls)!r}"


def test_every_problem_type_is_answered_by_something_and_documented_once():
    # the framework's own refusals (FastAPI validation, Starlette's HTTP errors, crashes)
    framework = {"validation", "malformed-json", "internal", *_KIND_OF_STATUS.values()}
    used = {problem_kind(c) for c in answered_classes()} | framework
    assert set(PROBLEM_TYPES) == used, "a problem type nothing answers with, or the reverse"
    doc = API_DOC.read_text()
    for kind, p in PROBLEM_TYPES.items():
        rows = re.findall(rf"^\| `{kind}` \| (\d+) \|", doc, re.M)
        assert rows == [str(p.status)], f"docs/api.md: {kind} {p.status}: rows {rows}"


# the refusals a client branches on, pinned: (error, problem type, status, detail, extra)
REFUSALS = [
    (NotFound("unknown machine 'm9'"), "not-found", 404, "unknown machine 'm9'", {}),
    (Conflict("m1: program O0001 active"), "conflict", 409, "m1: program O0001 active", {}),
    (
        UploadTooLarge("program of 9 bytes exceeds the upload limit of 4 bytes", limit=4),
        "upload-too-large",
        413,
        "program of 9 bytes exceeds the upload limit of 4 bytes",
        {"limit": 4},
    ),
    (InvalidUpload("x.nc: the program is empty"), "invalid-upload", 422, None, {}),
    (DncError("cannot resume: line 9 is not in the program"), "dnc-error", 400, None, {}),
    (
        TransferError("refused", "2002 memory full", alarm=2002),
        "transfer-failed",
        502,
        "2002 memory full",
        {"transfer_kind": "refused", "alarm": 2002},
    ),
    (
        MachineUnavailable("mill1: no answer on the simulation face"),
        "machine-unavailable",
        503,
        "mill1: no answer on the simulation face",
        {},
    ),
    (
        CommandRefused("mill1: mode MDI refused: a program is active", command="mode"),
        "command-refused",
        409,
        "mill1: mode MDI refused: a program is active",
        {"command": "mode"},
    ),
    (FaultRefused("mill1: ideal axes have no bus"), "fault-refused", 409, None, {}),
    (
        InvalidFault("fault spec 'drive:X:nonsense': unknown drive fault\n  valid specs: a, b"),
        "invalid-fault",
        422,
        "fault spec 'drive:X:nonsense': unknown drive fault",  # the first line only
        {},
    ),
    (
        InvalidMachineData("must be a number", "/3/length", what="tools"),
        "validation",
        422,
        "1 invalid field(s); first body #/tools/3/length: must be a number",
        {"errors": [{"detail": "must be a number", "pointer": "#/tools/3/length", "location": "body"}]},
    ),
    (
        InvalidMachineData("no such offset", "/work_offsets/G60", what="offsets"),
        "validation",
        422,
        "1 invalid field(s); first body #/work_offsets/G60: no such offset",
        {"errors": [{"detail": "no such offset", "pointer": "#/work_offsets/G60", "location": "body"}]},
    ),
    (
        api_errors.Unauthenticated("the API key is not known", headers={"WWW-Authenticate": "x"}),
        "unauthenticated",
        401,
        None,
        {},
    ),
    (
        api_errors.Forbidden("reading needs the viewer role", needed_role="viewer", role="x"),
        "forbidden",
        403,
        None,
        {"needed_role": "viewer", "role": "x"},
    ),
    (api_errors.TooManyAuthFailures("wait", retry_after_s=3), "too-many-auth-failures", 429, None,
     {"retry_after_s": 3}),
    (api_errors.UnsupportedMediaType("send JSON"), "unsupported-media-type", 415, None, {}),
    (api_errors.InvalidBody("the body must be an object"), "validation", 422, None, {}),
    (api_errors.InvalidLastEventId("not an id"), "invalid-last-event-id", 400, None, {}),
    (api_errors.NoCell("no machine is connected"), "no-cell", 503, None, {}),
    (api_errors.ShuttingDown("the server is shutting down"), "shutting-down", 503, None, {}),
    (HubClosed("the server is shutting down"), "shutting-down", 503, None, {}),
]  # fmt: skip


@pytest.mark.parametrize(
    ("error", "kind", "status", "detail", "extra"),
    REFUSALS,
    ids=[f"{type(r[0]).__name__}-{r[1]}" for r in REFUSALS],
)
def test_each_refusal_is_answered_as_its_problem(error, kind, status, detail, extra):
    app = FastAPI()
    install_problem_handlers(app, BASE)

    @app.get("/refuse")
    def refuse():
        raise error

    r = TestClient(app).get("/refuse")
    assert r.status_code == status and r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["type"] == BASE + kind
    assert (body["status"], body["title"]) == (status, PROBLEM_TYPES[kind].title)
    assert body["detail"] == (detail if detail is not None else str(error))
    assert body["instance"] == "/refuse"
    rest = {k: v for k, v in body.items() if k not in ("type", "title", "status", "detail")}
    assert rest == {"instance": "/refuse", **extra}
    for name, value in getattr(error, "headers", {}).items():
        assert r.headers[name] == value


def test_the_cell_errors_keep_the_bases_their_callers_catch():
    assert issubclass(CommandRefused, MachineUnavailable)
    assert issubclass(FaultRefused, MachineUnavailable)
    assert issubclass(InvalidFault, ValueError) and issubclass(InvalidFault, CellError)
    from cnc.machine_data import MachineDataError

    err = InvalidMachineData("must be a number", "/3/length", what="tools")
    assert isinstance(err, MachineDataError) and str(err) == "/3/length: must be a number"


# ------------------------------------------------------------------ no mapping in routers


def service_error_names() -> set[str]:
    """Names an except clause catches a service's error by: its class or a base of it
    (the roots, and the builtin bases they keep: ValueError, RuntimeError...)."""
    names = {c.__name__ for c in answered_classes()}
    return names | {"ValueError", "RuntimeError", "Exception", "BaseException"}


# calls that may name an error status: OpenAPI documentation of what a route answers
DOCUMENTATION_CALLS = {"problem_doc"}
# exceptions that carry a status chosen where they are raised
STATUS_CARRIERS = {"HTTPException", "ApiProblem"}
STATUS_KEYWORDS = {"status", "status_code"}


def _name(node: ast.AST) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return ""


def _caught(handler: ast.ExceptHandler) -> set[str]:
    if handler.type is None:
        return {"BaseException"}
    types = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return {_name(t) for t in types}


def mappings(path: Path) -> list[str]:
    """Where a router maps an error to HTTP itself: an HTTP error status (400..599) given
    to a call (a response, an exception) outside the OpenAPI documentation, an exception
    that carries a status, or an except clause catching a service's error that raises
    anything but that error again (a bare `raise`, after an audit, is fine)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    service = service_error_names()
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Call) and _name(node.func) not in DOCUMENTATION_CALLS:
            given = node.args + [k.value for k in node.keywords if k.arg in STATUS_KEYWORDS]
            for arg in given:
                if (
                    isinstance(arg, ast.Constant)
                    and type(arg.value) is int
                    and 400 <= arg.value < 600
                ):
                    found.append((line, f"HTTP status {arg.value}"))
            if _name(node.func) in STATUS_CARRIERS:
                found.append((line, f"{_name(node.func)}(...)"))
        elif isinstance(node, ast.ImportFrom) and {a.name for a in node.names} & STATUS_CARRIERS:
            found.append((line, "imports a status-carrying exception"))
        elif isinstance(node, ast.ExceptHandler) and _caught(node) & service:
            caught = "/".join(sorted(_caught(node)))
            for inner in ast.walk(node):
                if isinstance(inner, ast.Raise) and inner.exc is not None:
                    found.append((line, f"except {caught} raises {ast.unparse(inner.exc)}"))
    return [f"{path.name}:{line}: {what}" for line, what in sorted(found)]


def test_no_router_maps_errors_to_statuses_itself():
    found = [m for path in sorted(ROUTERS.glob("*.py")) for m in mappings(path)]
    assert found == []


def test_the_check_sees_a_router_that_maps_an_error(tmp_path):
    bad = tmp_path / "r.py"
    bad.write_text(
        "from fastapi import HTTPException\n"
        "from fastapi.responses import JSONResponse\n"
        "@router.post('/x', status_code=201, responses=problem_doc(404, 409))\n"
        "def f():\n"
        "    try:\n"
        "        cell.command('m1', 'reset')\n"
        "    except MachineUnavailable as exc:\n"
        "        raise Refused(str(exc)) from None\n"
        "    except Conflict:\n"
        "        audit()\n"
        "        raise\n"
        "    except ValidationError as exc:\n"
        "        raise invalid(exc.errors()) from None\n"
        "    if x:\n"
        "        raise HTTPException(404, 'no')\n"
        "    return JSONResponse({}, status_code=409)\n"
    )
    assert "ValidationError" not in service_error_names()  # pydantic's: the request's own
    assert mappings(bad) == [
        "r.py:1: imports a status-carrying exception",
        "r.py:7: except MachineUnavailable raises Refused(str(exc))",
        "r.py:15: HTTP status 404",
        "r.py:15: HTTPException(...)",
        "r.py:16: HTTP status 409",
    ]
