"""The jobs table as a queue, on SQLite and PostgreSQL: atomic claims, leases, retries, finishing."""

from __future__ import annotations

import threading
from datetime import datetime, timedelta

import pytest
from sqlalchemy import select, text
from sqlalchemy.exc import IntegrityError

from app.db import queue, repo
from app.db.models import Calibration, Court, Job, JobAttempt, JobStage, JobStatus, new_id, utcnow
from app.db.session import make_sessionmaker


def add_jobs(
    engine, n: int, max_attempts: int = 3, created_at: datetime | None = None
) -> tuple[str, list[str]]:
    """One tenant, one court, `n` queued jobs created one after another (1 ms apart from
    `created_at`, default now); -> (court id, job ids)."""
    job_ids = []
    with make_sessionmaker(engine).begin() as session:
        key_row, _ = repo.create_api_key(session, name="t")
        court = repo.create_court(session, key_row.tenant_id, "c", "wsf")
        court_id = court.id
        base = created_at or utcnow()
        for i in range(n):
            job = repo.new_job(
                session,
                job_id=new_id(),
                tenant_id=key_row.tenant_id,
                court_id=court_id,
                media_kind="images",
                media_files=["000.png"],
                params={"seed": i},
                max_attempts=max_attempts,
            )
            job.created_at = base + timedelta(milliseconds=i)
            job_ids.append(job.id)
    return court_id, job_ids


def job_row(engine, job_id: str) -> Job:
    with make_sessionmaker(engine)() as session:
        job = session.get(Job, job_id)
        assert job is not None
        return job


def make_calibration(job: queue.ClaimedJob) -> Calibration:
    return Calibration(
        id=new_id(),
        tenant_id=job.tenant_id,
        court_id=job.court_id,
        job_id=job.id,
        spec=job.spec,
        genome=[0.0] * 15,
        opencv={},
        fitness=1.0,
        quality={},
        result={},
        image_width=64,
        image_height=48,
    )


def test_claims_oldest_first_and_only_once(engine) -> None:
    _, ids = add_jobs(engine, 2)
    first = queue.claim(engine, "w1", lease_s=60)
    second = queue.claim(engine, "w2", lease_s=60)
    assert first is not None and second is not None
    assert (first.id, second.id) == (ids[0], ids[1])
    assert first.attempt == 1 and first.spec == "wsf" and first.params == {"seed": 0}
    assert queue.claim(engine, "w3", lease_s=60) is None
    row = job_row(engine, ids[0])
    assert (row.status, row.worker_id, row.attempts) == ("running", "w1", 1)
    assert row.lease_expires_at is not None and row.lease_expires_at > utcnow()


def claims_of_workers_at_once(engine, finish: bool, n_workers: int = 4) -> list[tuple[str, str]]:
    """(job id, worker) of every claim `n_workers` threads make, each claiming (and finishing, if
    `finish`) until the queue has nothing for it; an exception in any thread fails the test."""
    claims: list[tuple[str, str]] = []
    lock = threading.Lock()
    errors: list[BaseException] = []

    def worker(name: str) -> None:
        try:
            while (job := queue.claim(engine, name, lease_s=60)) is not None:
                with lock:
                    claims.append((job.id, name))
                if finish:
                    queue.finish_success(engine, job, name, make_calibration(job), {})
        except BaseException as exc:  # surfaced below
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(f"w{i}",)) for i in range(n_workers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert errors == []
    return claims


def test_concurrent_claims_never_share_a_job_and_each_opens_its_attempt(engine) -> None:
    _, ids = add_jobs(engine, 12)
    claims = claims_of_workers_at_once(engine, finish=False)
    assert sorted(job_id for job_id, _ in claims) == sorted(ids)  # each exactly once
    with make_sessionmaker(engine)() as session:
        opened = [(a.job_id, a.worker_id) for a in session.scalars(select(JobAttempt))]
    assert sorted(opened) == sorted(claims)  # one attempt per claim, under its worker


def test_expired_lease_is_reclaimed_and_the_old_worker_is_fenced_off(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    old = queue.claim(engine, "old", lease_s=60)
    assert old is not None
    assert queue.claim(engine, "new", lease_s=60) is None
    later = utcnow() + timedelta(seconds=61)
    new = queue.claim(engine, "new", lease_s=60, now=later)
    assert new is not None and new.id == job_id and new.attempt == 2
    # the stalled worker wakes up: its heartbeat, failure and success all fail to apply
    assert not queue.heartbeat(engine, job_id, "old", lease_s=60)
    with pytest.raises(queue.LeaseLost):
        queue.finish_failure(engine, job_id, "old", "x", "y", retryable=True)
    with pytest.raises(queue.LeaseLost):
        queue.finish_success(engine, old, "old", make_calibration(old), {})
    with make_sessionmaker(engine)() as session:
        assert session.scalars(select(Calibration)).all() == []
    assert queue.heartbeat(engine, job_id, "new", lease_s=60)
    queue.finish_success(engine, new, "new", make_calibration(new), {"total": 1.0})
    row = job_row(engine, job_id)
    assert (row.status, row.attempts, row.progress, row.worker_id) == ("succeeded", 2, 1.0, "new")


def test_storing_the_same_calibration_again_does_nothing_more(engine) -> None:
    """The worker retries finish_success when the connection drops; if the commit had gone
    through, the retry finds the job succeeded with its calibration and stops there. Another
    calibration for the finished job is still refused."""
    _, [job_id] = add_jobs(engine, 1)
    job = queue.claim(engine, "w", lease_s=60)
    assert job is not None
    calibration = make_calibration(job)
    queue.finish_success(engine, job, "w", calibration, {"total": 1.0})
    queue.finish_success(engine, job, "w", calibration, {"total": 2.0})
    with pytest.raises(queue.LeaseLost):
        queue.finish_success(engine, job, "w", make_calibration(job), {})
    row = job_row(engine, job_id)
    assert (row.status, row.calibration_id, row.timings) == (
        "succeeded",
        calibration.id,
        {"total": 1.0},
    )
    with make_sessionmaker(engine)() as session:
        assert session.scalars(select(Calibration.id)).all() == [calibration.id]


def test_a_claim_that_waited_for_a_lock_still_gets_its_whole_lease(engine) -> None:
    """The claim first fails jobs whose last attempt's worker was lost; on PostgreSQL that waits
    for their row locks (here another transaction holds one for 1.5 s). The job it then claims
    must hold a lease counted from after the wait, not from the transaction's start."""
    wait_s, lease_s = 1.5, 60.0
    _, [lost_id, queued_id] = add_jobs(engine, 2, max_attempts=1)
    long_ago = utcnow() - timedelta(hours=1)
    claimed = queue.claim(engine, "dead", lease_s=10, now=long_ago)
    assert claimed is not None and claimed.id == lost_id  # its lease ran out long ago
    locked, released_at = threading.Event(), []

    def hold_the_lost_jobs_row() -> None:
        with engine.begin() as connection:
            connection.execute(
                text("UPDATE jobs SET updated_at = updated_at WHERE id = :id"), {"id": lost_id}
            )
            locked.set()
            threading.Event().wait(wait_s)
            released_at.append(utcnow())

    holder = threading.Thread(target=hold_the_lost_jobs_row)
    holder.start()
    assert locked.wait(10)
    job = queue.claim(engine, "live", lease_s=lease_s)
    holder.join()
    assert job is not None and job.id == queued_id
    lease_expires_at = job_row(engine, queued_id).lease_expires_at
    assert lease_expires_at is not None
    assert lease_expires_at >= released_at[0] + timedelta(seconds=lease_s - 0.25)
    assert job_row(engine, lost_id).error_code == "worker_lost"


def test_heartbeat_extends_the_lease_and_writes_progress(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    job = queue.claim(engine, "w", lease_s=5)
    assert job is not None
    later = utcnow() + timedelta(seconds=4)
    progress = queue.Progress(stage="optimising", progress=0.5, generation=120, best_fitness=3.5)
    assert queue.heartbeat(engine, job_id, "w", lease_s=5, progress=progress, now=later)
    # not claimable at 6 s: the heartbeat at 4 s moved the expiry to 9 s
    assert queue.claim(engine, "x", lease_s=5, now=later + timedelta(seconds=2)) is None
    row = job_row(engine, job_id)
    assert (row.stage, row.progress, row.generation, row.best_fitness) == (
        "optimising",
        0.5,
        120,
        3.5,
    )


def test_retryable_failures_requeue_until_max_attempts(engine) -> None:
    _, [job_id] = add_jobs(engine, 1, max_attempts=3)
    for attempt in (1, 2, 3):
        job = queue.claim(engine, "w", lease_s=60)
        assert job is not None and job.attempt == attempt
        status = queue.finish_failure(engine, job_id, "w", "boom", f"failure {attempt}", True)
        assert status == ("failed" if attempt == 3 else "queued")
    assert queue.claim(engine, "w", lease_s=60) is None
    row = job_row(engine, job_id)
    assert (row.status, row.error_code, row.error_message) == ("failed", "boom", "failure 3")
    assert row.finished_at is not None


def test_non_retryable_failure_fails_at_once(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    assert queue.claim(engine, "w", lease_s=60) is not None
    status = queue.finish_failure(engine, job_id, "w", "court_not_found", "no court", False)
    assert status == "failed"
    assert queue.claim(engine, "w", lease_s=60) is None


def test_worker_lost_on_every_attempt_fails_the_job(engine) -> None:
    _, [job_id] = add_jobs(engine, 1, max_attempts=2)
    now = utcnow()
    assert queue.claim(engine, "a", lease_s=10, now=now) is not None
    now += timedelta(seconds=11)
    assert queue.claim(engine, "b", lease_s=10, now=now) is not None
    now += timedelta(seconds=11)
    assert queue.claim(engine, "c", lease_s=10, now=now) is None
    row = job_row(engine, job_id)
    assert (row.status, row.error_code, row.attempts) == ("failed", "worker_lost", 2)


def test_release_gives_the_job_back_without_using_an_attempt(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    assert queue.claim(engine, "w", lease_s=60) is not None
    assert queue.release(engine, job_id, "w")
    assert not queue.release(engine, job_id, "w")  # only from the running state
    row = job_row(engine, job_id)
    assert (row.status, row.attempts, row.worker_id) == ("queued", 0, None)
    again = queue.claim(engine, "v", lease_s=60)
    assert again is not None and again.attempt == 1


def test_newest_upload_stays_the_active_camera(engine) -> None:
    court_id, [older_id, newer_id] = add_jobs(engine, 2)
    older = queue.claim(engine, "w1", lease_s=60)
    newer = queue.claim(engine, "w2", lease_s=60)
    assert older is not None and newer is not None and older.id == older_id
    newer_cal = make_calibration(newer)
    queue.finish_success(engine, newer, "w2", newer_cal, {})
    older_cal = make_calibration(older)
    queue.finish_success(engine, older, "w1", older_cal, {})  # finishes last
    with make_sessionmaker(engine)() as session:
        court = session.get(Court, court_id)
        assert court is not None and court.active_calibration_id == newer_cal.id
        assert len(session.scalars(select(Calibration)).all()) == 2
    assert job_row(engine, newer_id).calibration_id == newer_cal.id


def test_retry_waits_out_its_backoff(engine) -> None:
    _, [job_id] = add_jobs(engine, 1, max_attempts=3)
    now = utcnow()
    assert queue.claim(engine, "w", lease_s=60, now=now) is not None
    status = queue.finish_failure(
        engine, job_id, "w", "internal_error", "boom", True, now=now, retry_delay_s=5.0
    )
    assert status == JobStatus.QUEUED
    assert job_row(engine, job_id).run_after == now + timedelta(seconds=5)
    assert queue.claim(engine, "w", lease_s=60, now=now + timedelta(seconds=4.9)) is None
    again = queue.claim(engine, "w", lease_s=60, now=now + timedelta(seconds=5))
    assert again is not None and again.attempt == 2
    assert job_row(engine, job_id).run_after is None


def test_retry_delay_doubles_up_to_its_cap() -> None:
    delays = [queue.retry_delay_s(attempt, base_s=5, max_s=30) for attempt in (1, 2, 3, 4, 5)]
    assert delays == [5, 10, 20, 30, 30]


def test_claim_and_heartbeat_record_the_workers_last_sign_of_life(engine) -> None:
    _, [job_id] = add_jobs(engine, 1)
    now = utcnow()
    assert queue.claim(engine, "w", lease_s=10, now=now) is not None
    assert job_row(engine, job_id).heartbeat_at == now
    assert queue.heartbeat(engine, job_id, "w", lease_s=10, now=now + timedelta(seconds=2))
    row = job_row(engine, job_id)
    assert row.heartbeat_at == now + timedelta(seconds=2)
    assert row.lease_expires_at == now + timedelta(seconds=12)


@pytest.mark.parametrize("column", ["status", "stage"])
def test_the_database_refuses_unknown_status_and_stage(engine, column: str) -> None:
    _, [job_id] = add_jobs(engine, 1)
    with pytest.raises(IntegrityError), engine.begin() as conn:
        conn.execute(text(f"UPDATE jobs SET {column} = 'paused' WHERE id = :id"), {"id": job_id})
    row = job_row(engine, job_id)
    assert (row.status, row.stage) == (JobStatus.QUEUED, JobStage.QUEUED)


def test_claims_take_turns_across_tenants(engine) -> None:
    """Tenant A queued three jobs before tenant B queued its three: workers alternate."""
    _, a_ids = add_jobs(engine, 3)
    _, b_ids = add_jobs(engine, 3)
    claimed = [queue.claim(engine, f"w{i}", lease_s=60) for i in range(6)]
    assert [job.id for job in claimed if job] == [
        a_ids[0],
        b_ids[0],
        a_ids[1],
        b_ids[1],
        a_ids[2],
        b_ids[2],
    ]


def test_a_tenant_with_nothing_running_goes_first(engine) -> None:
    _, a_ids = add_jobs(engine, 4)
    _, [b_id] = add_jobs(engine, 1)
    claimed = [queue.claim(engine, f"w{i}", lease_s=60) for i in range(3)]
    # B's one job does not wait behind A's four; then A and B have one running each: oldest first
    assert [job.id for job in claimed if job] == [a_ids[0], b_id, a_ids[1]]


def test_a_dead_workers_job_does_not_count_as_running(engine) -> None:
    _, a_ids = add_jobs(engine, 2)
    _, b_ids = add_jobs(engine, 2)
    now = utcnow()
    assert queue.claim(engine, "live", lease_s=60, now=now).id == a_ids[0]  # type: ignore[union-attr]
    later = now + timedelta(seconds=1)
    assert queue.claim(engine, "dead", lease_s=10, now=later).id == b_ids[0]  # type: ignore[union-attr]
    # B's lease ran out: B has nothing running and A one job, so B's job is taken again, although
    # A's turn is the older one (were the dead job counted, A's next job would go first)
    later += timedelta(seconds=11)
    assert queue.claim(engine, "w", lease_s=60, now=later).id == b_ids[0]  # type: ignore[union-attr]


def test_one_worker_finishing_each_job_still_takes_turns_across_tenants(engine) -> None:
    """One worker (the default): when it claims, every tenant has nothing running. Tenant A
    queued three jobs, then B one: B's is the second job taken, not the fourth."""
    start = utcnow() - timedelta(minutes=1)
    _, a_ids = add_jobs(engine, 3, created_at=start)
    _, [b_id] = add_jobs(engine, 1, created_at=start + timedelta(seconds=1))
    taken = []
    while (job := queue.claim(engine, "only", lease_s=60)) is not None:
        taken.append(job.id)
        queue.finish_success(engine, job, "only", make_calibration(job), {})
    assert taken == [a_ids[0], b_id, a_ids[1], a_ids[2]]


def test_a_tenant_never_served_goes_before_one_served_before(engine) -> None:
    """A's job came first and was done; A's next and C's job wait together: C, never served,
    goes first although A's job is older."""
    start = utcnow() - timedelta(minutes=1)
    _, [a_first, a_next] = add_jobs(engine, 2, created_at=start)
    _, [c_id] = add_jobs(engine, 1, created_at=start + timedelta(seconds=1))
    job = queue.claim(engine, "w", lease_s=60)
    assert job is not None and job.id == a_first
    queue.finish_success(engine, job, "w", make_calibration(job), {})
    assert [queue.claim(engine, "w", lease_s=60).id for _ in range(2)] == [c_id, a_next]  # type: ignore[union-attr]


def test_workers_claiming_and_finishing_at_once_across_tenants_take_each_job_once(engine) -> None:
    """Claims of one tenant queue on its row for its turn (PostgreSQL): no deadlock, no job taken
    twice, every job done."""
    job_ids = [job_id for _ in range(3) for job_id in add_jobs(engine, 6)[1]]
    taken = [job_id for job_id, _ in claims_of_workers_at_once(engine, finish=True)]
    assert sorted(taken) == sorted(job_ids)
    with make_sessionmaker(engine)() as session:
        statuses = session.scalars(select(Job.status)).all()
    assert statuses == [JobStatus.SUCCEEDED] * len(job_ids)


def test_jobs_of_one_court_finishing_together_do_not_deadlock(engine) -> None:
    """Both transactions lock the court: they must queue on it, not deadlock (PostgreSQL)."""
    _, job_ids = add_jobs(engine, 40)
    errors: list[BaseException] = []

    def finish(job: queue.ClaimedJob, worker_id: str, barrier: threading.Barrier) -> None:
        barrier.wait()
        try:
            queue.finish_success(engine, job, worker_id, make_calibration(job), {})
        except BaseException as exc:  # surfaced below
            errors.append(exc)

    for _ in range(20):
        pair = [queue.claim(engine, f"w{i}", lease_s=60) for i in range(2)]
        barrier = threading.Barrier(2)
        threads = [
            threading.Thread(target=finish, args=(job, f"w{i}", barrier))
            for i, job in enumerate(pair)
            if job is not None
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
    assert errors == []
    with make_sessionmaker(engine)() as session:
        assert len(session.scalars(select(Calibration)).all()) == 40
