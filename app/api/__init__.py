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

# /project first: routes are matched in order, and it is the hot path (issue 8); then the
# browser page's resources (issue 7). Every module's router uses app.api.routing.ApiRoute.
ROUTER_MODULES = (project, health, courts, calibrations, jobs, ui, docs) + (
    me,
    court_jobs,
    cameras,
    pictures,
    demo,
)
api_router = APIRouter()
for module in ROUTER_MODULES:
    api_router.include_router(module.router)
