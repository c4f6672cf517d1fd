"""SQLAlchemy 2 models. The schema itself is created only by Alembic (`alembic upgrade head`)."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import (
    JSON,
    CheckConstraint,
    DateTime,
    Enum,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    TypeDecorator,
    text,
)
from sqlalchemy.engine import Dialect
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

# Explicit constraint names, so migrations are identical on SQLite and PostgreSQL.
NAMING_CONVENTION = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class JobStatus(StrEnum):
    """Where a job is in the queue; the values are what the database and the API show."""

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class JobStage(StrEnum):
    """What a job is doing (the worker's stages, in order)."""

    QUEUED = "queued"
    BACKGROUND = "background"
    EDGES = "edges"
    OPTIMISING = "optimising"
    REFINING = "refining"
    STORING = "storing"
    DONE = "done"


class AttemptOutcome(StrEnum):
    """How one attempt at a job (one claim by a worker) ended; the values are what the database and
    the API show. An attempt still running has no outcome."""

    # it stored its calibration: the job succeeded
    SUCCEEDED = "succeeded"
    # it recorded an error and the job failed for good (not retryable, or no attempt left)
    FAILED = "failed"
    # it recorded a retryable error and the job went back to the queue for another attempt
    FAILED_RETRY = "failed_retry"
    # its worker gave the job back on shutdown; not counted, so the next claim has its number again
    RELEASED = "released"
    # its worker stopped renewing the lease (killed, stalled, cut off from the database): ended when
    # the queue noticed, i.e. when another claim took the job or failed it as worker_lost
    LEASE_LOST = "lease_lost"


def _string_enum(enum: type[StrEnum], name: str) -> Enum:
    """A VARCHAR holding the enum's values, guarded by a CHECK constraint named `name` (the same
    on SQLite and PostgreSQL: no native enum type, so adding a value is a plain migration)."""
    return Enum(
        enum,
        name=name,
        native_enum=False,
        create_constraint=True,
        length=16,
        validate_strings=True,
        values_callable=lambda members: [m.value for m in members],
    )


def new_id() -> str:
    return uuid.uuid4().hex


def utcnow() -> datetime:
    return datetime.now(UTC)


class UTCDateTime(TypeDecorator[datetime]):
    """Timezone-aware UTC datetimes on every backend (SQLite stores them naive)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("naive datetime given to a UTC column")
        value = value.astimezone(UTC)
        # SQLite compares these as text: store them naive so every row has the same format
        return value.replace(tzinfo=None) if dialect.name == "sqlite" else value

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map = {datetime: UTCDateTime(), dict[str, Any]: JSON()}


class Tenant(Base):
    __tablename__ = "tenants"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(200))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    # when a worker last took one of the tenant's jobs (the queue's turns across tenants); None
    # until the first claim
    last_claimed_at: Mapped[datetime | None] = mapped_column(default=None)


class ApiKey(Base):
    """An API key is stored only as its SHA-256: keys are 256-bit random, so a fast hash is safe."""

    __tablename__ = "api_keys"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    key_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    revoked_at: Mapped[datetime | None] = mapped_column(default=None)


class Court(Base):
    __tablename__ = "courts"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    spec: Mapped[str] = mapped_column(String(32))
    # The camera /project uses. No FK: calibrations reference courts, and a cycle buys nothing here.
    active_calibration_id: Mapped[str | None] = mapped_column(String(32), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Job(Base):
    """One calibration request; the jobs table is the work queue."""

    __tablename__ = "jobs"
    __table_args__ = (Index("ix_jobs_claim", "status", "created_at"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id", ondelete="CASCADE"), index=True)
    court_id: Mapped[str] = mapped_column(ForeignKey("courts.id", ondelete="CASCADE"), index=True)
    status: Mapped[JobStatus] = mapped_column(
        _string_enum(JobStatus, "status"), default=JobStatus.QUEUED
    )
    stage: Mapped[JobStage] = mapped_column(
        _string_enum(JobStage, "stage"), default=JobStage.QUEUED
    )
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    generation: Mapped[int | None] = mapped_column(Integer, default=None)
    best_fitness: Mapped[float | None] = mapped_column(Float, default=None)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer, default=3)
    worker_id: Mapped[str | None] = mapped_column(String(200), default=None)
    lease_expires_at: Mapped[datetime | None] = mapped_column(default=None)
    # the running worker's last sign of life (claim or lease renewal)
    heartbeat_at: Mapped[datetime | None] = mapped_column(default=None)
    # a queued job waits until then (retry backoff); None = at once
    run_after: Mapped[datetime | None] = mapped_column(default=None)
    # what was uploaded: "images" or "video", files in media/jobs/<id>/
    media_kind: Mapped[str] = mapped_column(String(16))
    media_files: Mapped[list[str]] = mapped_column(JSON)
    params: Mapped[dict[str, Any]] = mapped_column(JSON)
    error_code: Mapped[str | None] = mapped_column(String(64), default=None)
    error_message: Mapped[str | None] = mapped_column(Text, default=None)
    timings: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    calibration_id: Mapped[str | None] = mapped_column(String(32), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(default=None)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)


class UploadAttempt(Base):
    """An upload the API began to receive (past the key, the court and the tenant's limits),
    whatever became of it: the upload rate counts these, so that a client sending bad files in a
    loop is held to the rate as well as one whose uploads become jobs."""

    __tablename__ = "upload_attempts"
    __table_args__ = (Index("ix_upload_attempts_tenant_time", "tenant_id", "received_at"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id", ondelete="CASCADE"))
    received_at: Mapped[datetime] = mapped_column()


class JobAttempt(Base):
    """One claim of a job by a worker, from the claim to how it ended: the queue writes it in the
    same transaction as the claim and as whatever ends the attempt, so it is the record of who held
    which job when (the jobs row keeps only the last attempt)."""

    __tablename__ = "job_attempts"
    __table_args__ = (
        # an attempt ends with an outcome, and only then
        CheckConstraint("(ended_at IS NULL) = (outcome IS NULL)", name="ended_with_outcome"),
        # a job is held by at most one worker: the queue closes the stale attempt before it opens
        # the next one, and the database refuses a second open attempt if it ever did not
        Index(
            "ix_job_attempts_one_open_per_job",
            "job_id",
            unique=True,
            sqlite_where=text("ended_at IS NULL"),
            postgresql_where=text("ended_at IS NULL"),
        ),
    )

    # an integer key in the order of the claims (the claims of one job are serialised on its row):
    # the workers' clocks, which set claimed_at, need not agree to the millisecond
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    job_id: Mapped[str] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), index=True)
    # the job's attempt counter at the claim (jobs.attempts); a released attempt gives its number back
    attempt: Mapped[int] = mapped_column(Integer)
    worker_id: Mapped[str] = mapped_column(String(200))
    claimed_at: Mapped[datetime] = mapped_column()
    ended_at: Mapped[datetime | None] = mapped_column(default=None)
    outcome: Mapped[AttemptOutcome | None] = mapped_column(
        _string_enum(AttemptOutcome, "outcome"), default=None
    )
    # the error the attempt recorded (outcomes failed and failed_retry)
    error_code: Mapped[str | None] = mapped_column(String(64), default=None)


class Calibration(Base):
    __tablename__ = "calibrations"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    tenant_id: Mapped[str] = mapped_column(ForeignKey("tenants.id", ondelete="CASCADE"), index=True)
    court_id: Mapped[str] = mapped_column(ForeignKey("courts.id", ondelete="CASCADE"), index=True)
    # None for an imported camera (no job made it, and it has no fitness)
    job_id: Mapped[str | None] = mapped_column(
        ForeignKey("jobs.id", ondelete="CASCADE"), unique=True
    )
    spec: Mapped[str] = mapped_column(String(32))
    genome: Mapped[list[float]] = mapped_column(JSON)
    opencv: Mapped[dict[str, Any]] = mapped_column(JSON)
    fitness: Mapped[float | None] = mapped_column(Float)
    quality: Mapped[dict[str, Any]] = mapped_column(JSON)
    # the pipeline's whole CalibrationResult.to_json(): seed, bundle, generations, timings, ...
    result: Mapped[dict[str, Any]] = mapped_column(JSON)
    image_width: Mapped[int] = mapped_column(Integer)
    image_height: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
