"""Courts: create, list, read; the active camera; the court's calibrations."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, TypeVar

from fastapi import APIRouter, Query

from app.api.deps import SessionDep, TenantDep, WriteSessionDep
from app.api.errors import ApiError
from app.api.routing import ApiRoute
from app.api.serialize import calibration_out, court_out
from app.db import repo
from app.db.models import Court
from app.schemas import CalibrationList, CalibrationOut, CourtCreate, CourtList, CourtOut

router = APIRouter(prefix="/courts", tags=["courts"], route_class=ApiRoute)


@router.post("", status_code=201, response_model=CourtOut)
def create_court(body: CourtCreate, session: WriteSessionDep, tenant_id: TenantDep) -> CourtOut:
    court = repo.create_court(session, tenant_id, body.name, body.spec)
    session.commit()
    return court_out(court)


MAX_PAGE = 500
# far beyond any real list, and small enough for every database's integer OFFSET
MAX_OFFSET = 1_000_000_000
# a paged list's query parameters: GET /courts, GET /courts/{id}/calibrations
PageLimit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="items per page")]
PageOffset = Annotated[
    int, Query(ge=0, le=MAX_OFFSET, description="items to skip: the previous `next_offset`")
]
T = TypeVar("T")


def _page(rows: Sequence[T], limit: int, offset: int) -> tuple[Sequence[T], int | None]:
    """The page and the next page's offset (None on the last page) from `limit + 1` rows read
    at `offset`: the extra row tells whether another page exists without a COUNT query."""
    return rows[:limit], (offset + limit if len(rows) > limit else None)


@router.get("", response_model=CourtList)
def list_courts(
    session: SessionDep, tenant_id: TenantDep, limit: PageLimit = 100, offset: PageOffset = 0
) -> CourtList:
    """The tenant's courts, oldest first, one page at a time: follow `next_offset` until null."""
    rows, next_offset = _page(
        repo.list_courts(session, tenant_id, limit + 1, offset), limit, offset
    )
    return CourtList(courts=[court_out(c) for c in rows], next_offset=next_offset)


@router.get("/{court_id}", response_model=CourtOut)
def get_court(court_id: str, session: SessionDep, tenant_id: TenantDep) -> CourtOut:
    return court_out(repo.get_owned(session, Court, tenant_id, court_id))


@router.get("/{court_id}/camera", response_model=CalibrationOut)
def get_camera(court_id: str, session: SessionDep, tenant_id: TenantDep) -> CalibrationOut:
    cal = repo.active_calibration(session, tenant_id, court_id)
    if cal is None:
        raise ApiError(
            404,
            "no_calibration",
            f"court {court_id!r} has no calibration yet: upload frames or a clip to "
            f"POST /courts/{court_id}/calibrations and wait for the job to succeed",
        )
    return calibration_out(cal, active=True)


@router.get("/{court_id}/calibrations", response_model=CalibrationList)
def list_calibrations(
    court_id: str,
    session: SessionDep,
    tenant_id: TenantDep,
    limit: PageLimit = 100,
    offset: PageOffset = 0,
) -> CalibrationList:
    """The court's calibrations, newest first, one page at a time: follow `next_offset` until
    null."""
    court = repo.get_owned(session, Court, tenant_id, court_id)
    rows, next_offset = _page(
        repo.list_calibrations(session, tenant_id, court.id, limit + 1, offset), limit, offset
    )
    return CalibrationList(
        calibrations=[calibration_out(c, active=c.id == court.active_calibration_id) for c in rows],
        next_offset=next_offset,
    )
