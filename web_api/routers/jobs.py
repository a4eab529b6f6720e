"""FMS jobs: create, list, one job with its allocations and decisions, cancel."""

from __future__ import annotations

import dataclasses
from typing import Annotated

from fastapi import APIRouter, Depends, Path, Query, Request
from fastapi.responses import JSONResponse

from web_api.problems import problem_doc
from web_api.routers import Services, decode_cursor, encode_cursor, get_services, next_link
from web_api.routers.auth import Operator, Viewer
from web_api.schemas import DbId, Job, JobCreate, JobDetail, JobPage

router = APIRouter(tags=["jobs"], responses=problem_doc(400, 401, 403, 422, 503))
Svc = Annotated[Services, Depends(get_services)]
JobId = Annotated[DbId, Path()]


def job_out(info) -> Job:
    return Job.model_validate(dataclasses.asdict(info))


@router.post(
    "/api/jobs",
    status_code=201,
    response_model=Job,
    summary="Queue a job: quantity of a released revision on eligible machines",
    responses=problem_doc(404, 409),
)
def create_job(body: JobCreate, services: Svc, principal: Operator) -> JSONResponse:
    info = services.jobs.create(
        revision_id=body.revision_id,
        quantity=body.quantity,
        due_at=body.due_at,
        priority=body.priority,
        machine_group=body.machine_group,
        cycle_time_s=body.cycle_time_s,
        actor=principal.user,
    )
    return JSONResponse(
        job_out(info).model_dump(mode="json"),
        status_code=201,
        headers={"Location": f"/api/jobs/{info.id}"},
    )


@router.get("/api/jobs", response_model=JobPage, summary="Jobs, oldest first (cursor pages)")
def list_jobs(
    request: Request,
    services: Svc,
    _: Viewer,
    status: Annotated[
        str | None, Query(pattern="^(queued|running|interrupted|completed|cancelled)$")
    ] = None,
    cursor: Annotated[str | None, Query(max_length=64)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
) -> JSONResponse:
    limit = min(limit, services.settings.page_limit_max)
    after = decode_cursor("j", cursor) if cursor else 0
    rows = services.jobs.list(status=status, after_id=after, limit=limit + 1)
    nxt = encode_cursor("j", rows[limit - 1].id) if len(rows) > limit else None
    body = JobPage(items=[job_out(j) for j in rows[:limit]], next_cursor=nxt)
    return JSONResponse(body.model_dump(mode="json"), headers=next_link(request, nxt))


@router.get(
    "/api/jobs/{job_id}",
    response_model=JobDetail,
    summary="One job with its allocations and the scheduler's decisions",
    responses=problem_doc(404),
)
def get_job(job_id: JobId, services: Svc, _: Viewer) -> JobDetail:
    jobs = services.jobs
    job = job_out(jobs.get(job_id))
    return JobDetail(
        **job.model_dump(),
        allocations=jobs.allocations(job_id),
        decisions=jobs.decisions(job_id=job_id),
    )


@router.post(
    "/api/jobs/{job_id}/cancel",
    response_model=Job,
    summary="Cancel a job (parts already on a machine finish normally)",
    responses=problem_doc(404, 409),
)
def cancel_job(job_id: JobId, services: Svc, principal: Operator) -> Job:
    return job_out(services.jobs.cancel(job_id, actor=principal.user))
