"""Liveness and readiness."""

from __future__ import annotations

from fastapi import APIRouter
from starlette.concurrency import run_in_threadpool

from app.api.deps import StateDep
from app.api.errors import ApiError
from app.api.routing import ApiRoute
from app.db.migrate import current_revision
from app.schemas import Health, Ready

router = APIRouter(tags=["health"], route_class=ApiRoute)


@router.get("/healthz", response_model=Health)
def healthz() -> Health:
    """The process is up."""
    return Health(status="ok")


@router.get("/readyz", response_model=Ready)
async def readyz(state: StateDep) -> Ready:
    """The database answers, its schema is at the migrations' head, and the numerical kernels
    are loaded (so that no request pays their compile)."""
    if not state.kernels_ready.is_set():
        raise ApiError(503, "warming_up", "loading the numerical kernels; ready in a few seconds")
    try:
        revision = await run_in_threadpool(current_revision, state.engine)
    except Exception:
        raise ApiError(503, "database_unreachable", "the database is not reachable") from None
    if revision != state.head_revision:
        raise ApiError(
            503,
            "migrations_pending",
            f"database schema is at {revision!r}, code expects {state.head_revision!r}: "
            "run `squashcal migrate`",
        )
    # the database's kind and version are nobody's business outside: status and schema only
    return Ready(status="ready", revision=revision)
