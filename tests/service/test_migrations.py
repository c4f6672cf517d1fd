"""Schema only via Alembic: migrating from empty gives exactly the models' schema."""

from __future__ import annotations

from datetime import timedelta
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import CheckConstraint, insert, inspect, select, update

from app.db import queue
from app.db.migrate import alembic_config, current_revision, head_revision, upgrade_head
from app.db.models import (
    Base,
    Calibration,
    Court,
    Job,
    JobAttempt,
    JobStatus,
    Tenant,
    UploadAttempt,
    new_id,
    utcnow,
)
from app.db.session import make_engine
from app.settings import Settings
from tests.service.conftest import make_settings, postgres_schema
from tests.service.test_queue import job_row, make_calibration


def _assert_schema_matches_models(settings: Settings) -> None:
    engine = make_engine(settings)
    try:
        assert current_revision(engine) is None
        upgrade_head(settings)
        assert current_revision(engine) == head_revision(settings)
        with engine.connect() as conn:
            context = MigrationContext.configure(conn, opts={"compare_type": True})
            assert compare_metadata(context, Base.metadata) == []
            tables = set(inspect(conn).get_table_names())
            # compare_metadata does not compare CHECK constraints: their names must match too
            # (0003 created doubled ones, "ck_jobs_ck_jobs_status")
            for table in ("jobs", "job_attempts"):
                migrated = {c["name"] for c in inspect(conn).get_check_constraints(table)}
                modelled = {
                    c.name
                    for c in Base.metadata.tables[table].constraints
                    if isinstance(c, CheckConstraint)
                }
                assert migrated == modelled, table
        assert tables == set(Base.metadata.tables) | {"alembic_version"}
        # and back down to nothing, and up again
        command.downgrade(alembic_config(settings), "base")
        with engine.connect() as conn:
            assert set(inspect(conn).get_table_names()) == {"alembic_version"}
        upgrade_head(settings)
        assert current_revision(engine) == head_revision(settings)
    finally:
        engine.dispose()


def test_migrations_from_empty_sqlite(tmp_path: Path) -> None:
    _assert_schema_matches_models(make_settings(tmp_path / "data"))


@pytest.mark.postgres
def test_migrations_from_empty_postgres(tmp_path: Path) -> None:
    with postgres_schema() as url:
        _assert_schema_matches_models(make_settings(tmp_path / "data", database_url=url))


def _jobs_at_an_old_revision(engine, n: int) -> list[str]:
    """A tenant, a court and `n` queued jobs written with the columns they have had since 0001
    (an INSERT through the models names every column they have today)."""
    tenant_id, court_id, job_ids = new_id(), new_id(), [new_id() for _ in range(n)]
    now = utcnow()
    with engine.begin() as conn:
        conn.execute(insert(Tenant.__table__).values(id=tenant_id, name="t", created_at=now))
        conn.execute(
            insert(Court.__table__).values(
                id=court_id, tenant_id=tenant_id, name="c", spec="wsf", created_at=now
            )
        )
        for i, job_id in enumerate(job_ids):
            conn.execute(
                insert(Job.__table__).values(
                    id=job_id,
                    tenant_id=tenant_id,
                    court_id=court_id,
                    media_kind="images",
                    media_files=["000.png"],
                    params={},
                    created_at=now + timedelta(milliseconds=i),
                )
            )
    return job_ids


def _assert_job_attempts_migrate_up_and_down_with_jobs(settings: Settings) -> None:
    """0004 -> 0005 (and on to the head, which the queue's code needs) on a database with a job
    in it, work recorded in job_attempts, back down to 0004 (the table goes, the job stays) and
    up again."""
    config = alembic_config(settings)
    engine = make_engine(settings)
    try:
        command.upgrade(config, "0004")
        [job_id] = _jobs_at_an_old_revision(engine, 1)
        upgrade_head(settings)
        job = queue.claim(engine, "w", lease_s=60)
        assert job is not None
        queue.finish_success(engine, job, "w", make_calibration(job), {})
        with engine.connect() as conn:
            rows = conn.exec_driver_sql("SELECT attempt, outcome FROM job_attempts").all()
        assert [tuple(row) for row in rows] == [(1, "succeeded")]
        command.downgrade(config, "0004")
        with engine.connect() as conn:
            assert "job_attempts" not in inspect(conn).get_table_names()
        assert job_row(engine, job_id).status == JobStatus.SUCCEEDED
        upgrade_head(settings)
        with engine.connect() as conn:
            assert conn.exec_driver_sql("SELECT count(*) FROM job_attempts").scalar() == 0
    finally:
        engine.dispose()


def test_job_attempts_migrate_up_and_down_with_jobs_sqlite(tmp_path: Path) -> None:
    _assert_job_attempts_migrate_up_and_down_with_jobs(make_settings(tmp_path / "data"))


@pytest.mark.postgres
def test_job_attempts_migrate_up_and_down_with_jobs_postgres(tmp_path: Path) -> None:
    with postgres_schema() as url:
        settings = make_settings(tmp_path / "data", database_url=url)
        _assert_job_attempts_migrate_up_and_down_with_jobs(settings)


def test_sqlite_table_rebuilds_keep_the_rows_that_reference_the_table(tmp_path: Path) -> None:
    """On SQLite a batch migration rebuilds a table (copy, drop, rename), as 0006 and its
    downgrade do with `jobs`. Dropping the old table must not cascade to the rows that reference
    it (0006 used to delete every calibration and job attempt)."""
    settings = make_settings(tmp_path / "data")
    config = alembic_config(settings)
    engine = make_engine(settings)
    tables = ("tenants", "courts", "jobs", "job_attempts", "calibrations")

    def counts() -> dict[str, int]:
        with engine.connect() as conn:
            return {t: conn.exec_driver_sql(f"SELECT count(*) FROM {t}").scalar() for t in tables}

    try:
        command.upgrade(config, "0005")
        [job_id] = _jobs_at_an_old_revision(engine, 1)
        with engine.begin() as conn:
            tenant_id, court_id = conn.execute(
                select(Job.tenant_id, Job.court_id).where(Job.id == job_id)
            ).one()
            conn.execute(
                insert(JobAttempt.__table__).values(
                    job_id=job_id, attempt=1, worker_id="w", claimed_at=utcnow()
                )
            )
            conn.execute(
                insert(Calibration.__table__).values(
                    id=new_id(),
                    tenant_id=tenant_id,
                    court_id=court_id,
                    job_id=job_id,
                    spec="wsf",
                    genome=[0.0] * 15,
                    opencv={},
                    fitness=1.0,
                    quality={},
                    result={},
                    image_width=64,
                    image_height=48,
                )
            )
        before = counts()
        assert set(before.values()) == {1}
        upgrade_head(settings)
        assert counts() == before
        command.downgrade(config, "0005")
        assert counts() == before
        with engine.connect() as conn:  # and the connections that migrated still check them
            assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    finally:
        engine.dispose()


def _assert_tenants_last_claim_is_filled_from_their_jobs(settings: Settings) -> None:
    """0006 -> 0007: a tenant's last claim is the latest start of its jobs (null if none ran)."""
    config = alembic_config(settings)
    engine = make_engine(settings)
    try:
        command.upgrade(config, "0006")
        first, second = _jobs_at_an_old_revision(engine, 2)
        _jobs_at_an_old_revision(engine, 1)  # another tenant, never served
        started = utcnow() - timedelta(minutes=5)
        with engine.begin() as conn:
            for job_id, at in ((first, started), (second, started + timedelta(seconds=30))):
                conn.execute(update(Job).where(Job.id == job_id).values(started_at=at))
        command.upgrade(config, "0007")
        with engine.connect() as conn:
            turns = conn.execute(select(Tenant.last_claimed_at).order_by(Tenant.created_at)).all()
        assert [row[0] for row in turns] == [started + timedelta(seconds=30), None]
        command.downgrade(config, "0006")
        with engine.connect() as conn:
            assert "last_claimed_at" not in {
                c["name"] for c in inspect(conn).get_columns("tenants")
            }
    finally:
        engine.dispose()


def test_tenants_last_claim_is_filled_from_their_jobs_sqlite(tmp_path: Path) -> None:
    _assert_tenants_last_claim_is_filled_from_their_jobs(make_settings(tmp_path / "data"))


@pytest.mark.postgres
def test_tenants_last_claim_is_filled_from_their_jobs_postgres(tmp_path: Path) -> None:
    with postgres_schema() as url:
        settings = make_settings(tmp_path / "data", database_url=url)
        _assert_tenants_last_claim_is_filled_from_their_jobs(settings)


def _assert_upload_attempts_are_filled_from_the_jobs(settings: Settings) -> None:
    """0007 -> 0008: every job is an upload its tenant made when the job was created (the rate's
    hour does not start again at the upgrade)."""
    config = alembic_config(settings)
    engine = make_engine(settings)
    try:
        command.upgrade(config, "0007")
        job_ids = _jobs_at_an_old_revision(engine, 2)
        with engine.connect() as conn:
            jobs = conn.execute(
                select(Job.id, Job.tenant_id, Job.created_at).order_by(Job.id)
            ).all()
        command.upgrade(config, "0008")
        with engine.connect() as conn:
            uploads = conn.execute(
                select(
                    UploadAttempt.id, UploadAttempt.tenant_id, UploadAttempt.received_at
                ).order_by(UploadAttempt.id)
            ).all()
        assert sorted(job_ids) == [row[0] for row in jobs]
        assert [tuple(row) for row in uploads] == [tuple(row) for row in jobs]
        command.downgrade(config, "0007")
        with engine.connect() as conn:
            assert "upload_attempts" not in inspect(conn).get_table_names()
    finally:
        engine.dispose()


def test_upload_attempts_are_filled_from_the_jobs_sqlite(tmp_path: Path) -> None:
    _assert_upload_attempts_are_filled_from_the_jobs(make_settings(tmp_path / "data"))


@pytest.mark.postgres
def test_upload_attempts_are_filled_from_the_jobs_postgres(tmp_path: Path) -> None:
    with postgres_schema() as url:
        settings = make_settings(tmp_path / "data", database_url=url)
        _assert_upload_attempts_are_filled_from_the_jobs(settings)


def test_models_differ_from_an_unmigrated_database(tmp_path: Path) -> None:
    """The comparison above is not vacuous: an empty database differs from the models."""
    settings = make_settings(tmp_path / "data")
    engine = make_engine(settings)
    try:
        with engine.connect() as conn:
            diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
        added_tables = [d[1].name for d in diff if d[0] == "add_table"]
        assert sorted(added_tables) == sorted(Base.metadata.tables)
    finally:
        engine.dispose()


def test_sqlite_runs_in_wal_mode_with_busy_timeout(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "data")
    engine = make_engine(settings)
    try:
        with engine.connect() as conn:
            assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
            assert conn.exec_driver_sql("PRAGMA busy_timeout").scalar() >= 1000
            assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    finally:
        engine.dispose()
