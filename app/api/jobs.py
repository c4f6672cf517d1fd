"""Calibration jobs: status, stage, progress, errors."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import SessionDep, TenantDep
from app.api.routing import ApiRoute
from app.api.serialize import job_out
from app.db import repo
from app.db.models import Job
from app.schemas import JobOut

router = APIRouter(prefix="/jobs", tags=["jobs"], route_class=ApiRoute)


@router.get("/{job_id}", response_model=JobOut)
def get_job(job_id: str, session: SessionDep, tenant_id: TenantDep) -> JobOut:
    job = repo.get_owned(session, Job, tenant_id, job_id)
    return job_out(job, repo.attempts_of_jobs(session, [job.id])[job.id])
