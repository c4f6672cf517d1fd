"""Service settings: every knob has an env var (prefix `SQUASHCAL_`) and a sane embedded default."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="SQUASHCAL_", extra="ignore")

    # Storage: the SQLite file and all media live under data_dir unless database_url says otherwise.
    data_dir: Path = Path("./data")
    database_url: str | None = None

    # HTTP server
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)

    # Upload limits (checked while streaming / from headers before any full decode)
    max_upload_bytes: int = Field(default=512 * 1024 * 1024, ge=1)
    max_files: int = Field(default=32, ge=1)
    max_image_pixels: int = Field(default=50_000_000, ge=1)
    max_video_width_px: int = Field(default=4096, ge=1)
    max_video_height_px: int = Field(default=4096, ge=1)
    max_video_duration_s: float = Field(default=900.0, gt=0)
    upload_chunk_bytes: int = Field(default=1024 * 1024, ge=1024)

    # Background: frames sampled from a clip, spread over its whole length
    background_frames: int = Field(default=15, ge=1, le=200)

    # Queue and worker
    max_attempts: int = Field(default=3, ge=1)
    lease_s: float = Field(default=60.0, gt=0)
    poll_interval_s: float = Field(default=1.0, gt=0)
    progress_interval_s: float = Field(default=0.3, gt=0)
    shutdown_grace_s: float = Field(default=30.0, ge=0)

    # Calibration run (None = the pipeline's own defaults)
    ga_time_budget_s: float | None = Field(default=None, gt=0)
    ga_max_generations: int | None = Field(default=None, ge=1)

    # Load the numerical kernels at start, before taking work (`app.calib.warmup`): the API's
    # /readyz and the worker's first claim wait for it. Off: the first request or job pays it.
    warm_up: bool = True

    # Caches of the API process (the /project hot path does no database work)
    camera_refresh_s: float = Field(default=0.5, gt=0)
    camera_cache_size: int = Field(default=10_000, ge=1)
    auth_cache_s: float = Field(default=30.0, ge=0)

    @model_validator(mode="after")
    def _lease_outlives_progress(self) -> Settings:
        if self.progress_interval_s * 2 >= self.lease_s:
            raise ValueError("lease_s must be more than twice progress_interval_s")
        return self

    @property
    def media_dir(self) -> Path:
        return self.data_dir / "media"

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
