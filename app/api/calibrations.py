"""Calibration uploads (-> queued job) and stored calibrations with their images."""

from __future__ import annotations

import math
from datetime import timedelta
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import FileResponse, JSONResponse
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from app import media
from app.api import uploads
from app.api.deps import AppState, SessionDep, StateDep, TenantDep
from app.api.errors import ApiError
from app.api.routing import ApiRoute
from app.api.serialize import calibration_out
from app.db import repo
from app.db.models import Calibration, Court, Job, new_id, utcnow
from app.media import probe
from app.schemas import CalibrationOut, ErrorResponse, JobAccepted
from app.settings import Settings

router = APIRouter(tags=["calibrations"], route_class=ApiRoute)

_UPLOAD_FORM: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["files"],
                    "properties": {
                        "files": {
                            "type": "array",
                            "minItems": 1,
                            "items": {"type": "string", "format": "binary"},
                            "description": "one or more PNG/JPEG images of the same fixed camera,"
                            " or one MP4/MOV/MKV/AVI/WebM clip (type read from the bytes)",
                        },
                        "start_camera": {
                            "type": "string",
                            "description": "optional start camera: a genome (15 numbers) or the "
                            'OpenCV JSON form {"K", "dist", "rvec", "tvec", "image_size"}',
                        },
                        "seed": {"type": "integer", "minimum": 0, "maximum": 2**63 - 1},
                        "bundle": {"type": "string", "description": "GA operator bundle name"},
                    },
                }
            }
        },
    }
}
_ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorResponse} for code in (401, 404, 413, 415, 422, 429)
}


UPLOAD_RATE_WINDOW = timedelta(hours=1)


def _refuse_if_over_limits(
    session: Session, tenant_id: str, settings: Settings, counted_uploads: int = 0
) -> None:
    """429 while the tenant already has its share of waiting jobs, or of uploads this hour
    (beyond `counted_uploads` of them: the uploads of this request already counted)."""
    if repo.count_queued_jobs(session, tenant_id) >= settings.max_queued_jobs_per_tenant:
        raise ApiError(
            429,
            "too_many_queued_jobs",
            f"{settings.max_queued_jobs_per_tenant} of your calibrations are already waiting; "
            "upload again when some have run",
            headers={"Retry-After": str(settings.queue_full_retry_after_s)},
        )
    now = utcnow()
    count, oldest = repo.uploads_since(session, tenant_id, now - UPLOAD_RATE_WINDOW)
    if count - counted_uploads >= settings.max_uploads_per_hour_per_tenant:
        assert oldest is not None  # the window holds at least one upload
        retry_after_s = max(1, math.ceil((oldest + UPLOAD_RATE_WINDOW - now).total_seconds()))
        raise ApiError(
            429,
            "too_many_uploads",
            f"{count} calibrations were uploaded with your key in the last hour, the most "
            f"allowed; upload again in {retry_after_s} s",
            headers={"Retry-After": str(retry_after_s)},
        )


@router.post(
    "/courts/{court_id}/calibrations",
    status_code=202,
    response_model=JobAccepted,
    openapi_extra=_UPLOAD_FORM,
    responses=_ERRORS,
)
async def upload_calibration(
    court_id: str, request: Request, state: StateDep, tenant_id: TenantDep
) -> JSONResponse:
    """Store the upload, queue a calibration job and answer at once (202 + Location)."""
    settings = state.settings

    def owned_court_with_room_in_the_queue() -> Court:
        with state.write_sessions.begin() as session:
            court = repo.get_owned(session, Court, tenant_id, court_id)
            _refuse_if_over_limits(session, tenant_id, settings)
            # counted whatever becomes of it (a refused one too): refused for its content in a
            # loop, it would otherwise cost receiving and probing without limit
            now = utcnow()
            repo.record_upload_attempt(session, tenant_id, now, now - UPLOAD_RATE_WINDOW)
            return court

    # 404 or 429 before reading a byte of the body
    await run_in_threadpool(owned_court_with_room_in_the_queue)
    job_id = new_id()
    store = media.media_store(settings)
    target = store.create_job_dir(job_id)
    try:
        received = await uploads.receive_upload(request, target, settings)
        summary = await run_in_threadpool(probe.check_upload, target, received.files, settings)
        params = uploads.parse_job_params(received.fields, summary.image_size)
        params["image_size"] = list(summary.image_size)
        # on disk (and on a shared volume, visible to every host) before the job exists
        await run_in_threadpool(store.persist, target)

        def commit_job() -> None:
            with state.write_sessions.begin() as session:
                # others came in meanwhile (this upload is counted already)
                _refuse_if_over_limits(session, tenant_id, settings, counted_uploads=1)
                repo.new_job(
                    session,
                    job_id=job_id,
                    tenant_id=tenant_id,
                    court_id=court_id,
                    media_kind=summary.kind,
                    media_files=[f.name for f in received.files],
                    params=params,
                    max_attempts=settings.max_attempts,
                )

        await run_in_threadpool(commit_job)
    except OperationalError:
        # The connection can drop after the database committed and before it said so: then
        # the job exists, and removing its media would lose an accepted upload (and the
        # client's retry of the 503 would queue it twice). Keep the media unless the job is
        # known not to exist; a folder without a job is swept later (orphan_media_grace_s).
        # (The commit is the only database call in this block.)
        stored = await run_in_threadpool(_job_stored, state, job_id)
        if stored is True:
            return _accepted(job_id)
        if stored is False:
            store.remove_job_dir(job_id)
        raise
    except BaseException:
        store.remove_job_dir(job_id)
        raise
    return _accepted(job_id)


def _job_stored(state: AppState, job_id: str) -> bool | None:
    """Whether the job's row exists; None when the database cannot say now."""
    try:
        with state.sessions() as session:
            return session.get(Job, job_id) is not None
    except OperationalError:
        return None


def _accepted(job_id: str) -> JSONResponse:
    return JSONResponse(
        {"job_id": job_id, "status": "queued"},
        status_code=202,
        headers={"Location": f"/jobs/{job_id}"},
    )


@router.get("/calibrations/{calibration_id}", response_model=CalibrationOut)
def get_calibration(
    calibration_id: str, session: SessionDep, tenant_id: TenantDep
) -> CalibrationOut:
    cal = repo.get_owned(session, Calibration, tenant_id, calibration_id)
    court = repo.get_owned(session, Court, tenant_id, cal.court_id)
    return calibration_out(cal, active=court.active_calibration_id == cal.id)


def _calibration_image(
    calibration_id: str, name: str, state: StateDep, session: SessionDep, tenant_id: str
) -> FileResponse:
    cal = repo.get_owned(session, Calibration, tenant_id, calibration_id)
    path = media.calibration_dir(state.settings, cal.id) / name
    if not path.is_file():
        raise ApiError(404, "image_missing", f"{name} of calibration {cal.id} is not on disk")
    return FileResponse(path, media_type="image/png")


@router.get(
    "/calibrations/{calibration_id}/background.png",
    response_class=FileResponse,
    responses={200: {"content": {"image/png": {}}}},
)
def get_background(
    calibration_id: str, state: StateDep, session: SessionDep, tenant_id: TenantDep
) -> FileResponse:
    """The player-free background the camera was fitted to."""
    return _calibration_image(calibration_id, "background.png", state, session, tenant_id)
