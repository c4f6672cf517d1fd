"""The jobs table as a work queue: enqueue (repo.new_job), claim, heartbeat, finish, release.

Every state change updates only rows in the state it expects (status and owning worker), so a worker
whose lease expired and whose job was re-claimed elsewhere cannot overwrite the new owner's work.
Claims take turns across tenants: the next job is the oldest of the tenant with the fewest running
jobs and, among tenants equal in that, the one whose last claim is the oldest (never claimed:
first); each claim records its time on the tenant's row (tenants.last_claimed_at). The running
count shares the workers out; the turns matter when it is even, as with one worker (the
default), where every tenant has nothing running at each claim: tenant A's pile of three then
goes A, B, A, A when B's one job came after them, not A, A, A, B. On PostgreSQL two workers
claiming at the same instant may both see the same counts and turns, so fairness is approximate
there; exclusivity is not. Claims are atomic: on SQLite the transaction starts with BEGIN
IMMEDIATE (one writer at a time, so the select-then-update inside one UPDATE statement cannot
race, and each claim sees the turns of the one before); on PostgreSQL the candidate row is locked
with FOR UPDATE SKIP LOCKED so concurrent workers pick different jobs without waiting.

Every claim opens a row of job_attempts, and whatever ends the attempt closes it, in the same
transaction as the change to the job: finishing, failing, giving the job back, or, for a worker
whose lease ran out, the claim that takes the job again (or fails it as worker_lost). So the
attempts table says who held which job when, and never disagrees with the jobs table. Each of those
transactions changes the jobs row before the job's attempts, so on PostgreSQL they queue on the job
row and cannot deadlock over attempts. A claim writes its tenant's row last, after which it waits
for nothing: claims of one tenant queue there for a moment and cannot deadlock (uploads only
share-lock the row for their foreign key, which that write does not block).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import Engine, func, insert, or_, select, update
from sqlalchemy.orm import Session, aliased

from app.db.models import (
    AttemptOutcome,
    Calibration,
    Court,
    Job,
    JobAttempt,
    JobStage,
    JobStatus,
    Tenant,
    utcnow,
)
from app.db.session import write_engine


class LeaseLost(RuntimeError):
    """The job is no longer running under this worker (lease expired and someone else took it)."""


@dataclass(frozen=True)
class ClaimedJob:
    id: str
    tenant_id: str
    court_id: str
    spec: str
    attempt: int
    max_attempts: int
    media_kind: str
    media_files: list[str]
    params: dict[str, Any]
    created_at: datetime


@dataclass
class Progress:
    stage: JobStage
    progress: float
    generation: int | None = None
    best_fitness: float | None = None


def _expired(now: datetime) -> Any:
    return (Job.status == JobStatus.RUNNING) & (Job.lease_expires_at < now)


def _due(now: datetime) -> Any:
    """Queued and past its retry backoff."""
    return (Job.status == JobStatus.QUEUED) & (Job.run_after.is_(None) | (Job.run_after <= now))


def retry_delay_s(attempt: int, base_s: float, max_s: float) -> float:
    """Backoff before attempt `attempt + 1` after attempt `attempt` failed: base, 2 x base, ..."""
    return min(max_s, base_s * 2.0 ** max(0, attempt - 1))


def _now_under_lock(session: Session, now: datetime | None) -> datetime:
    """The time for a write, read once the transaction holds its lock. On SQLite, BEGIN IMMEDIATE
    may wait seconds for other writers: a lease computed from a clock read before that wait could
    be expired on arrival, and another worker would claim the job at once."""
    session.connection()  # opens the transaction (BEGIN IMMEDIATE on SQLite), waiting if need be
    return now or utcnow()


def _running_jobs_of_the_same_tenant(now: datetime) -> Any:
    """For a candidate row of `jobs`: how many jobs its tenant has running (live leases only)."""
    busy = aliased(Job, name="busy")
    return (
        select(func.count(busy.id))
        .where(
            busy.tenant_id == Job.tenant_id,
            busy.status == JobStatus.RUNNING,
            busy.lease_expires_at >= now,
        )
        .correlate(Job)
        .scalar_subquery()
    )


def _last_claim_of_the_same_tenant() -> Any:
    """For a candidate row of `jobs`: when its tenant last had a job claimed (None: never)."""
    return (
        select(Tenant.last_claimed_at)
        .where(Tenant.id == Job.tenant_id)
        .correlate(Job)
        .scalar_subquery()
    )


def _open_attempt(
    session: Session, job_id: str, attempt: int, worker_id: str, now: datetime
) -> None:
    session.execute(
        insert(JobAttempt).values(
            job_id=job_id, attempt=attempt, worker_id=worker_id, claimed_at=now
        )
    )


def _close_own_attempt(
    session: Session,
    job_id: str,
    worker_id: str,
    outcome: AttemptOutcome,
    now: datetime,
    error_code: str | None = None,
) -> None:
    """End the open attempt of `worker_id` at `job_id` (the caller has just checked, in this
    transaction, that the job is running under that worker). A job claimed before the attempts
    table existed has no open attempt: nothing to end."""
    session.execute(
        update(JobAttempt)
        .where(
            JobAttempt.job_id == job_id,
            JobAttempt.worker_id == worker_id,
            JobAttempt.ended_at.is_(None),
        )
        .values(ended_at=now, outcome=outcome, error_code=error_code)
        .execution_options(synchronize_session=False)
    )


def _close_lost_attempts(session: Session, job_ids: list[str], now: datetime) -> None:
    """End, as lease_lost, the open attempts of jobs whose lease expired and that this transaction
    has just reclaimed or failed. It is the moment the queue took the job from the silent worker,
    so that is the attempt's end (the worker itself may have died any time after its last renewal)."""
    if not job_ids:
        return
    session.execute(
        update(JobAttempt)
        .where(JobAttempt.job_id.in_(job_ids), JobAttempt.ended_at.is_(None))
        .values(ended_at=now, outcome=AttemptOutcome.LEASE_LOST)
        .execution_options(synchronize_session=False)
    )


def claim(
    engine: Engine, worker_id: str, lease_s: float, now: datetime | None = None
) -> ClaimedJob | None:
    """Atomically take a claimable job (queued and due, or running with an expired lease): the
    oldest of the tenant with the fewest running jobs and, among those, the longest since its
    last claim, so that one tenant's pile of uploads does not hold back another tenant's single
    one (whether several workers run or one)."""
    given = now
    with Session(write_engine(engine), expire_on_commit=False) as session, session.begin():
        now = _now_under_lock(session, given)
        # A job whose worker died on its last attempt will never be retried: fail it with a reason.
        worker_lost = session.scalars(
            update(Job)
            .where(_expired(now), Job.attempts >= Job.max_attempts)
            .values(
                status=JobStatus.FAILED,
                stage=JobStage.DONE,
                error_code="worker_lost",
                error_message=(
                    "the worker running this job stopped responding (lease expired) and the job "
                    "has used all its attempts"
                ),
                worker_id=None,
                lease_expires_at=None,
                finished_at=now,
                updated_at=now,
            )
            .returning(Job.id)
            .execution_options(synchronize_session=False)
        ).all()
        _close_lost_attempts(session, list(worker_lost), now)
        # On PostgreSQL that statement waits for the row locks of the jobs it fails (another
        # worker's claim or heartbeat holds them for a moment): the lease starts now, not when
        # the transaction began, or it would arrive already shortened by the wait.
        now = given or utcnow()
        candidate = (
            select(Job.id)
            .where(or_(_due(now), _expired(now)), Job.attempts < Job.max_attempts)
            .order_by(
                _running_jobs_of_the_same_tenant(now),
                _last_claim_of_the_same_tenant().nulls_first(),
                Job.created_at,
                Job.id,
            )
            .limit(1)
            .with_for_update(skip_locked=True)
            .scalar_subquery()
        )
        job = session.scalars(
            update(Job)
            .where(Job.id == candidate)
            .values(
                status=JobStatus.RUNNING,
                stage=JobStage.BACKGROUND,
                progress=0.0,
                generation=None,
                best_fitness=None,
                attempts=Job.attempts + 1,
                worker_id=worker_id,
                lease_expires_at=now + timedelta(seconds=lease_s),
                heartbeat_at=now,
                run_after=None,
                started_at=now,
                updated_at=now,
            )
            .returning(Job)
            .execution_options(synchronize_session=False)
        ).first()
        if job is None:
            return None
        # An attempt still open here is the previous holder's, whose lease ran out: every other way
        # out of the running state closes its attempt in its own transaction.
        _close_lost_attempts(session, [job.id], now)
        _open_attempt(session, job.id, job.attempts, worker_id, now)
        # the tenant's turn is taken; written last (see the module's note on locks)
        session.execute(
            update(Tenant)
            .where(Tenant.id == job.tenant_id)
            .values(last_claimed_at=now)
            .execution_options(synchronize_session=False)
        )
        court = session.get(Court, job.court_id)
        if court is None:  # FK cascade makes this impossible short of manual surgery
            raise RuntimeError(f"job {job.id} refers to a missing court {job.court_id}")
        return ClaimedJob(
            id=job.id,
            tenant_id=job.tenant_id,
            court_id=job.court_id,
            spec=court.spec,
            attempt=job.attempts,
            max_attempts=job.max_attempts,
            media_kind=job.media_kind,
            media_files=list(job.media_files),
            params=dict(job.params),
            created_at=job.created_at,
        )


def _owned_running(job_id: str, worker_id: str) -> Any:
    return (Job.id == job_id) & (Job.status == JobStatus.RUNNING) & (Job.worker_id == worker_id)


def heartbeat(
    engine: Engine,
    job_id: str,
    worker_id: str,
    lease_s: float,
    progress: Progress | None = None,
    now: datetime | None = None,
) -> bool:
    """Renew the lease (and write progress). False when the job is no longer ours."""
    with Session(write_engine(engine)) as session, session.begin():
        now = _now_under_lock(session, now)
        values: dict[str, Any] = {
            "lease_expires_at": now + timedelta(seconds=lease_s),
            "heartbeat_at": now,
            "updated_at": now,
        }
        if progress is not None:
            values.update(
                stage=progress.stage,
                progress=min(1.0, max(0.0, float(progress.progress))),
                generation=progress.generation,
                best_fitness=progress.best_fitness,
            )
        result = session.execute(
            update(Job)
            .where(_owned_running(job_id, worker_id))
            .values(**values)
            .execution_options(synchronize_session=False)
        )
        return bool(result.rowcount)  # type: ignore[attr-defined]


def finish_success(
    engine: Engine,
    job: ClaimedJob,
    worker_id: str,
    calibration: Calibration,
    timings: dict[str, float],
    now: datetime | None = None,
) -> None:
    """Store the calibration, mark the job succeeded and make it the court's active camera: one
    transaction. The court's camera only moves forward: an older upload finishing late does not
    replace the camera of a newer one. Raises LeaseLost (and stores nothing) if the job is not ours.

    Safe to call again with the same calibration after an error (the worker retries it): when the
    connection dropped after the database committed but before it said so, the job has already
    succeeded with this calibration, and the call does nothing more.
    """
    with Session(write_engine(engine), expire_on_commit=False) as session, session.begin():
        now = _now_under_lock(session, now)
        result = session.execute(
            update(Job)
            .where(_owned_running(job.id, worker_id))
            .values(
                status=JobStatus.SUCCEEDED,
                stage=JobStage.DONE,
                progress=1.0,
                calibration_id=calibration.id,
                error_code=None,
                error_message=None,
                timings=timings,
                lease_expires_at=None,
                finished_at=now,
                updated_at=now,
            )
            .execution_options(synchronize_session=False)
        )
        if not result.rowcount:  # type: ignore[attr-defined]
            stored = session.scalar(
                select(Job.calibration_id).where(
                    Job.id == job.id, Job.status == JobStatus.SUCCEEDED
                )
            )
            if stored == calibration.id:  # an earlier call committed it (ids are never reused)
                return
            raise LeaseLost(f"job {job.id} is no longer running under worker {worker_id}")
        _close_own_attempt(session, job.id, worker_id, AttemptOutcome.SUCCEEDED, now)
        # Lock the court before inserting the calibration: the insert's foreign-key check takes a
        # share lock on the court row, and two jobs of one court that both hold it and then ask
        # for FOR UPDATE deadlock on PostgreSQL.
        court = session.scalars(
            select(Court).where(Court.id == job.court_id).with_for_update()
        ).one()
        session.add(calibration)
        newer_than_active = True
        if court.active_calibration_id is not None:
            active_job_created = session.scalar(
                select(Job.created_at)
                .join(Calibration, Calibration.job_id == Job.id)
                .where(Calibration.id == court.active_calibration_id)
            )
            newer_than_active = active_job_created is None or active_job_created <= job.created_at
        if newer_than_active:
            session.flush()
            court.active_calibration_id = calibration.id


def finish_failure(
    engine: Engine,
    job_id: str,
    worker_id: str,
    code: str,
    message: str,
    retryable: bool,
    timings: dict[str, float] | None = None,
    now: datetime | None = None,
    retry_delay_s: float = 0.0,
) -> JobStatus:
    """Record an error. Retryable errors requeue the job while attempts remain, claimable again
    `retry_delay_s` from now; returns the new status (queued or failed). Raises LeaseLost if the
    job is not ours."""
    with Session(write_engine(engine), expire_on_commit=False) as session, session.begin():
        now = _now_under_lock(session, now)
        row = session.execute(
            select(Job.attempts, Job.max_attempts).where(_owned_running(job_id, worker_id))
        ).first()
        if row is None:
            raise LeaseLost(f"job {job_id} is no longer running under worker {worker_id}")
        attempts, max_attempts = row
        requeue = retryable and attempts < max_attempts
        status = JobStatus.QUEUED if requeue else JobStatus.FAILED
        values: dict[str, Any] = {
            "status": status,
            "stage": JobStage.QUEUED if requeue else JobStage.DONE,
            "error_code": code,
            "error_message": message,
            "worker_id": None,
            "lease_expires_at": None,
            "run_after": now + timedelta(seconds=retry_delay_s) if requeue else None,
            "updated_at": now,
        }
        if not requeue:
            values["finished_at"] = now
        if timings is not None:
            values["timings"] = timings
        result = session.execute(
            update(Job)
            .where(_owned_running(job_id, worker_id))
            .values(**values)
            .execution_options(synchronize_session=False)
        )
        if not result.rowcount:  # type: ignore[attr-defined]
            raise LeaseLost(f"job {job_id} is no longer running under worker {worker_id}")
        outcome = AttemptOutcome.FAILED_RETRY if requeue else AttemptOutcome.FAILED
        _close_own_attempt(session, job_id, worker_id, outcome, now, error_code=code)
        return status


def release(engine: Engine, job_id: str, worker_id: str, now: datetime | None = None) -> bool:
    """Give a job back to the queue without counting the attempt (worker shutting down)."""
    with Session(write_engine(engine), expire_on_commit=False) as session, session.begin():
        now = _now_under_lock(session, now)
        result = session.execute(
            update(Job)
            .where(_owned_running(job_id, worker_id))
            .values(
                status=JobStatus.QUEUED,
                stage=JobStage.QUEUED,
                attempts=Job.attempts - 1,
                worker_id=None,
                lease_expires_at=None,
                updated_at=now,
            )
            .execution_options(synchronize_session=False)
        )
        if not result.rowcount:  # type: ignore[attr-defined]
            return False
        _close_own_attempt(session, job_id, worker_id, AttemptOutcome.RELEASED, now)
        return True
