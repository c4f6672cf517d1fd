"""Service settings: every knob has an env var (prefix `SQUASHCAL_`) and a sane embedded default."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="SQUASHCAL_", extra="ignore")

    # Storage: the SQLite file and all media live under data_dir unless database_url and media_root
    # say otherwise (media_root: a volume shared by every API and worker host, see the README).
    data_dir: Path = Path("./data")
    database_url: str | None = None
    media_root: Path | None = None
    # Media sweep (by every API process, at start and then every interval): uploads of failed jobs
    # after the retention period, and job folders without a job (an upload cut off by a crash)
    # and calibration folders without a calibration (a worker killed while storing it) once
    # nothing has been written to them for the grace period (keep it well above lease_s).
    failed_media_retention_s: float = Field(default=7 * 24 * 3600.0, ge=0)
    orphan_media_grace_s: float = Field(default=3600.0, ge=0)
    media_sweep_interval_s: float = Field(default=3600.0, gt=0)

    # HTTP server
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)

    # Upload limits (checked while streaming / from headers before any full decode)
    max_upload_bytes: int = Field(default=512 * 1024 * 1024, ge=1)
    max_files: int = Field(default=32, ge=1)
    # pixels are counted from each image's header before anything is decoded: one 4096 x 4096
    # image, and together 64 Mi pixels (32 full-HD frames), i.e. <= 200 MB of decoded BGR per job
    max_image_pixels: int = Field(default=4096 * 4096, ge=1)
    max_upload_pixels: int = Field(default=64 * 1024 * 1024, ge=1)
    max_video_width_px: int = Field(default=4096, ge=1)
    max_video_height_px: int = Field(default=4096, ge=1)
    max_video_duration_s: float = Field(default=900.0, gt=0)
    # JSON bodies (everything but uploads) are read whole: 100 000 points fit in about 4 MB
    max_json_body_bytes: int = Field(default=8 * 1024 * 1024, ge=1024)
    upload_chunk_bytes: int = Field(default=1024 * 1024, ge=1024)

    # Background: frames sampled from a clip, spread over its whole length
    background_frames: int = Field(default=15, ge=1, le=200)
    # ... and the most memory (MB, 10^6 bytes) the full frames a clip job keeps may take: up to
    # 3 x background_frames of them (the view on screen and the longest other view). Large frames
    # get fewer (never below 3): 1080p and below all 15, 4K UHD 13, 4096 x 4096 6.
    max_clip_frames_mb: int = Field(default=1024, ge=1)

    # Queue and worker. A short lease renewed often: a dead worker's job is visibly stale (and
    # claimable again) within seconds, while a few missed renewals (a slow database) are tolerated.
    max_attempts: int = Field(default=3, ge=1)
    lease_s: float = Field(default=10.0, gt=0)
    heartbeat_s: float = Field(default=2.0, gt=0)
    poll_interval_s: float = Field(default=1.0, gt=0)
    progress_interval_s: float = Field(default=0.3, gt=0)
    shutdown_grace_s: float = Field(default=30.0, ge=0)
    # a retryable failure waits retry_backoff_s, then twice that, ... (at most retry_backoff_max_s)
    retry_backoff_s: float = Field(default=5.0, ge=0)
    retry_backoff_max_s: float = Field(default=300.0, ge=0)
    # A tenant with this many jobs waiting gets 429 (Retry-After: queue_full_retry_after_s) for
    # more uploads: one tenant cannot fill the queue (or the disk) for everyone.
    max_queued_jobs_per_tenant: int = Field(default=50, ge=1)
    queue_full_retry_after_s: int = Field(default=30, ge=1)
    # ... and one with this many uploads in the last hour (whatever became of them: one refused
    # for its content counts too, a 429 does not; table upload_attempts) gets 429 with
    # Retry-After until the oldest of them is an hour old: a client stuck in a retry loop, or a
    # leaked key, cannot flood the workers and the disk.
    max_uploads_per_hour_per_tenant: int = Field(default=240, ge=1)

    # Calibration run (None = the pipeline's own defaults)
    ga_time_budget_s: float | None = Field(default=None, gt=0)
    ga_max_generations: int | None = Field(default=None, ge=1)

    # Load the numerical kernels at start, before taking work (`app.calib.warmup`): the API's
    # /readyz and the worker's first claim wait for it. Off: the first request or job pays it.
    warm_up: bool = True

    # Caches of the API process (the /project hot path does no database work)
    camera_refresh_s: float = Field(default=0.5, gt=0)
    camera_cache_size: int = Field(default=10_000, ge=1)

    @model_validator(mode="after")
    def _lease_outlives_heartbeats(self) -> Settings:
        if self.progress_interval_s * 2 >= self.lease_s:
            raise ValueError("lease_s must be more than twice progress_interval_s")
        if self.heartbeat_s * 3 > self.lease_s:
            raise ValueError("lease_s must be at least three heartbeat_s (two renewals may fail)")
        return self

    @property
    def media_dir(self) -> Path:
        return self.media_root if self.media_root is not None else self.data_dir / "media"

    @property
    def sqlalchemy_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'squashcal.sqlite3').resolve()}"

    @property
    def is_sqlite(self) -> bool:
        return self.sqlalchemy_url.startswith("sqlite")


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
