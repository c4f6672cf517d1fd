"""Rows -> response models (one place, so every endpoint shows a resource the same way)."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime

import numpy as np

from app.db.models import Calibration, Court, Job, JobAttempt, JobStatus, utcnow
from app.schemas import (
    CalibrationOut,
    CameraPose,
    CourtOut,
    JobAttemptOut,
    JobError,
    JobOut,
    OpenCVCamera,
    Verdict,
)
from app.viewer.camera_text import camera_pose


def court_out(court: Court) -> CourtOut:
    return CourtOut(
        id=court.id,
        name=court.name,
        spec=court.spec,  # type: ignore[arg-type]  # one of COURT_SPECS: only those are stored
        active_calibration_id=court.active_calibration_id,
        created_at=court.created_at,
    )


def job_attempt_out(attempt: JobAttempt) -> JobAttemptOut:
    return JobAttemptOut(
        attempt=attempt.attempt,
        claimed_at=attempt.claimed_at,
        ended_at=attempt.ended_at,
        outcome=attempt.outcome.value if attempt.outcome is not None else None,
        error_code=attempt.error_code,
    )


def job_out(job: Job, attempts: Sequence[JobAttempt], now: datetime | None = None) -> JobOut:
    """`attempts`: the job's attempts in the order of their claims (repo.attempts_of_jobs)."""
    now = now or utcnow()
    stale = (
        job.status == JobStatus.RUNNING
        and job.lease_expires_at is not None
        and job.lease_expires_at < now
    )
    error = None
    if job.status == JobStatus.FAILED and job.error_code is not None:
        error = JobError(code=job.error_code, message=job.error_message or "")
    return JobOut(
        id=job.id,
        court_id=job.court_id,
        status=job.status.value,
        stage=job.stage.value,
        progress=job.progress,
        generation=job.generation,
        best_fitness=job.best_fitness,
        attempts=job.attempts,
        max_attempts=job.max_attempts,
        heartbeat_at=job.heartbeat_at,
        stale=stale,
        media_kind=job.media_kind,  # type: ignore[arg-type]
        n_files=len(job.media_files),
        error=error,
        calibration_id=job.calibration_id,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
        timings_s={k: float(v) for k, v in (job.timings or {}).items()},
        attempt_history=[job_attempt_out(a) for a in attempts],
    )


def calibration_out(cal: Calibration, active: bool) -> CalibrationOut:
    result = cal.result or {}
    verdict = result.get("verdict")
    pose = camera_pose(np.asarray(cal.genome), (cal.image_width, cal.image_height))
    return CalibrationOut(
        id=cal.id,
        court_id=cal.court_id,
        job_id=cal.job_id,
        source="upload" if cal.job_id is not None else "import",
        spec=cal.spec,
        opencv=OpenCVCamera(**cal.opencv),
        genome=list(cal.genome),
        fitness=cal.fitness,
        quality=cal.quality,
        verdict=Verdict.model_validate(verdict) if isinstance(verdict, dict) else None,
        uncertainty=result.get("uncertainty")
        if isinstance(result.get("uncertainty"), dict)
        else None,
        pose=CameraPose(**pose),
        timings_s={k: float(v) for k, v in (result.get("timings_s") or {}).items()},
        seed=result.get("seed"),
        bundle=result.get("bundle"),
        generations=result.get("generations"),
        created_at=cal.created_at,
        active=active,
        background_url=f"/calibrations/{cal.id}/background.png",
        overlay_url=f"/calibrations/{cal.id}/overlay.png",
    )
