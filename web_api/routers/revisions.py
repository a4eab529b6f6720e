"""Revisions: read, text, release (the approver is the key's user) and diff."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Query
from fastapi.responses import PlainTextResponse, Response, StreamingResponse

from dnc.tape import sha256_of
from web_api.problems import problem_doc
from web_api.routers import Services, get_services
from web_api.routers.auth import Programmer, Viewer
from web_api.routers.programs import revision_out
from web_api.schemas import (
    DbId,
    DerivedRevision,
    MachineName,
    ProgramCall,
    ReleaseRequest,
    Revision,
)

router = APIRouter(tags=["revisions"], responses=problem_doc(400, 401, 403, 404, 422, 503))
Svc = Annotated[Services, Depends(get_services)]
RevisionId = Annotated[DbId, Path()]


@router.get("/api/revisions/{revision_id}", response_model=Revision, summary="One revision")
def get_revision(revision_id: RevisionId, services: Svc, _: Viewer) -> Revision:
    return revision_out(services.library.get_revision(revision_id))


@router.get(
    "/api/revisions/{revision_id}/calls",
    response_model=list[ProgramCall],
    summary="The other programs the revision calls (M98 P, G65 P, G66 P), resolved today",
)
def revision_calls(revision_id: RevisionId, services: Svc, _: Viewer) -> list[ProgramCall]:
    return [ProgramCall(**c) for c in services.library.calls(revision_id)]


@router.get(
    "/api/revisions/{revision_id}/text",
    response_class=PlainTextResponse,
    summary="The revision's program text (its ETag is the sha256 of the text)",
    responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}}},
)
def revision_text(revision_id: RevisionId, services: Svc, _: Viewer) -> Response:
    # streamed a stored chunk at a time (dnc.content): a 15 MB program is never whole in
    # the host's memory; its length is known, so a cut-off transfer shows as one
    info, chunks = services.library.revision_chunks(revision_id)
    return StreamingResponse(
        (chunk.encode("utf-8") for chunk in chunks),
        media_type="text/plain; charset=utf-8",
        headers={
            "ETag": f'"{info.sha256}"',
            "Content-Length": str(info.size),
            "Content-Disposition": f'inline; filename="rev{revision_id}.nc"',
        },
    )


@router.post(
    "/api/revisions/{revision_id}/release",
    response_model=Revision,
    summary="Release a draft (needs a passed NC check and an approval comment)",
    responses=problem_doc(409),
)
def release(
    revision_id: RevisionId, body: ReleaseRequest, services: Svc, principal: Programmer
) -> Revision:
    info = services.library.release(revision_id, approver=principal.user, comment=body.comment)
    return revision_out(info)


@router.get(
    "/api/revisions/{a}/diff/{b}",
    response_class=PlainTextResponse,
    summary="Unified diff from revision a to revision b",
    responses={200: {"content": {"text/x-diff": {"schema": {"type": "string"}}}}},
)
def diff(
    a: RevisionId,
    b: RevisionId,
    services: Svc,
    _: Viewer,
    ignore_numbers: Annotated[bool, Query(description="ignore N block numbers")] = False,
    ignore_whitespace: bool = False,
    ignore_comments: Annotated[bool, Query(description="ignore (...) and ; comments")] = False,
) -> Response:
    text = services.library.diff(
        a,
        b,
        ignore_numbers=ignore_numbers,
        ignore_whitespace=ignore_whitespace,
        ignore_comments=ignore_comments,
    )
    return Response(text, media_type="text/x-diff; charset=utf-8")


@router.get(
    "/api/revisions/{revision_id}/posted",
    response_class=PlainTextResponse,
    summary="Preview an APT/CL revision posted for a machine (nothing is stored)",
    description="The G-code a dispatch of this revision to `machine` would send: posted by "
    "the post-processor of the machine's kind with its configuration, and checked as the "
    "machine runs it (travel included). Headers name the post-processor and its version "
    "(X-Post-Processor), the tolerance T (X-Post-Tolerance-Mm, 5-axis posts) and the "
    "machine kind; the ETag is the posted text's sha256. A post the machine cannot run is "
    "a 422 `post-refused` problem with the source's `line`, `column` and the `reason`.",
    responses={
        200: {"content": {"text/plain": {"schema": {"type": "string"}}}},
        **problem_doc(409),
    },
)
def posted_preview(
    revision_id: RevisionId,
    services: Svc,
    _: Viewer,
    machine: Annotated[MachineName, Query(description="the machine to post for")],
) -> Response:
    posted = services.library.posted_preview(revision_id, machine)
    headers = {
        "ETag": f'"{posted.sha256}"',
        "X-Post-Processor": f"{posted.post_name} {posted.post_version}",
        "X-Machine-Kind": posted.machine_kind,
        "Content-Disposition": f'inline; filename="rev{revision_id}-{machine}.nc"',
    }
    if posted.tolerance_mm is not None:
        headers["X-Post-Tolerance-Mm"] = repr(posted.tolerance_mm)
    return PlainTextResponse(posted.text, headers=headers)


@router.get(
    "/api/revisions/{revision_id}/derived",
    response_model=list[DerivedRevision],
    summary="The G-code an APT/CL revision was posted to at dispatch, per machine kind",
)
def derived(revision_id: RevisionId, services: Svc, _: Viewer) -> list[DerivedRevision]:
    return [DerivedRevision(**d) for d in services.library.derived_revisions(revision_id)]


@router.get(
    "/api/derived-revisions/{derived_id}/text",
    response_class=PlainTextResponse,
    summary="A derived revision's G-code (its ETag is the sha256 of the text)",
    responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}}},
)
def derived_text(derived_id: Annotated[DbId, Path()], services: Svc, _: Viewer) -> Response:
    text = services.library.derived_text(derived_id)
    return PlainTextResponse(text, headers={"ETag": f'"{sha256_of(text)}"'})
