"""The media sweep: uploads of failed jobs after the retention period, and job and calibration
folders without their row (on SQLite and PostgreSQL)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy import update

from app.db import repo
from app.db.models import Calibration, Job, new_id, utcnow
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.media.store import media_store
from app.media.sweep import SweepReport, sweep_media
from app.settings import Settings
from tests.service.conftest import api_client

pytestmark = pytest.mark.both_databases

DAY_S = 24 * 3600.0


def _job_with_upload(settings: Settings, sessions, court_id: str, tenant_id: str) -> str:
    job_id = new_id()
    folder = media_store(settings).create_job_dir(job_id)
    (folder / "000.png").write_bytes(b"stored upload")
    with sessions.begin() as session:
        repo.new_job(
            session,
            job_id=job_id,
            tenant_id=tenant_id,
            court_id=court_id,
            media_kind="images",
            media_files=["000.png"],
            params={},
            max_attempts=1,
        )
    return job_id


def _set_status(sessions, job_id: str, status: str, finished_days_ago: float) -> None:
    with sessions.begin() as session:
        session.execute(
            update(Job)
            .where(Job.id == job_id)
            .values(status=status, finished_at=utcnow() - timedelta(days=finished_days_ago))
        )


def _orphan(settings: Settings, age_s: float) -> str:
    orphan_id = new_id()
    folder = media_store(settings).create_job_dir(orphan_id)
    part = folder / "part000.tmp"
    part.write_bytes(b"half an upload")
    _last_written(age_s, part, folder)
    return orphan_id


def _last_written(age_s: float, *paths: Path) -> None:
    then = time.time() - age_s
    for path in paths:
        os.utime(path, (then, then))


def _calibration_folder(settings: Settings, age_s: float, calibration_id: str | None = None) -> str:
    """A calibration's folder of images as the worker writes it, last written `age_s` ago."""
    calibration_id = calibration_id or new_id()
    folder = media_store(settings).calibration_dir(calibration_id)
    folder.mkdir(parents=True)
    image = folder / "overlay.png"
    image.write_bytes(b"png")
    _last_written(age_s, image, folder)
    return calibration_id


def _stored_calibration(settings: Settings, sessions, court_id: str, tenant_id: str) -> str:
    """A calibration with its row (an imported camera's: no job) and a folder a day old."""
    calibration_id = new_id()
    with sessions.begin() as session:
        session.add(
            Calibration(
                id=calibration_id,
                tenant_id=tenant_id,
                court_id=court_id,
                job_id=None,
                spec="wsf",
                genome=[0.0] * 15,
                opencv={},
                fitness=None,
                quality={},
                result={},
                image_width=64,
                image_height=48,
            )
        )
    return _calibration_folder(settings, DAY_S, calibration_id)


def test_sweep_removes_old_failed_uploads_and_quiet_orphans_only(
    new_settings: Callable[..., Settings],
) -> None:
    settings = new_settings(failed_media_retention_s=2 * DAY_S, orphan_media_grace_s=3600)
    engine = make_engine(settings)
    sessions = make_sessionmaker(engine)
    with sessions.begin() as session:
        key_row, _ = repo.create_api_key(session, name="t")
        court = repo.create_court(session, key_row.tenant_id, "c", "wsf")
        tenant_id, court_id = key_row.tenant_id, court.id
    old_failure = _job_with_upload(settings, sessions, court_id, tenant_id)
    _set_status(sessions, old_failure, "failed", finished_days_ago=3)
    recent_failure = _job_with_upload(settings, sessions, court_id, tenant_id)
    _set_status(sessions, recent_failure, "failed", finished_days_ago=1)
    old_success = _job_with_upload(settings, sessions, court_id, tenant_id)
    _set_status(sessions, old_success, "succeeded", finished_days_ago=30)
    queued = _job_with_upload(settings, sessions, court_id, tenant_id)
    crashed_upload = _orphan(settings, age_s=2 * 3600)
    upload_in_progress = _orphan(settings, age_s=60)
    stored = _stored_calibration(settings, sessions, court_id, tenant_id)
    worker_killed_while_storing = _calibration_folder(settings, age_s=2 * 3600)
    being_stored = _calibration_folder(settings, age_s=60)

    report = sweep_media(media_store(settings), sessions, settings)
    engine.dispose()

    assert report == SweepReport(
        failed_uploads_removed=1, orphans_removed=1, orphan_calibrations_removed=1
    )
    left = {d.id for d in media_store(settings).job_dirs()}
    assert left == {recent_failure, old_success, queued, upload_in_progress}
    assert crashed_upload not in left and old_failure not in left
    calibrations_left = {d.id for d in media_store(settings).calibration_dirs()}
    assert calibrations_left == {stored, being_stored}
    assert worker_killed_while_storing not in calibrations_left


def test_api_sweeps_orphans_at_start(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings(orphan_media_grace_s=10)
    store = media_store(settings)
    crashed_upload = store.job_dir(_orphan(settings, age_s=60))
    unstored_calibration = store.calibration_dir(_calibration_folder(settings, age_s=60))
    with api_client(create_app(settings)) as client:
        deadline = time.monotonic() + 10
        while crashed_upload.exists() or unstored_calibration.exists():
            assert time.monotonic() < deadline, "the startup sweep did not remove the orphans"
            time.sleep(0.05)
        assert client.get("/healthz").status_code == 200
