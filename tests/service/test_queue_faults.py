"""The queue under faults, with real worker processes (tests/service/fake_worker.py: the real worker
loop and bookkeeping, a stand-in calibration of a fraction of a second), on SQLite and PostgreSQL:
many jobs and workers, SIGKILLed and SIGTERMed workers, a database that goes away.

Who held which job when is read from the queue's own record, the job_attempts table; the fake
worker's events add what the database cannot see (a stalled worker still computing after the queue
gave its job to another).
"""

from __future__ import annotations

import itertools
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections import Counter, defaultdict
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa
from sqlalchemy import select

from app.db import repo
from app.db.models import AttemptOutcome, Calibration, Job, JobAttempt, JobStatus
from app.db.session import SQLITE_BEGIN_OPTION, make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import POSTGRES_ADMIN_URL, api_client
from tests.service.test_queue import add_jobs
from worker.main import HARD_EXIT_AFTER_S

REPO_ROOT = Path(__file__).resolve().parents[2]

# Short leases so that a killed worker's job comes back within seconds (but not so short that a
# worker starved of SQLite's write lock for a moment on this busy 2-core machine loses its job).
FAST_QUEUE = {
    "lease_s": 2.5,
    "heartbeat_s": 0.4,
    "progress_interval_s": 0.2,
    "poll_interval_s": 0.05,
    "retry_backoff_s": 0.1,
    "retry_backoff_max_s": 0.5,
    "shutdown_grace_s": 0,
}


class Workers:
    """Worker processes on the settings' database, each incarnation with its own log file:
    here the product's own `python -m worker` (what `squashcal run` starts)."""

    def __init__(self, settings: Settings, tmp_path: Path, **overrides: object):
        self.settings = settings
        self.log_dir = tmp_path / "logs"
        self.log_dir.mkdir(exist_ok=True)
        # named connections, so that a test can cut exactly these from PostgreSQL
        self.application_name = f"squashcal_faults_{uuid.uuid4().hex[:8]}"
        url = settings.sqlalchemy_url
        if not settings.is_sqlite:
            url += f"&application_name={self.application_name}"
        self.env = {
            **os.environ,
            "SQUASHCAL_DATA_DIR": str(settings.data_dir),
            "SQUASHCAL_DATABASE_URL": url,
            **{f"SQUASHCAL_{k.upper()}": str(v) for k, v in {**FAST_QUEUE, **overrides}.items()},
        }
        self.processes: dict[str, subprocess.Popen[bytes]] = {}
        self.log_paths: dict[int, Path] = {}  # by pid
        self.started = 0

    def command(self, name: str) -> list[str]:
        return [sys.executable, "-m", "worker"]

    def start(self, name: str) -> subprocess.Popen[bytes]:
        self.started += 1
        path = self.log_dir / f"{name}-{self.started}.log"
        with path.open("wb") as log:
            process = subprocess.Popen(
                self.command(name), cwd=REPO_ROOT, env=self.env, stdout=log, stderr=log
            )
        self.processes[name] = process
        self.log_paths[process.pid] = path
        return process

    def stop_all(self, timeout_s: float = 20) -> dict[str, int | None]:
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        codes: dict[str, int | None] = {}
        for name, process in self.processes.items():
            try:
                codes[name] = process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                process.kill()
                codes[name] = process.wait()
        return codes


class FakeWorkers(Workers):
    """Fake-calibration worker processes (tests/service/fake_worker.py), with their event logs."""

    def __init__(self, settings: Settings, tmp_path: Path, work_s: float, **overrides: object):
        super().__init__(settings, tmp_path, fake_work_s=work_s, **overrides)
        self.events_dir = tmp_path / "events"

    def command(self, name: str) -> list[str]:
        return [sys.executable, "-m", "tests.service.fake_worker", name, str(self.events_dir)]

    def wait_until_up(self, timeout_s: float = 40) -> None:
        """Until every worker started has imported its modules (seconds each on a busy box)."""
        deadline = time.monotonic() + timeout_s
        while len([e for e in self.events() if e["event"] == "worker_started"]) < self.started:
            assert time.monotonic() < deadline, "workers did not start"
            time.sleep(0.1)

    def events(self) -> list[dict]:
        lines = []
        for path in sorted(self.events_dir.glob("*.jsonl")):
            lines += [json.loads(line) for line in path.read_text().splitlines() if line]
        return lines


@pytest.fixture
def workers_factory(any_db_settings: Settings, tmp_path: Path) -> Iterator:
    made: list[FakeWorkers] = []

    def make(work_s: float, **overrides: object) -> FakeWorkers:
        made.append(FakeWorkers(any_db_settings, tmp_path, work_s, **overrides))
        return made[-1]

    yield make
    for workers in made:
        workers.stop_all()


def queue_jobs(engine: sa.Engine, n_tenants: int, per_tenant: int) -> list[str]:
    ids: list[str] = []
    for _ in range(n_tenants):
        ids += add_jobs(engine, per_tenant, max_attempts=10)[1]
    return ids


def statuses(engine: sa.Engine) -> Counter[str]:
    with make_sessionmaker(engine)() as session:
        return Counter(str(s) for s in session.scalars(select(Job.status)))


def wait_until_all_finished(engine: sa.Engine, n: int, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        counts = statuses(engine)
        if counts[JobStatus.SUCCEEDED] + counts[JobStatus.FAILED] == n:
            return
        assert time.monotonic() < deadline, f"jobs not finished in {timeout_s} s: {counts}"
        time.sleep(0.2)


def jobs_each_succeeded_once(
    engine: sa.Engine, job_ids: list[str]
) -> tuple[dict[str, Job], list[Calibration]]:
    """The jobs (by id) and calibrations, asserting that every job succeeded with exactly one
    calibration."""
    with make_sessionmaker(engine)() as session:
        jobs = {j.id: j for j in session.scalars(select(Job))}
        calibrations = list(session.scalars(select(Calibration)))
    assert sorted(jobs) == sorted(job_ids)
    assert {j.status for j in jobs.values()} == {JobStatus.SUCCEEDED}, Counter(
        (j.status, j.error_code) for j in jobs.values()
    )
    assert sorted(str(c.job_id) for c in calibrations if c.job_id) == sorted(job_ids)  # once each
    return jobs, calibrations


def attempts_by_job(engine: sa.Engine) -> dict[str, list[JobAttempt]]:
    """Every job's attempts, in the order of their claims."""
    by_job: dict[str, list[JobAttempt]] = defaultdict(list)
    with make_sessionmaker(engine)() as session:
        for attempt in session.scalars(select(JobAttempt).order_by(JobAttempt.id)):
            by_job[attempt.job_id].append(attempt)
    return dict(by_job)


def describe(attempts: list[JobAttempt]) -> str:
    """The attempts, one per line, for an assertion's message."""
    return "\n".join(
        f"  #{a.attempt} {a.worker_id} {a.claimed_at:%H:%M:%S.%f} -> "
        f"{a.ended_at and f'{a.ended_at:%H:%M:%S.%f}'} {a.outcome} {a.error_code}"
        for a in attempts
    )


# how an attempt that was not the job's last may have ended
GAVE_WAY = {AttemptOutcome.LEASE_LOST, AttemptOutcome.FAILED_RETRY, AttemptOutcome.RELEASED}


def assert_attempts_show_one_holder_at_a_time_and_one_success(
    jobs: dict[str, Job], attempts: dict[str, list[JobAttempt]]
) -> None:
    """What the attempts table must say of jobs that all succeeded: no job held by two workers at
    once (each attempt ended before the next one was claimed; one the queue took back from a silent
    worker ended at that very claim), exactly one successful attempt per job (its last, by the
    worker and at the time the jobs row says), and the counted attempts numbered 1..attempts."""
    assert sorted(attempts) == sorted(jobs), "a job without attempts, or attempts of no job"
    for job_id, job in jobs.items():
        tries = attempts[job_id]
        story = f"job {job_id}:\n{describe(tries)}"
        for before, after in itertools.pairwise(tries):
            assert before.ended_at is not None and before.ended_at <= after.claimed_at, story
            assert before.outcome in GAVE_WAY, story
            if before.outcome == AttemptOutcome.LEASE_LOST:
                assert before.ended_at == after.claimed_at, story
        last = tries[-1]
        assert last.outcome == AttemptOutcome.SUCCEEDED, story
        assert (last.worker_id, last.ended_at) == (job.worker_id, job.finished_at), story
        counted = [a.attempt for a in tries if a.outcome != AttemptOutcome.RELEASED]
        assert counted == list(range(1, job.attempts + 1)), story


def assert_each_worker_held_one_job_at_a_time(attempts: dict[str, list[JobAttempt]]) -> None:
    """A worker process works on one job at a time: its attempts follow one another (worker ids
    must name one process each)."""
    by_worker: dict[str, list[JobAttempt]] = defaultdict(list)
    for attempt in sorted(itertools.chain(*attempts.values()), key=lambda a: a.id):
        by_worker[attempt.worker_id].append(attempt)
    for worker_id, tries in by_worker.items():
        for before, after in itertools.pairwise(tries):
            assert before.ended_at is not None and before.ended_at <= after.claimed_at, (
                f"worker {worker_id} held two jobs at once:\n{describe([before, after])}"
            )


def assert_each_job_succeeded_once_with_its_own_result(
    engine: sa.Engine, job_ids: list[str], workers: FakeWorkers, exclusive: bool = True
) -> list[Job]:
    """... and no job worked on by two live workers at once: strictly if `exclusive`; otherwise
    a worker that stalled past its lease (a loaded machine, a database outage) may still be
    computing when another claims the job, but it must then stop without storing anything (the
    lease fencing: the one result stored is not the stalled worker's). Either way the queue's record
    of attempts shows one holder at a time and one success per job."""
    jobs, calibrations = jobs_each_succeeded_once(engine, job_ids)
    assert_attempts_show_one_holder_at_a_time_and_one_success(jobs, attempts_by_job(engine))
    for cal in calibrations:
        job = jobs[str(cal.job_id)]
        assert job.calibration_id == cal.id
        assert cal.result["job_id"] == job.id
        assert cal.genome[0] == job.params["seed"]  # the job's own input made this result
        assert 1 <= job.attempts <= job.max_attempts
    events = workers.events()
    doubles = [e for e in events if e["event"] == "double_hold"]
    if exclusive:
        assert doubles == []
    stored_by = {cal.job_id: cal.result["worker_pid"] for cal in calibrations}
    for double in doubles:
        assert stored_by[double["job"]] != double["other_pid"], double
    return list(jobs.values())


@pytest.mark.slow
def test_200_jobs_on_4_workers_each_succeed_once(engine, workers_factory) -> None:
    job_ids = queue_jobs(engine, n_tenants=4, per_tenant=50)
    # a lease no hiccup outlasts: every job must succeed on its first attempt
    workers = workers_factory(work_s=0.02, lease_s=10, heartbeat_s=1)
    for i in range(4):
        workers.start(f"w{i}")
    workers.wait_until_up()
    wait_until_all_finished(engine, len(job_ids), timeout_s=50)
    jobs = assert_each_job_succeeded_once_with_its_own_result(engine, job_ids, workers)
    assert all(job.attempts == 1 for job in jobs)
    # the queue's record: one attempt per job, which succeeded, and no worker on two jobs at once
    attempts = attempts_by_job(engine)
    assert all(len(tries) == 1 for tries in attempts.values()), attempts
    assert_each_worker_held_one_job_at_a_time(attempts)
    # every worker took part, and all stop cleanly on SIGTERM
    assert len({job.worker_id for job in jobs}) == 4
    assert set(workers.stop_all().values()) == {0}


@pytest.mark.slow
def test_sigkilled_workers_are_restarted_and_every_job_still_succeeds(
    engine, workers_factory
) -> None:
    job_ids = queue_jobs(engine, n_tenants=4, per_tenant=20)
    workers = workers_factory(work_s=0.25)
    names = [f"w{i}" for i in range(4)]
    for name in names:
        workers.start(name)
    workers.wait_until_up()
    rng = random.Random(8)
    kills = 0
    deadline = time.monotonic() + 50
    while statuses(engine)[JobStatus.SUCCEEDED] < len(job_ids) and kills < 6:
        assert time.monotonic() < deadline
        time.sleep(rng.uniform(0.8, 1.5))
        victim = rng.choice(names)
        workers.processes[victim].send_signal(signal.SIGKILL)
        workers.processes[victim].wait(10)
        kills += 1
        workers.start(victim)
    wait_until_all_finished(engine, len(job_ids), timeout_s=deadline - time.monotonic())
    # short leases on a loaded box: a worker may stall past one (then it must be fenced off)
    jobs = assert_each_job_succeeded_once_with_its_own_result(
        engine, job_ids, workers, exclusive=False
    )
    # a killed worker's job was taken again: its attempts say so
    retried = [job for job in jobs if job.attempts > 1]
    assert retried, "no job was interrupted by the kills"
    started = Counter(e["job"] for e in workers.events() if e["event"] == "start")
    assert all(started[job.id] <= job.attempts for job in jobs)  # every start was a claim
    assert set(workers.stop_all().values()) == {0}


def wait_for_event(workers: FakeWorkers, kind: str, timeout_s: float) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = [e for e in workers.events() if e["event"] == kind]
        if found:
            return found[0]
        time.sleep(0.05)
    raise AssertionError(f"no {kind} event in {timeout_s} s")


def job_row(engine: sa.Engine, job_id: str) -> Job:
    with make_sessionmaker(engine)() as session:
        job = session.get(Job, job_id)
        assert job is not None
        return job


def assert_given_back_once(engine: sa.Engine, job_id: str, worker_id: str) -> None:
    """The job's one attempt was the worker's, and ended as released."""
    [attempt] = attempts_by_job(engine)[job_id]
    assert (attempt.attempt, attempt.worker_id) == (1, worker_id)
    assert attempt.outcome == AttemptOutcome.RELEASED and attempt.ended_at is not None


def test_sigterm_with_no_grace_gives_the_job_back_and_exits(engine, workers_factory) -> None:
    [job_id] = queue_jobs(engine, n_tenants=1, per_tenant=1)
    workers = workers_factory(work_s=30, shutdown_grace_s=0)
    worker = workers.start("w")
    wait_for_event(workers, "start", timeout_s=30)
    t0 = time.monotonic()
    worker.send_signal(signal.SIGTERM)
    assert worker.wait(10) == 0
    assert time.monotonic() - t0 < 5
    job = job_row(engine, job_id)
    assert (job.status, job.attempts, job.worker_id) == (JobStatus.QUEUED, 0, None)
    assert_given_back_once(engine, job_id, "w")


def test_sigterm_during_a_step_that_cannot_be_interrupted_still_exits_in_bounded_time(
    engine, workers_factory
) -> None:
    """The calibration reports no progress (so it never sees the abort): the worker gives the job
    back when the grace period ends and exits on its own HARD_EXIT_AFTER_S later."""
    [job_id] = queue_jobs(engine, n_tenants=1, per_tenant=1)
    workers = workers_factory(work_s=120, shutdown_grace_s=1, fake_silent=1)
    worker = workers.start("w")
    wait_for_event(workers, "start", timeout_s=40)
    t0 = time.monotonic()
    worker.send_signal(signal.SIGTERM)
    assert worker.wait(HARD_EXIT_AFTER_S + 10) == 0
    assert time.monotonic() - t0 < 1 + HARD_EXIT_AFTER_S + 5
    job = job_row(engine, job_id)
    assert (job.status, job.attempts, job.worker_id) == (JobStatus.QUEUED, 0, None)
    assert_given_back_once(engine, job_id, "w")


def test_sigterm_with_grace_finishes_the_job_then_exits(engine, workers_factory) -> None:
    [job_id] = queue_jobs(engine, n_tenants=1, per_tenant=1)
    workers = workers_factory(work_s=2, shutdown_grace_s=20)
    worker = workers.start("w")
    wait_for_event(workers, "start", timeout_s=30)
    worker.send_signal(signal.SIGTERM)
    assert worker.wait(15) == 0
    job = job_row(engine, job_id)
    assert (job.status, job.attempts) == (JobStatus.SUCCEEDED, 1)
    # it took no other job after the signal
    assert [e["event"] for e in workers.events() if e["event"] == "start"] == ["start"]


def cut_the_database(settings: Settings, workers: FakeWorkers, seconds: float) -> None:
    """The workers lose the database for `seconds`: on PostgreSQL their connections are
    terminated again and again; on SQLite the database is locked (past the busy timeout)."""
    if settings.is_sqlite:
        engine = make_engine(settings)
        try:
            exclusive = engine.execution_options(**{SQLITE_BEGIN_OPTION: "BEGIN EXCLUSIVE"})
            with exclusive.begin():
                time.sleep(seconds)
        finally:
            engine.dispose()
        return
    admin = sa.create_engine(POSTGRES_ADMIN_URL)
    try:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            with admin.begin() as conn:
                conn.execute(
                    sa.text(
                        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
                        " WHERE application_name = :name"
                    ),
                    {"name": workers.application_name},
                )
            time.sleep(0.05)
    finally:
        admin.dispose()


@pytest.mark.slow
def test_workers_recover_by_themselves_when_the_database_comes_back(
    engine, workers_factory, any_db_settings: Settings
) -> None:
    job_ids = queue_jobs(engine, n_tenants=2, per_tenant=20)
    workers = workers_factory(work_s=0.3)
    for i in range(3):
        workers.start(f"w{i}")
    workers.wait_until_up()
    wait_for_event(workers, "computed", timeout_s=30)
    # SQLite's busy timeout is 10 s: lock it longer, so that the workers see errors
    outage_s = 12.0 if any_db_settings.is_sqlite else 4.0
    cutter = threading.Thread(target=cut_the_database, args=(any_db_settings, workers, outage_s))
    cutter.start()
    cutter.join()
    assert all(p.poll() is None for p in workers.processes.values()), "a worker died"
    wait_until_all_finished(engine, len(job_ids), timeout_s=40)
    assert_each_job_succeeded_once_with_its_own_result(engine, job_ids, workers, exclusive=False)
    assert set(workers.stop_all().values()) == {0}


def test_the_job_of_a_sigkilled_worker_shows_a_stale_heartbeat(
    engine, workers_factory, any_db_settings: Settings
) -> None:
    [job_id] = queue_jobs(engine, n_tenants=1, per_tenant=1)
    with make_sessionmaker(engine).begin() as session:
        job = session.get(Job, job_id)
        assert job is not None
        _, key = repo.create_api_key(session, name="viewer", tenant_id=job.tenant_id)
    auth = {"Authorization": f"Bearer {key}"}
    workers = workers_factory(work_s=60)
    worker = workers.start("w")
    wait_for_event(workers, "start", timeout_s=40)
    with api_client(create_app(any_db_settings)) as client:
        alive = client.get(f"/jobs/{job_id}", headers=auth).json()
        assert (alive["status"], alive["stale"]) == ("running", False)
        worker.send_signal(signal.SIGKILL)
        worker.wait(10)
        killed_at = time.monotonic()
        while not (body := client.get(f"/jobs/{job_id}", headers=auth).json())["stale"]:
            assert time.monotonic() - killed_at < FAST_QUEUE["lease_s"] + 2, body
            time.sleep(0.1)
        assert body["status"] == "running" and body["heartbeat_at"] is not None
