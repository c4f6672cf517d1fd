"""HTTP API: one router per resource, mounted by `app.main.create_app`."""

from __future__ import annotations

from fastapi import APIRouter, Depends

from app.api import (
    calibrations,
    cameras,
    court_jobs,
    courts,
    demo,
    docs,
    health,
    jobs,
    me,
    pictures,
    project,
    ui,
)
from app.api.deps import reject_unknown_query

api_router = APIRouter(dependencies=[Depends(reject_unknown_query)])
for module in (health, courts, calibrations, jobs, project, ui, docs):
    api_router.include_router(module.router)
# the browser page's resources (issue 7)
for module in (me, court_jobs, cameras, pictures, demo):
    api_router.include_router(module.router)
