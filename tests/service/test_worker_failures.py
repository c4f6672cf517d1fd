"""How the worker records a failed job: the exception table, retry backoff, and a database that
is away while the failure (or a success) is recorded, on SQLite and PostgreSQL."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import pytest
from sqlalchemy import event, select
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from app.calib import scene, synthetic
from app.calib.pipeline import CourtNotFound
from app.db import queue, repo
from app.db.models import (
    AttemptOutcome,
    Calibration,
    Court,
    JobAttempt,
    JobStatus,
    new_id,
    utcnow,
)
from app.db.session import make_engine, make_sessionmaker
from app.media import MediaError, media_store
from app.settings import Settings
from tests.service.test_queue import add_jobs, job_row
from worker import main as worker_main
from worker.errors import classify


def db_down() -> OperationalError:
    return OperationalError("UPDATE jobs ...", {}, ConnectionRefusedError("connection refused"))


@pytest.mark.parametrize(
    ("exc", "code", "retryable", "log_traceback"),
    [
        (MediaError("corrupt_image", "cannot decode 000.png"), "corrupt_image", False, False),
        (CourtNotFound("no court lines"), "court_not_found", False, False),
        (ValueError("array must not contain infs or NaNs"), "internal_error", True, True),
        (ZeroDivisionError("float division by zero"), "internal_error", True, True),
        (db_down(), "database_error", True, True),
        (OSError(28, "No space left on device"), "storage_error", True, True),
        (MemoryError(), "out_of_memory", True, True),
    ],
)
def test_each_exception_has_one_code_and_retryability(
    exc: Exception, code: str, retryable: bool, log_traceback: bool
) -> None:
    failure = classify(exc)
    assert (failure.code, failure.retryable, failure.log_traceback) == (
        code,
        retryable,
        log_traceback,
    )
    assert failure.message


def test_a_value_error_is_ours_not_invalid_input() -> None:
    failure = classify(ValueError("SVD did not converge"))
    assert failure.code == "internal_error"
    assert failure.message == "ValueError: SVD did not converge"


@pytest.fixture
def settings(new_settings: Callable[..., Settings]) -> Settings:
    # a short lease: recording a failure or a success is given up after one lease. On SQLite, or
    # also on PostgreSQL for the tests marked both_databases
    return new_settings(lease_s=1.0, heartbeat_s=0.3, progress_interval_s=0.1, retry_backoff_s=30.0)


def run_failing_job(settings: Settings, exc: Exception, monkeypatch) -> tuple[str, str]:
    """Claim a job and process it with a background step that raises `exc`: (status, job id)."""

    def broken_background(settings: Settings, job: queue.ClaimedJob):
        raise exc

    monkeypatch.setattr(worker_main, "_background", broken_background)
    engine = make_engine(settings)
    try:
        _, [job_id] = add_jobs(engine, 1)
        job = queue.claim(engine, "w", settings.lease_s)
        assert job is not None
        shutdown = worker_main.Shutdown(threading.Event())
        return worker_main.process_job(engine, settings, job, "w", shutdown), job_id
    finally:
        engine.dispose()


@pytest.mark.both_databases
def test_a_bug_is_logged_with_its_traceback_and_retried_after_a_backoff(
    settings: Settings, monkeypatch, caplog
) -> None:
    before = utcnow()
    with caplog.at_level(logging.ERROR, logger="squashcal.worker"):
        status, job_id = run_failing_job(settings, ValueError("bad numerics"), monkeypatch)
    assert status == JobStatus.QUEUED
    [record] = [r for r in caplog.records if r.exc_info]
    assert isinstance(record.exc_info[1], ValueError)
    engine = make_engine(settings)
    try:
        row = job_row(engine, job_id)
        assert (row.error_code, row.error_message) == ("internal_error", "ValueError: bad numerics")
        assert row.run_after is not None
        assert 29 < (row.run_after - before).total_seconds() < 32  # the first backoff: 30 s
        assert queue.claim(engine, "w2", settings.lease_s) is None  # not before then
    finally:
        engine.dispose()


@pytest.mark.both_databases
def test_a_failure_is_recorded_once_the_database_is_back(
    settings: Settings, monkeypatch, caplog
) -> None:
    real_finish_failure = queue.finish_failure
    calls = []

    def flaky_finish_failure(*args, **kwargs):
        calls.append(1)
        if len(calls) <= 2:
            raise db_down()
        return real_finish_failure(*args, **kwargs)

    monkeypatch.setattr(queue, "finish_failure", flaky_finish_failure)
    status, job_id = run_failing_job(settings, CourtNotFound("no court"), monkeypatch)
    assert status == JobStatus.FAILED and len(calls) == 3
    assert "retrying" in caplog.text
    engine = make_engine(settings)
    try:
        assert job_row(engine, job_id).error_code == "court_not_found"
    finally:
        engine.dispose()


@pytest.mark.both_databases
def test_a_database_away_for_good_does_not_kill_the_worker(settings: Settings, monkeypatch) -> None:
    def finish_failure_down(*args, **kwargs):
        raise db_down()

    monkeypatch.setattr(queue, "finish_failure", finish_failure_down)
    # process_job returns (the worker goes on polling); the job's lease brings it back
    status, job_id = run_failing_job(settings, CourtNotFound("no court"), monkeypatch)
    assert status == "unrecorded"
    engine = make_engine(settings)
    try:
        assert job_row(engine, job_id).status == JobStatus.RUNNING
    finally:
        engine.dispose()


def queue_a_job_of_court_images(settings: Settings) -> str:
    """A queued job whose upload is three rendered frames of a court, as the API stores one."""
    size = (640, 360)
    frames = scene.render_clip_frames(synthetic.typical_target_camera(size), size, 3, 3)
    job_id = new_id()
    folder = media_store(settings).create_job_dir(job_id)
    names = [f"{i:03d}.png" for i in range(len(frames))]
    for name, frame in zip(names, frames, strict=True):
        assert cv2.imwrite(str(folder / name), frame)
    engine = make_engine(settings)
    try:
        with make_sessionmaker(engine).begin() as session:
            key_row, _ = repo.create_api_key(session, name="t")
            court = repo.create_court(session, key_row.tenant_id, "c", "wsf")
            repo.new_job(
                session,
                job_id=job_id,
                tenant_id=key_row.tenant_id,
                court_id=court.id,
                media_kind="images",
                media_files=names,
                params={"seed": 0},
                max_attempts=3,
            )
    finally:
        engine.dispose()
    return job_id


@pytest.mark.both_databases
def test_a_success_is_stored_once_the_database_is_back(settings: Settings, caplog) -> None:
    """The connection drops while the finished calibration is stored: first its INSERT fails,
    then the COMMIT goes through but its answer is lost. The worker tries again; the job ends
    succeeded on its first attempt, with its calibration and the calibration's images."""
    job_id = queue_a_job_of_court_images(settings)
    engine = make_engine(settings)
    inserts: list[str] = []
    answer_lost = []

    def drop_the_first_insert(conn, cursor, statement, parameters, context, executemany) -> None:
        if statement.startswith("INSERT INTO calibrations"):
            inserts.append(statement)
            if len(inserts) == 1:
                raise db_down()

    def lose_the_answer_of_the_next_commit(session: Session) -> None:
        if len(inserts) == 2 and not answer_lost:
            answer_lost.append(True)
            raise db_down()

    event.listen(engine, "before_cursor_execute", drop_the_first_insert)
    event.listen(Session, "after_commit", lose_the_answer_of_the_next_commit)
    try:
        job = queue.claim(engine, "w", settings.lease_s)
        assert job is not None and job.id == job_id
        status = worker_main.process_job(
            engine, settings, job, "w", worker_main.Shutdown(threading.Event())
        )
    finally:
        event.remove(Session, "after_commit", lose_the_answer_of_the_next_commit)
        event.remove(engine, "before_cursor_execute", drop_the_first_insert)
    try:
        assert status == JobStatus.SUCCEEDED
        assert len(inserts) == 2 and answer_lost == [True]
        assert "storing the calibration of job" in caplog.text and "retrying" in caplog.text
        row = job_row(engine, job_id)
        assert (row.status, row.attempts, row.error_code) == (JobStatus.SUCCEEDED, 1, None)
        with make_sessionmaker(engine)() as session:
            calibration = session.get(Calibration, row.calibration_id)
            assert calibration is not None and calibration.job_id == job_id
            court = session.get(Court, calibration.court_id)
            assert court is not None and court.active_calibration_id == calibration.id
            outcomes = session.scalars(select(JobAttempt.outcome)).all()
        assert outcomes == [AttemptOutcome.SUCCEEDED]
        images = media_store(settings).calibration_dir(calibration.id)
        assert {"background.png", "overlay.png", "edges.png"} <= {p.name for p in images.iterdir()}
    finally:
        engine.dispose()


# A worker whose warm-up is slow (an empty numba cache on a busy machine compiles for tens of
# seconds; here a stand-in that reports it has begun and sleeps), run as its own process.
SLOW_WARM_UP_WORKER = """
import sys, time
from pathlib import Path
from app.calib import warmup
from app.settings import get_settings
from worker import main as worker_main

def slow_warm_up(parts):
    Path(sys.argv[1]).touch()
    time.sleep(120)

warmup.warm_up = slow_warm_up
sys.exit(worker_main.run_worker(get_settings(), worker_id="slow-warm-up"))
"""


def test_sigterm_during_the_warm_up_stops_the_worker_at_once(settings: Settings) -> None:
    """It holds no job yet: nothing to finish, so it must not compile on before it stops (a
    supervisor, or a test, that waits a bounded time for it would otherwise kill it)."""
    started = settings.data_dir / "warm-up-started"
    env = {**os.environ, "SQUASHCAL_DATA_DIR": str(settings.data_dir), "SQUASHCAL_WARM_UP": "1"}
    process = subprocess.Popen(
        [sys.executable, "-c", SLOW_WARM_UP_WORKER, str(started)],
        cwd=Path(__file__).resolve().parents[2],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 60
        while not started.exists():
            assert process.poll() is None, process.communicate()[0].decode()
            assert time.monotonic() < deadline, "the warm-up never began"
            time.sleep(0.05)
        process.send_signal(signal.SIGTERM)
        code = process.wait(10)
    finally:
        if process.poll() is None:
            process.kill()
    output = process.communicate()[0].decode()
    assert code == 0, output
    assert "stopped during the warm-up" in output
