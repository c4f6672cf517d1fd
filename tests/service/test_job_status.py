"""What GET /jobs/{id} says about a job in the queue: its enums, whether its worker is alive, and
every attempt at it (on SQLite and PostgreSQL)."""

from __future__ import annotations

from datetime import datetime, timedelta

import httpx
import pytest

from app.db import queue, repo
from app.db.models import AttemptOutcome, JobStage, JobStatus, new_id, utcnow
from app.db.session import make_engine, make_sessionmaker
from app.settings import Settings

pytestmark = pytest.mark.both_databases


def queued_job(settings: Settings) -> tuple[dict[str, str], str]:
    """A tenant's key and one queued job of it, made without an upload."""
    engine = make_engine(settings)
    try:
        with make_sessionmaker(engine).begin() as session:
            key_row, key = repo.create_api_key(session, name="t")
            court = repo.create_court(session, key_row.tenant_id, "c", "wsf")
            job = repo.new_job(
                session,
                job_id=new_id(),
                tenant_id=key_row.tenant_id,
                court_id=court.id,
                media_kind="images",
                media_files=["000.png"],
                params={},
                max_attempts=3,
            )
        return {"Authorization": f"Bearer {key}"}, job.id
    finally:
        engine.dispose()


def test_a_job_whose_worker_stopped_renewing_is_shown_stale(
    client: httpx.Client, settings: Settings
) -> None:
    auth, job_id = queued_job(settings)
    body = client.get(f"/jobs/{job_id}", headers=auth).json()
    assert (body["status"], body["heartbeat_at"], body["stale"]) == ("queued", None, False)

    engine = make_engine(settings)
    try:
        assert queue.claim(engine, "alive", lease_s=10) is not None
        body = client.get(f"/jobs/{job_id}", headers=auth).json()
        assert (body["status"], body["stale"]) == ("running", False)
        assert body["heartbeat_at"] is not None

        # the worker was SIGKILLed 11 s ago, just after its last renewal of a 10 s lease
        assert queue.release(engine, job_id, "alive")
        assert queue.claim(engine, "killed", lease_s=10, now=utcnow() - timedelta(seconds=11))
        body = client.get(f"/jobs/{job_id}", headers=auth).json()
        assert (body["status"], body["stale"]) == ("running", True)
    finally:
        engine.dispose()


def attempt_rows(body: dict) -> list[tuple[int, str | None, str | None]]:
    # workers' ids name hosts and processes: operators read them in job_attempts, tenants never
    assert all("worker_id" not in a for a in body["attempt_history"]), body
    return [(a["attempt"], a["outcome"], a["error_code"]) for a in body["attempt_history"]]


def when(text: str | None) -> datetime | None:
    return datetime.fromisoformat(text) if text is not None else None


def test_the_job_shows_every_attempt_and_how_it_ended(
    client: httpx.Client, settings: Settings
) -> None:
    auth, job_id = queued_job(settings)
    assert client.get(f"/jobs/{job_id}", headers=auth).json()["attempt_history"] == []

    engine = make_engine(settings)
    try:
        # killed while it held the job; the next worker takes it when the lease has run out
        start = utcnow() - timedelta(seconds=60)
        assert queue.claim(engine, "killed", lease_s=10, now=start)
        retaken = start + timedelta(seconds=11)
        assert queue.claim(engine, "unlucky", lease_s=10, now=retaken)
        failed = retaken + timedelta(seconds=2)
        queue.finish_failure(
            engine, job_id, "unlucky", "storage_error", "disk full", True, now=failed
        )
        assert queue.claim(engine, "current", lease_s=10)
    finally:
        engine.dispose()

    body = client.get(f"/jobs/{job_id}", headers=auth).json()
    assert (body["status"], body["attempts"]) == ("running", 3)
    assert attempt_rows(body) == [
        (1, "lease_lost", None),
        (2, "failed_retry", "storage_error"),
        (3, None, None),
    ]
    killed, unlucky, current = body["attempt_history"]
    assert (when(killed["claimed_at"]), when(killed["ended_at"])) == (start, retaken)
    assert (when(unlucky["claimed_at"]), when(unlucky["ended_at"])) == (retaken, failed)
    assert current["ended_at"] is None
    # the court's job list shows the same
    listed = client.get(f"/courts/{body['court_id']}/jobs", headers=auth).json()["jobs"]
    assert [attempt_rows(job) for job in listed] == [attempt_rows(body)]


def test_the_api_enums_are_the_database_enums(client: httpx.Client) -> None:
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    job = schemas["JobOut"]["properties"]
    assert job["status"]["enum"] == [s.value for s in JobStatus]
    assert job["stage"]["enum"] == [s.value for s in JobStage]
    assert job["status"]["enum"] == ["queued", "running", "succeeded", "failed"]
    assert schemas["JobAccepted"]["properties"]["status"]["enum"] == job["status"]["enum"]
    # an attempt's outcome: one of the enum's, or null while it runs
    outcome = schemas["JobAttemptOut"]["properties"]["outcome"]
    assert outcome["anyOf"] == [
        {"type": "string", "enum": [o.value for o in AttemptOutcome]},
        {"type": "null"},
    ]
    assert job["attempt_history"]["items"] == {"$ref": "#/components/schemas/JobAttemptOut"}
