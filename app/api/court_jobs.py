"""A court's recent jobs (running, queued, failed and succeeded), newest first."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from app.api.deps import SessionDep, TenantDep
from app.api.routing import ApiRoute
from app.api.serialize import job_out
from app.db import repo
from app.schemas import JobList

router = APIRouter(tags=["jobs"], route_class=ApiRoute)


@router.get("/courts/{court_id}/jobs", response_model=JobList)
def list_court_jobs(
    court_id: str,
    session: SessionDep,
    tenant_id: TenantDep,
    limit: Annotated[int, Query(ge=1, le=200)] = 20,
) -> JobList:
    jobs = repo.list_jobs(session, tenant_id, court_id, limit)
    attempts = repo.attempts_of_jobs(session, [job.id for job in jobs])
    return JobList(jobs=[job_out(job, attempts[job.id]) for job in jobs])
