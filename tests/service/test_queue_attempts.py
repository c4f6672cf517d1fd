"""The queue's record of attempts (job_attempts), on SQLite and PostgreSQL: each claim opens one,
and whatever ends it (success, failure, retry, release, a lease that ran out) closes it with the
right outcome at the right time, in the same transaction as the change to the job."""

from __future__ import annotations

import itertools
from datetime import datetime, timedelta

import pytest
import sqlalchemy as sa
from sqlalchemy import select, text
from sqlalchemy.exc import IntegrityError

from app.db import queue, repo
from app.db.models import AttemptOutcome, Calibration, JobAttempt, JobStatus, utcnow
from app.db.session import make_sessionmaker
from tests.service.test_queue import add_jobs, job_row, make_calibration


def attempts_of(engine: sa.Engine, job_id: str) -> list[JobAttempt]:
    """The job's attempts in the order of their claims, as the API reads them."""
    with make_sessionmaker(engine)() as session:
        return repo.attempts_of_jobs(session, [job_id])[job_id]


def summary(attempt: JobAttempt) -> tuple[int, str, str | None, str | None]:
    """(attempt number, worker, outcome, error code): what the tests compare."""
    outcome = attempt.outcome.value if attempt.outcome is not None else None
    return attempt.attempt, attempt.worker_id, outcome, attempt.error_code


def claim_at(engine: sa.Engine, worker_id: str, now: datetime) -> queue.ClaimedJob:
    job = queue.claim(engine, worker_id, lease_s=10, now=now)
    assert job is not None
    return job


def test_a_claim_opens_an_attempt(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    claim_at(engine, "w", now)
    [attempt] = attempts_of(engine, job_id)
    assert summary(attempt) == (1, "w", None, None)
    assert (attempt.claimed_at, attempt.ended_at) == (now, None)


def test_success_closes_the_attempt_as_succeeded(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    job = claim_at(engine, "w", now)
    done = now + timedelta(seconds=3)
    queue.finish_success(engine, job, "w", make_calibration(job), {}, now=done)
    [attempt] = attempts_of(engine, job_id)
    assert summary(attempt) == (1, "w", "succeeded", None)
    assert (attempt.claimed_at, attempt.ended_at) == (now, done)
    assert job_row(engine, job_id).finished_at == done


def test_a_failure_for_good_closes_the_attempt_as_failed_with_its_code(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    claim_at(engine, "w", now)
    done = now + timedelta(seconds=2)
    status = queue.finish_failure(
        engine, job_id, "w", "court_not_found", "no court", retryable=False, now=done
    )
    assert status == JobStatus.FAILED
    [attempt] = attempts_of(engine, job_id)
    assert summary(attempt) == (1, "w", "failed", "court_not_found")
    assert attempt.ended_at == done


def test_retries_close_each_attempt_as_failed_retry_and_the_last_as_failed(engine) -> None:
    _, [job_id] = add_jobs(engine, 1, max_attempts=3)
    now = utcnow()
    for attempt in (1, 2, 3):
        claim_at(engine, f"w{attempt}", now)
        queue.finish_failure(engine, job_id, f"w{attempt}", "internal_error", "boom", True, now=now)
    assert [summary(a) for a in attempts_of(engine, job_id)] == [
        (1, "w1", "failed_retry", "internal_error"),
        (2, "w2", "failed_retry", "internal_error"),
        (3, "w3", "failed", "internal_error"),
    ]


def test_a_release_closes_the_attempt_as_released_and_the_next_claim_has_its_number(
    engine,
) -> None:
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    claim_at(engine, "leaving", now)
    assert queue.release(engine, job_id, "leaving", now=now + timedelta(seconds=1))
    claim_at(engine, "next", now + timedelta(seconds=2))
    released, running = attempts_of(engine, job_id)
    assert summary(released) == (1, "leaving", "released", None)
    assert released.ended_at == now + timedelta(seconds=1)
    assert summary(running) == (1, "next", None, None)
    assert running.ended_at is None


def test_a_reclaim_after_the_lease_expired_closes_the_stale_attempt_as_lease_lost(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    claim_at(engine, "silent", now)
    reclaimed = now + timedelta(seconds=11)
    claim_at(engine, "next", reclaimed)
    stale, running = attempts_of(engine, job_id)
    assert summary(stale) == (1, "silent", "lease_lost", None)
    assert stale.ended_at == reclaimed  # closed by the reclaiming transaction, at its time
    assert summary(running) == (2, "next", None, None)
    assert running.claimed_at == reclaimed


def test_a_fenced_off_worker_changes_no_attempt(engine) -> None:
    """The silent worker wakes up after the reclaim: its failure and success are refused, and its
    attempt stays lease_lost, the new holder's open."""
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    silent = claim_at(engine, "silent", now)
    claim_at(engine, "next", now + timedelta(seconds=11))
    before = [summary(a) for a in attempts_of(engine, job_id)]
    with pytest.raises(queue.LeaseLost):
        queue.finish_failure(engine, job_id, "silent", "internal_error", "late", retryable=True)
    with pytest.raises(queue.LeaseLost):
        queue.finish_success(engine, silent, "silent", make_calibration(silent), {})
    assert not queue.release(engine, job_id, "silent")
    assert [summary(a) for a in attempts_of(engine, job_id)] == before
    assert before == [(1, "silent", "lease_lost", None), (2, "next", None, None)]


def test_the_last_attempt_lost_fails_the_job_and_closes_the_attempt_as_lease_lost(
    engine,
) -> None:
    _, [job_id] = add_jobs(engine, 1, max_attempts=1)
    now = utcnow()
    claim_at(engine, "silent", now)
    noticed = now + timedelta(seconds=11)
    assert queue.claim(engine, "other", lease_s=10, now=noticed) is None
    row = job_row(engine, job_id)
    assert (row.status, row.error_code) == (JobStatus.FAILED, "worker_lost")
    [attempt] = attempts_of(engine, job_id)
    assert summary(attempt) == (1, "silent", "lease_lost", None)
    assert attempt.ended_at == noticed


def test_a_job_retried_after_a_lost_lease_and_a_failure_keeps_every_attempt(engine) -> None:
    _, [job_id] = add_jobs(engine, 1, max_attempts=3)
    now = utcnow()
    claim_at(engine, "killed", now)
    now += timedelta(seconds=11)
    claim_at(engine, "failing", now)
    queue.finish_failure(engine, job_id, "failing", "storage_error", "disk full", True, now=now)
    now += timedelta(seconds=1)
    job = claim_at(engine, "lucky", now)
    queue.finish_success(engine, job, "lucky", make_calibration(job), {}, now=now)
    attempts = attempts_of(engine, job_id)
    assert [summary(a) for a in attempts] == [
        (1, "killed", "lease_lost", None),
        (2, "failing", "failed_retry", "storage_error"),
        (3, "lucky", "succeeded", None),
    ]
    assert job_row(engine, job_id).attempts == 3
    for before, after in itertools.pairwise(attempts):
        assert before.ended_at is not None and before.ended_at <= after.claimed_at


def test_a_job_without_attempt_rows_still_finishes(engine) -> None:
    """A job claimed before the attempts table existed (no open attempt) finishes as before."""
    _, [job_id] = add_jobs(engine, 1)
    job = claim_at(engine, "w", utcnow())
    with engine.begin() as conn:
        conn.execute(text("DELETE FROM job_attempts"))
    queue.finish_success(engine, job, "w", make_calibration(job), {})
    assert job_row(engine, job_id).status == JobStatus.SUCCEEDED
    assert attempts_of(engine, job_id) == []
    with make_sessionmaker(engine)() as session:
        assert len(session.scalars(select(Calibration)).all()) == 1


def insert_attempt(engine: sa.Engine, job_id: str, **columns: object) -> None:
    values = {"job_id": job_id, "attempt": 1, "worker_id": "w", "claimed_at": utcnow(), **columns}
    with engine.begin() as conn:
        conn.execute(sa.insert(JobAttempt).values(**values))


def test_the_database_refuses_an_unknown_outcome(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    insert_attempt(engine, job_id, ended_at=utcnow(), outcome=AttemptOutcome.SUCCEEDED)
    with pytest.raises(IntegrityError), engine.begin() as conn:
        conn.execute(text("UPDATE job_attempts SET outcome = 'paused'"))


@pytest.mark.parametrize(
    "columns",
    [
        {"ended_at": utcnow()},  # ended, but how?
        {"outcome": AttemptOutcome.SUCCEEDED},  # an outcome, but still running?
    ],
    ids=["ended_without_outcome", "outcome_while_open"],
)
def test_the_database_refuses_an_attempt_half_ended(engine, columns: dict) -> None:
    _, [job_id] = add_jobs(engine, 1)
    with pytest.raises(IntegrityError):
        insert_attempt(engine, job_id, **columns)


def test_the_database_refuses_a_second_open_attempt_of_a_job(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    insert_attempt(engine, job_id, worker_id="first")
    with pytest.raises(IntegrityError):
        insert_attempt(engine, job_id, worker_id="second")
    # a closed one may sit beside the open one
    insert_attempt(engine, job_id, ended_at=utcnow(), outcome=AttemptOutcome.RELEASED)
