"""HTTP API: one router per resource, mounted by `app.main.create_app`."""

from __future__ import annotations

from fastapi import APIRouter

from app.api import calibrations, courts, health, jobs, project, ui

api_router = APIRouter()
for module in (health, courts, calibrations, jobs, project, ui):
    api_router.include_router(module.router)
