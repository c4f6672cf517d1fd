"""HTTP API: one router per resource, mounted by `app.main.create_app`."""

from __future__ import annotations

from fastapi import APIRouter

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

api_router = APIRouter()
for module in (health, courts, calibrations, jobs, project, ui, docs):
    api_router.include_router(module.router)
# the browser page's resources (issue 7)
for module in (me, court_jobs, cameras, pictures, demo):
    api_router.include_router(module.router)
