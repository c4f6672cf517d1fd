"""Request and response models: the public contract of the HTTP API."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

JobStatus = Literal["queued", "running", "succeeded", "failed"]
JobStage = Literal["queued", "background", "edges", "optimising", "refining", "storing", "done"]
# (u, v) pixels or (x, y) floor metres; JSON has no NaN/Infinity, and Python's "NaN" tokens are refused
FinitePair = tuple[float, float]


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class ErrorDetail(BaseModel):
    code: str = Field(examples=["not_found"])
    message: str


class ErrorResponse(BaseModel):
    error: ErrorDetail


class CourtCreate(StrictModel):
    name: str = Field(min_length=1, max_length=200)
    spec: str = Field(default="wsf", description="court specification: wsf, psa or doubles")


class CourtOut(BaseModel):
    id: str
    name: str
    spec: str
    active_calibration_id: str | None
    created_at: datetime


class CourtList(BaseModel):
    courts: list[CourtOut]


class JobAccepted(BaseModel):
    job_id: str
    status: JobStatus


class JobError(BaseModel):
    code: str
    message: str


class JobOut(BaseModel):
    id: str
    court_id: str
    status: JobStatus
    stage: JobStage
    progress: float = Field(ge=0, le=1)
    generation: int | None
    best_fitness: float | None
    attempts: int
    max_attempts: int
    media_kind: Literal["images", "video"]
    n_files: int
    error: JobError | None
    calibration_id: str | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    timings_s: dict[str, float] = Field(description="seconds per stage, as far as the job got")


class OpenCVCamera(BaseModel):
    K: list[list[float]]
    dist: list[float]
    rvec: list[float]
    tvec: list[float]
    image_size: list[int]


class CalibrationOut(BaseModel):
    id: str
    court_id: str
    job_id: str
    spec: str
    opencv: OpenCVCamera
    genome: list[float]
    fitness: float
    quality: dict[str, Any]
    seed: int | None
    bundle: str | None
    generations: int | None
    created_at: datetime
    active: bool
    background_url: str
    overlay_url: str


class CalibrationList(BaseModel):
    calibrations: list[CalibrationOut]


class ProjectRequest(StrictModel):
    court_id: str
    pixels: list[FinitePair] = Field(
        max_length=100_000, description="image points [u, v] in pixels (OpenCV convention)"
    )


class ProjectResponse(BaseModel):
    points: list[FinitePair | None] = Field(
        description="floor [x, y] metres in the court frame; null where the ray misses the floor"
    )
    inside_court: list[bool] = Field(
        description="true where the floor point lies on the court (0..width, 0..length)"
    )
    calibration_id: str


class ImagePointsRequest(StrictModel):
    points: list[FinitePair] = Field(
        max_length=100_000, description="floor points [x, y] in metres (court frame, z = 0)"
    )


class ImagePointsResponse(BaseModel):
    pixels: list[FinitePair | None] = Field(
        description="[u, v] pixels; null where the point is behind the camera"
    )
    in_image: list[bool]
    calibration_id: str


class Health(BaseModel):
    status: Literal["ok"]


class Ready(BaseModel):
    status: Literal["ready"]
    database: str
    revision: str | None
