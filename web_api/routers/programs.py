"""Programs: upload (JSON or a multipart file), list and search, one program with history."""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import ctypes
import ctypes.util
import dataclasses
from concurrent.futures import ThreadPoolExecutor
from pathlib import PurePath
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ValidationError
from starlette.datastructures import UploadFile

from dnc.errors import InvalidUpload, UploadTooLarge
from dnc.posting import REVISION_KINDS, kind_of_upload, partno_header
from dnc.tape import MAX_PROGRAM_NUMBER, read_header
from dnc.upload import ProgramUpload
from web_api.errors import UnsupportedMediaType
from web_api.problems import problem_doc
from web_api.routers import Services, decode_cursor, get_services, next_link
from web_api.routers.auth import Programmer, Viewer
from web_api.schemas import (
    KIND_HELP,
    POST_KINDS_HELP,
    DbId,
    MachineKind,
    Name,
    Program,
    ProgramCreate,
    ProgramCreated,
    ProgramDetail,
    ProgramPage,
    Revision,
    RevisionCreate,
    Tag,
)

router = APIRouter(tags=["programs"], responses=problem_doc(400, 401, 403, 422, 503))
Svc = Annotated[Services, Depends(get_services)]
FORM_FIELDS = (
    "number",
    "name",
    "machine_kind",
    "description",
    "tags",
    "comment",
    "kind",
    "post_kinds",
)
LIST_FIELDS = ("tags", "post_kinds")  # comma-separated in a form


def upload_body(json_model: type[BaseModel], form_fields: dict[str, Any]) -> dict:
    """OpenAPI requestBody for a route taking JSON or a multipart file upload."""
    return {
        "requestBody": {
            "required": True,
            "content": {
                "application/json": {
                    "schema": {"$ref": f"#/components/schemas/{json_model.__name__}"}
                },
                "multipart/form-data": {
                    "schema": {
                        "type": "object",
                        "required": ["file"],
                        "properties": {
                            "file": {"type": "string", "format": "binary"},
                            **form_fields,
                        },
                    }
                },
            },
        }
    }


SOURCE_FORM_FIELDS = {
    "kind": {"type": "string", "enum": ["gcode", "apt", "cl"], "description": KIND_HELP},
    "post_kinds": {"type": "string", "description": "comma-separated; " + POST_KINDS_HELP},
}


def program_out(info) -> Program:
    return Program.model_validate(dataclasses.asdict(info))


def revision_out(info) -> Revision:
    return Revision.model_validate(dataclasses.asdict(info))


def _invalid(errors: list, prefix: tuple = ("body",)) -> RequestValidationError:
    return RequestValidationError([{**e, "loc": prefix + tuple(e.get("loc", ()))} for e in errors])


async def read_upload(
    request: Request, model: type[BaseModel], services: Services
) -> tuple[BaseModel, str | ProgramUpload, str | None]:
    """The validated fields, the program text (str from JSON, a streamed ProgramUpload from
    a file, which the caller closes) and the file name. JSON and multipart bodies get the
    same validation and the same problems."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype == "application/json" or ctype.endswith("+json"):
        try:
            fields = model.model_validate_json(await request.body())
        except ValidationError as exc:
            raise _invalid(exc.errors()) from None
        text = fields.text
        if len(text.encode("utf-8", "surrogatepass")) > services.settings.upload_limit_bytes:
            raise _too_large(len(text.encode("utf-8", "surrogatepass")), services)
        return fields, text, None
    if ctype == "multipart/form-data":
        form = await request.form(max_files=1, max_fields=len(FORM_FIELDS) + 1)
        upload = form.get("file")
        if not isinstance(upload, UploadFile):
            raise _invalid(
                [{"type": "missing", "loc": ("file",), "msg": "a file part named 'file'"}]
            )
        limit = services.settings.upload_limit_bytes
        # streamed: validated and hashed chunk by chunk into a temporary file, never the
        # whole file in memory (see dnc.upload)
        spooled = ProgramUpload(limit=limit, name=upload.filename or "upload")
        refused: InvalidUpload | None = None
        over = 0  # bytes received when the limit was crossed (said with the API's key)
        try:
            while chunk := await upload.read(UPLOAD_CHUNK):
                if spooled.size + len(chunk) > limit:
                    over = spooled.size + len(chunk)
                    break
                spooled.feed(chunk)
        except InvalidUpload as exc:
            refused = exc  # said after the fields' own problems, as before
        if over:
            spooled.close()
            raise _too_large(over, services, at_least=True)
        values: dict[str, Any] = {
            k: form[k] for k in FORM_FIELDS if k in model.model_fields and k in form
        }
        for key in LIST_FIELDS:
            if key in values:
                values[key] = [t.strip() for t in str(values[key]).split(",") if t.strip()]
        if "number" in model.model_fields:
            given = values.get("kind")  # one that is no kind: the model's validation says so
            kind = kind_of_upload(given if given in REVISION_KINDS else None, upload.filename)
            _fill_from_header(values, spooled.head, upload.filename, kind)
        try:
            # form fields are text by nature: "1001" is the number 1001 here (lax), while
            # a JSON body is strict
            fields = model.model_validate({**values, "text": ""}, strict=False)
        except ValidationError as exc:
            spooled.close()
            raise _invalid(exc.errors()) from None
        if refused is not None:
            spooled.close()
            raise refused
        return fields, spooled, upload.filename
    raise UnsupportedMediaType(
        f"send application/json or multipart/form-data, not {ctype or 'no content type'!r}",
    )


UPLOAD_CHUNK = 1 << 20
#: a program larger than this is NC-checked and stored on one worker thread, one at a time:
#: the check of a 15 MB program holds the CPU for seconds, and several at once would only
#: share it (one interpreter lock). A file upload is stored a chunk at a time (dnc.content,
#: a few MB whatever its size), but a JSON body holds its whole text, and glibc keeps what a
#: thread freed in that thread's own arena: on whichever pool thread was free, four large
#: JSON uploads would leave four arenas at their peak. One thread reuses one arena, and the
#: heap is trimmed after each large store.
HEAVY_BYTES = 1 << 20
_heavy_worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fmscell-large-upload")


def _find_malloc_trim():
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None  # not glibc (musl, macOS): nothing to trim


_malloc_trim = _find_malloc_trim()


async def _heavy(text: str | ProgramUpload, work):
    """Run the library call in the thread pool; a large program on the large-upload worker
    (in turn), the heap trimmed after it."""
    size = text.size if isinstance(text, ProgramUpload) else len(text)
    if size < HEAVY_BYTES:
        return await run_in_threadpool(work)

    def then_trim():
        try:
            return work()
        finally:
            if _malloc_trim is not None:
                _malloc_trim(0)

    context = contextvars.copy_context()
    return await asyncio.wrap_future(_heavy_worker.submit(context.run, then_trim))


@contextlib.contextmanager
def _closing(text: str | ProgramUpload):
    try:
        yield
    finally:
        if isinstance(text, ProgramUpload):
            text.close()


def _fill_from_header(values: dict, data: bytes, filename: str | None, kind: str) -> None:
    """A file upload may leave number and name out: the tape's O block supplies them (an
    APT or CL file's PARTNO: its text, and the number ending it)."""
    head = data[:4096].decode("utf-8", "replace")
    header = read_header(head) if kind == "gcode" else partno_header(head)
    if "number" not in values and header.number is not None:
        values["number"] = header.number
    if "name" not in values:
        stem = PurePath(filename or "").stem
        values["name"] = header.title or stem or f"O{values.get('number', 0):04d}"


def _too_large(size: int, services: Services, at_least: bool = False) -> UploadTooLarge:
    limit = services.settings.upload_limit_bytes
    amount = f"at least {size}" if at_least else str(size)
    return UploadTooLarge(
        f"program of {amount} bytes exceeds the upload limit of {limit} bytes "
        "(configure upload_limit_bytes, or drip-feed the program from a file)",
        limit=limit,
    )


@router.post(
    "/api/programs",
    status_code=201,
    response_model=ProgramCreated,
    summary="Upload a new program (its first revision is a draft, NC-checked)",
    responses=problem_doc(409, 413, 415),
    openapi_extra=upload_body(
        ProgramCreate,
        {
            "number": {"type": "integer", "minimum": 1, "maximum": MAX_PROGRAM_NUMBER},
            "name": {"type": "string", "maxLength": 200},
            "machine_kind": {"type": "string", "pattern": "^[A-Za-z0-9_.-]+$"},
            "description": {"type": "string", "maxLength": 4000},
            "tags": {"type": "string", "description": "comma-separated"},
            "comment": {"type": "string", "maxLength": 2000},
            **SOURCE_FORM_FIELDS,
        },
    ),
)
async def create_program(request: Request, services: Svc, principal: Programmer) -> JSONResponse:
    fields, text, filename = await read_upload(request, ProgramCreate, services)
    comment = fields.comment or (f"uploaded as {filename}" if filename else "")
    with _closing(text):
        program, revision = await _heavy(
            text,
            lambda: services.library.create_program(
                number=fields.number,
                name=fields.name,
                text=text,
                machine_kind=fields.machine_kind,
                description=fields.description,
                tags=fields.tags,
                author=principal.user,
                comment=comment,
                kind=kind_of_upload(fields.kind, filename),
                post_kinds=fields.post_kinds or None,
            ),
        )
    body = ProgramCreated(program=program_out(program), revision=revision_out(revision))
    return JSONResponse(
        body.model_dump(mode="json"),
        status_code=201,
        headers={"Location": f"/api/programs/{program.id}"},
    )


@router.get(
    "/api/programs",
    response_model=ProgramPage,
    summary="List and search programs (cursor pagination; Link header to the next page)",
)
def list_programs(
    request: Request,
    services: Svc,
    _: Viewer,
    q: Annotated[Name | None, Query(description="name contains, or O number")] = None,
    number: Annotated[int | None, Query(ge=1, le=MAX_PROGRAM_NUMBER)] = None,
    tag: Annotated[Tag | None, Query()] = None,
    text: Annotated[Name | None, Query(description="text in any revision")] = None,
    machine_kind: Annotated[MachineKind | None, Query()] = None,
    cursor: Annotated[str | None, Query(max_length=64)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
) -> JSONResponse:
    if cursor:
        decode_cursor("p", cursor)  # refuse foreign cursors before the database sees them
    page = services.library.search(
        query=q or None,
        number=number,
        tag=tag,
        text=text or None,
        machine_kind=machine_kind,
        limit=min(limit, services.settings.page_limit_max),
        cursor=cursor or None,
    )
    body = ProgramPage(items=[program_out(p) for p in page.items], next_cursor=page.next_cursor)
    return JSONResponse(body.model_dump(mode="json"), headers=next_link(request, page.next_cursor))


@router.get(
    "/api/programs/{program_id}",
    response_model=ProgramDetail,
    summary="One program with its revisions, linked tools, fixtures and material, the "
    "programs it calls and the programs that call it",
    responses=problem_doc(404),
)
def get_program(program_id: Annotated[DbId, Path()], services: Svc, _: Viewer) -> ProgramDetail:
    lib = services.library
    info = lib.get_program(program_id)
    program = program_out(info)
    current = info.released_revision_id or info.latest_revision_id
    return ProgramDetail(
        **program.model_dump(),
        revisions=[revision_out(r) for r in lib.revisions(program_id)],
        resources=lib.resources(program_id),
        calls=lib.calls(current) if current is not None else [],
        called_by=lib.called_by(program_id),
    )


@router.post(
    "/api/programs/{program_id}/revisions",
    status_code=201,
    response_model=Revision,
    summary="Add a revision (a draft, NC-checked) to a program",
    responses=problem_doc(404, 409, 413, 415),
    openapi_extra=upload_body(
        RevisionCreate, {"comment": {"type": "string", "maxLength": 2000}, **SOURCE_FORM_FIELDS}
    ),
)
async def add_revision(
    program_id: Annotated[DbId, Path()],
    request: Request,
    services: Svc,
    principal: Programmer,
) -> JSONResponse:
    fields, text, filename = await read_upload(request, RevisionCreate, services)
    comment = fields.comment or (f"uploaded as {filename}" if filename else "")
    with _closing(text):
        revision = await _heavy(
            text,
            lambda: services.library.add_revision(
                program_id,
                text,
                author=principal.user,
                comment=comment,
                kind=kind_of_upload(fields.kind, filename),
                post_kinds=fields.post_kinds or None,
            ),
        )
    return JSONResponse(
        revision_out(revision).model_dump(mode="json"),
        status_code=201,
        headers={"Location": f"/api/revisions/{revision.id}"},
    )
