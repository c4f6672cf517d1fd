"""Reads and writes of tenants' resources. Every read of a court, job or calibration goes through
`get_owned`, which filters by tenant, so another tenant's row is indistinguishable from a missing one.
"""

from __future__ import annotations

import hashlib
import secrets
import threading
from collections.abc import Sequence
from datetime import datetime
from typing import Any, TypeVar

from sqlalchemy import Connection, Engine, bindparam, delete, func, select, update
from sqlalchemy.exc import DBAPIError, StatementError
from sqlalchemy.orm import Session

from app.db.models import (
    ApiKey,
    Calibration,
    Court,
    Job,
    JobAttempt,
    JobStage,
    JobStatus,
    Tenant,
    UploadAttempt,
    utcnow,
)

KEY_PREFIX = "sqc_"

Owned = TypeVar("Owned", Court, Job, Calibration)


class NotFound(LookupError):
    """The resource does not exist or belongs to another tenant (the caller cannot tell which)."""

    def __init__(self, kind: str, resource_id: str) -> None:
        super().__init__(f"{kind} {resource_id!r} not found")
        self.kind = kind
        self.resource_id = resource_id


def hash_key(key: str) -> str:
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def create_api_key(session: Session, name: str, tenant_id: str | None = None) -> tuple[ApiKey, str]:
    """A new key for `tenant_id` (or for a new tenant called `name`); returns (row, the key)."""
    if not name.strip():
        raise ValueError("a key needs a non-empty name")
    if tenant_id is None:
        tenant = Tenant(name=name)
        session.add(tenant)
        session.flush()
        tenant_id = tenant.id
    elif session.get(Tenant, tenant_id) is None:
        raise ValueError(f"no tenant with id {tenant_id!r}")
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    row = ApiKey(tenant_id=tenant_id, name=name, key_sha256=hash_key(key))
    session.add(row)
    session.flush()
    return row, key


def list_api_keys(session: Session) -> Sequence[ApiKey]:
    return session.scalars(select(ApiKey).order_by(ApiKey.created_at)).all()


def revoke_api_key(session: Session, key_id: str) -> bool:
    result = session.execute(
        update(ApiKey)
        .where(ApiKey.id == key_id, ApiKey.revoked_at.is_(None))
        .values(revoked_at=utcnow())
    )
    return bool(result.rowcount)  # type: ignore[attr-defined]


# compiled once: it runs on every authenticated request
_TENANT_FOR_KEY = select(ApiKey.tenant_id).where(
    ApiKey.key_sha256 == bindparam("key_sha256"), ApiKey.revoked_at.is_(None)
)


def tenant_for_key(connection: Connection | Session, key: str) -> str | None:
    """The tenant of an API key that exists and is not revoked, else None."""
    tenant_id = connection.scalar(_TENANT_FOR_KEY, {"key_sha256": hash_key(key)})
    return str(tenant_id) if tenant_id is not None else None


class KeyLookup:
    """`tenant_for_key` for the request path: one read on a driver connection.

    Every request checks its key (so a revocation applies at once), so this is on the hot path:
    through a SQLAlchemy Connection the read costs ~350 us on SQLite (BEGIN/ROLLBACK around it and
    the Connection's bookkeeping), on a pooled driver connection ~15 us, on a driver connection
    kept by the calling thread ~3 us. The statement is compiled once by SQLAlchemy for the
    engine's dialect, so the SQL and its placeholders stay its job.

    SQLite (`local`): each thread that looks keys up keeps one connection (the API's event loop
    is the one such thread). A kept connection reads the latest commit like any other: SQLite
    starts a fresh read at every statement in autocommit mode, and the cursor is closed after
    each read so that no read stays open to hold back WAL checkpoints. Other databases: a pooled
    connection per read (`pool_pre_ping` keeps it healthy across database restarts).
    """

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        # a local file (SQLite): the read takes microseconds and never waits on a network
        self.local = engine.dialect.name == "sqlite"
        compiled = _TENANT_FOR_KEY.compile(dialect=engine.dialect)
        self.sql = str(compiled)
        self.positional = bool(compiled.positional)
        self.driver_error: type[Exception] = engine.dialect.loaded_dbapi.Error
        self._kept = threading.local()
        self._kept_all: list[Any] = []  # every kept connection, closed by close()
        self._kept_lock = threading.Lock()

    def tenant_for(self, key: str) -> str | None:
        key_sha256 = hash_key(key)
        params: Any = (key_sha256,) if self.positional else {"key_sha256": key_sha256}
        kept = self.local
        connection = getattr(self._kept, "connection", None) if kept else None
        if connection is None:
            try:
                connection = self.engine.raw_connection()
            except self.driver_error as exc:  # database down: the pool does not wrap this one
                raise self._wrapped(params, exc) from exc
            if kept:
                self._kept.connection = connection
                with self._kept_lock:
                    self._kept_all.append(connection)
        try:
            cursor = connection.cursor()
            try:
                cursor.execute(self.sql, params)
                row = cursor.fetchone()
            finally:
                cursor.close()
        except self.driver_error as exc:
            if kept:
                self._forget_kept(connection)
            connection.invalidate()  # a broken connection must not go back to the pool
            raise self._wrapped(params, exc) from exc
        finally:
            if not kept:
                connection.close()
        return str(row[0]) if row is not None else None

    def close(self) -> None:
        """Give back the kept connections (before the engine is disposed)."""
        with self._kept_lock:
            kept, self._kept_all = self._kept_all, []
        for connection in kept:
            connection.close()
        self._kept = threading.local()

    def _forget_kept(self, connection: Any) -> None:
        self._kept.connection = None
        with self._kept_lock:
            if connection in self._kept_all:
                self._kept_all.remove(connection)

    def _wrapped(self, params: Any, exc: Exception) -> StatementError:
        # the same exception type as any other query's, so the API answers 503, not 500
        return DBAPIError.instance(self.sql, params, exc, self.driver_error)


def get_owned(session: Session, model: type[Owned], tenant_id: str, resource_id: str) -> Owned:
    """The one tenant-scoped read: the row if it exists AND belongs to `tenant_id`, else NotFound."""
    if "\x00" in resource_id:
        # no id has one (they are generated hex), and PostgreSQL fails any query sent a NUL
        raise NotFound(model.__name__.lower(), resource_id)
    row = session.scalar(select(model).where(model.id == resource_id, model.tenant_id == tenant_id))
    if row is None:
        raise NotFound(model.__name__.lower(), resource_id)
    return row


def list_courts(session: Session, tenant_id: str, limit: int, offset: int = 0) -> Sequence[Court]:
    """One page of the tenant's courts, oldest first (a stable order, so pages do not overlap)."""
    return session.scalars(
        select(Court)
        .where(Court.tenant_id == tenant_id)
        .order_by(Court.created_at, Court.id)
        .limit(limit)
        .offset(offset)
    ).all()


def create_court(session: Session, tenant_id: str, name: str, spec: str) -> Court:
    court = Court(tenant_id=tenant_id, name=name, spec=spec)
    session.add(court)
    session.flush()
    return court


def list_calibrations(
    session: Session, tenant_id: str, court_id: str, limit: int, offset: int = 0
) -> Sequence[Calibration]:
    """One page of the court's calibrations, newest first (ties by id: pages do not overlap)."""
    court = get_owned(session, Court, tenant_id, court_id)
    return session.scalars(
        select(Calibration)
        .where(Calibration.court_id == court.id, Calibration.tenant_id == tenant_id)
        .order_by(Calibration.created_at.desc(), Calibration.id)
        .limit(limit)
        .offset(offset)
    ).all()


def active_calibration(session: Session, tenant_id: str, court_id: str) -> Calibration | None:
    court = get_owned(session, Court, tenant_id, court_id)
    if court.active_calibration_id is None:
        return None
    return get_owned(session, Calibration, tenant_id, court.active_calibration_id)


def active_calibration_ids(session: Session, court_ids: Sequence[str]) -> dict[str, str | None]:
    """court id -> active calibration id, for the API's camera cache refresher (not tenant data)."""
    rows = session.execute(
        select(Court.id, Court.active_calibration_id).where(Court.id.in_(list(court_ids)))
    ).all()
    return {court_id: cal_id for court_id, cal_id in rows}


def new_job(
    session: Session,
    *,
    job_id: str,
    tenant_id: str,
    court_id: str,
    media_kind: str,
    media_files: list[str],
    params: dict[str, Any],
    max_attempts: int,
) -> Job:
    job = Job(
        id=job_id,
        tenant_id=tenant_id,
        court_id=court_id,
        media_kind=media_kind,
        media_files=media_files,
        params=params,
        max_attempts=max_attempts,
        status=JobStatus.QUEUED,
        stage=JobStage.QUEUED,
        timings={},
    )
    session.add(job)
    session.flush()
    return job


def count_queued_jobs(session: Session, tenant_id: str) -> int:
    return int(
        session.scalar(
            select(func.count(Job.id)).where(
                Job.tenant_id == tenant_id, Job.status == JobStatus.QUEUED
            )
        )
        or 0
    )


def uploads_since(session: Session, tenant_id: str, since: datetime) -> tuple[int, datetime | None]:
    """(how many uploads the tenant began since `since`, whatever became of them; when the oldest
    of them began)."""
    count, oldest = session.execute(
        select(func.count(UploadAttempt.id), func.min(UploadAttempt.received_at)).where(
            UploadAttempt.tenant_id == tenant_id, UploadAttempt.received_at >= since
        )
    ).one()
    return int(count or 0), oldest


def record_upload_attempt(
    session: Session, tenant_id: str, received_at: datetime, forget_before: datetime
) -> None:
    """Count an upload the API begins to receive, and forget the tenant's uploads from before
    `forget_before` (the rate's window: older ones count for nothing, and the table stays small)."""
    session.execute(
        delete(UploadAttempt).where(
            UploadAttempt.tenant_id == tenant_id, UploadAttempt.received_at < forget_before
        )
    )
    session.add(UploadAttempt(tenant_id=tenant_id, received_at=received_at))


def list_jobs(session: Session, tenant_id: str, court_id: str, limit: int) -> Sequence[Job]:
    """The court's most recent jobs, newest first."""
    court = get_owned(session, Court, tenant_id, court_id)
    return session.scalars(
        select(Job)
        .where(Job.court_id == court.id, Job.tenant_id == tenant_id)
        .order_by(Job.created_at.desc(), Job.id)
        .limit(limit)
    ).all()


def attempts_of_jobs(session: Session, job_ids: Sequence[str]) -> dict[str, list[JobAttempt]]:
    """Each job's attempts in the order of their claims (one query for a page of jobs); callers
    read the jobs through get_owned or list_jobs first, so these are the tenant's."""
    by_job: dict[str, list[JobAttempt]] = {job_id: [] for job_id in job_ids}
    rows = session.scalars(
        select(JobAttempt).where(JobAttempt.job_id.in_(list(job_ids))).order_by(JobAttempt.id)
    )
    for row in rows:
        by_job[row.job_id].append(row)
    return by_job


def api_key_for_hash(session: Session, key_sha256: str) -> ApiKey | None:
    return session.scalar(
        select(ApiKey).where(ApiKey.key_sha256 == key_sha256, ApiKey.revoked_at.is_(None))
    )


def failed_job_ids_finished_before(session: Session, cutoff: datetime) -> list[str]:
    """Jobs that failed for good before `cutoff`: their uploads are past the retention period."""
    return list(
        session.scalars(select(Job.id).where(Job.status == "failed", Job.finished_at < cutoff))
    )


def existing_job_ids(session: Session, job_ids: Sequence[str]) -> set[str]:
    return set(session.scalars(select(Job.id).where(Job.id.in_(list(job_ids)))))


def existing_calibration_ids(session: Session, calibration_ids: Sequence[str]) -> set[str]:
    return set(
        session.scalars(select(Calibration.id).where(Calibration.id.in_(list(calibration_ids))))
    )
