"""Courts: create, list, read; the active camera; the court's calibrations."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import SessionDep, TenantDep
from app.api.errors import ApiError
from app.api.serialize import calibration_out, court_out
from app.calib.court import COURT_SPECS
from app.db import repo
from app.db.models import Court
from app.schemas import CalibrationList, CalibrationOut, CourtCreate, CourtList, CourtOut

router = APIRouter(prefix="/courts", tags=["courts"])


@router.post("", status_code=201, response_model=CourtOut)
def create_court(body: CourtCreate, session: SessionDep, tenant_id: TenantDep) -> CourtOut:
    if body.spec not in COURT_SPECS:
        known = ", ".join(sorted(COURT_SPECS))
        raise ApiError(422, "unknown_spec", f"unknown court spec {body.spec!r}; known: {known}")
    court = repo.create_court(session, tenant_id, body.name, body.spec)
    session.commit()
    return court_out(court)


@router.get("", response_model=CourtList)
def list_courts(session: SessionDep, tenant_id: TenantDep) -> CourtList:
    return CourtList(courts=[court_out(c) for c in repo.list_courts(session, tenant_id)])


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
def list_calibrations(court_id: str, session: SessionDep, tenant_id: TenantDep) -> CalibrationList:
    court = repo.get_owned(session, Court, tenant_id, court_id)
    return CalibrationList(
        calibrations=[
            calibration_out(c, active=c.id == court.active_calibration_id)
            for c in repo.list_calibrations(session, tenant_id, court_id)
        ]
    )
