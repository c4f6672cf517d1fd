"""Request and response models: the public contract of the HTTP API."""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from app.db import models

# The database's enums as Literals: the OpenAPI schema keeps its inline string enums and cannot
# drift from what the jobs table's CHECK constraints allow.
if TYPE_CHECKING:  # mypy cannot follow a computed Literal: it checks these as plain strings
    JobStatus = str
    JobStage = str
    AttemptOutcome = str
else:
    JobStatus = Literal[tuple(s.value for s in models.JobStatus)]
    JobStage = Literal[tuple(s.value for s in models.JobStage)]
    AttemptOutcome = Literal[tuple(s.value for s in models.AttemptOutcome)]
# the court specifications of app.calib.court.COURT_SPECS (a test keeps the two equal)
CourtSpecName = Literal["wsf", "psa", "doubles"]
# (u, v) pixels or (x, y) floor metres; JSON has no NaN/Infinity, and Python's "NaN" tokens are refused.
# A list of two, not tuple[float, float]: that would be `prefixItems` in the schema, which many
# OpenAPI tools cannot read.
FinitePair = Annotated[list[float], Field(min_length=2, max_length=2)]


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class ErrorDetail(BaseModel):
    code: str = Field(examples=["not_found"])
    message: str


class ErrorResponse(BaseModel):
    error: ErrorDetail


class CourtCreate(StrictModel):
    # no NUL character: PostgreSQL cannot store one in text (SQLite would, and answer differently)
    name: str = Field(
        min_length=1,
        max_length=200,
        pattern=r"^[^\x00]*$",
        description="1 to 200 characters, any but NUL (U+0000)",
    )
    spec: CourtSpecName = Field(
        default="wsf", description="court specification: wsf, psa or doubles"
    )


class CourtOut(BaseModel):
    id: str
    name: str
    spec: CourtSpecName
    active_calibration_id: str | None
    created_at: datetime


class CourtList(BaseModel):
    courts: list[CourtOut]
    next_offset: int | None = Field(description="`offset` of the next page; null on the last page")


class JobAccepted(BaseModel):
    job_id: str
    status: JobStatus


class JobError(BaseModel):
    code: str
    message: str


class JobAttemptOut(BaseModel):
    """One claim of the job by a worker process, and how it ended. Which worker held it is kept
    in the database for operators (job_attempts.worker_id: host and process) and not shown to
    tenants."""

    attempt: int = Field(
        ge=1,
        description="the job's attempt number at the claim (1 = first); a released attempt does "
        "not count, so the claim after it has the same number",
    )
    claimed_at: datetime
    ended_at: datetime | None = Field(description="null while the worker holds the job")
    outcome: AttemptOutcome | None = Field(
        description="null while running; succeeded: stored its calibration; failed: recorded an "
        "error and the job failed; failed_retry: recorded an error and the job was queued again; "
        "released: its worker gave the job back on shutdown; lease_lost: its worker stopped "
        "renewing its lease (ended when the job was taken again, or failed as worker_lost)"
    )
    error_code: str | None = Field(
        description="the error the attempt recorded (outcomes failed and failed_retry)"
    )


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
    heartbeat_at: datetime | None = Field(
        description="when the worker running the job last renewed its lease (null if never run)"
    )
    stale: bool = Field(
        description="running, but its worker has not renewed the lease in time (it has probably "
        "died): the job goes back to the queue and is retried while attempts remain"
    )
    media_kind: Literal["images", "video"]
    n_files: int
    error: JobError | None
    calibration_id: str | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    timings_s: dict[str, float] = Field(description="seconds per stage, as far as the job got")
    attempt_history: list[JobAttemptOut] = Field(
        description="every claim of the job by a worker, in order (`attempts` counts them, "
        "less the released ones)"
    )


class OpenCVCamera(BaseModel):
    K: list[list[float]]
    dist: list[float]
    rvec: list[float]
    tvec: list[float]
    image_size: list[int]


class Verdict(BaseModel):
    """Whether a person can trust the camera: "good", or "check" (look at the overlay first)."""

    model_config = ConfigDict(extra="allow")
    label: str = Field(examples=["good", "check"])
    score: float | None = None
    reasons: list[str] = Field(default_factory=list)
    figures: dict[str, Any] = Field(default_factory=dict)


class CameraPose(BaseModel):
    """Where the camera is and where it looks, in the court frame."""

    position_m: list[float] = Field(description="camera centre (x, y, z), z down (above floor < 0)")
    height_m: float = Field(description="height above the floor, positive metres")
    pan_deg: float = Field(description="0 = looking straight at the front wall; + = to the right")
    tilt_deg: float = Field(description="degrees below the horizontal")
    roll_deg: float = Field(
        description="rotation about the viewing direction; + = picture's right side lower"
    )
    fov_deg: list[float] = Field(description="field of view across and down the image")


class CalibrationOut(BaseModel):
    id: str
    court_id: str
    job_id: str | None = Field(description="the job that made it; null for an imported camera")
    source: Literal["upload", "import"]
    spec: str
    opencv: OpenCVCamera
    genome: list[float]
    fitness: float | None = Field(description="the GA fitness; null for an imported camera")
    quality: dict[str, Any]
    verdict: Verdict | None = None
    uncertainty: dict[str, Any] | None = None
    pose: CameraPose
    seed: int | None
    bundle: str | None
    generations: int | None
    created_at: datetime
    active: bool
    background_url: str
    overlay_url: str
    timings_s: dict[str, float] = Field(default_factory=dict, description="seconds per stage")


class JobList(BaseModel):
    jobs: list[JobOut]


class ActivateCamera(StrictModel):
    calibration_id: str = Field(
        description="a calibration of this court; it becomes the active one"
    )


class CameraImport(StrictModel):
    camera: dict[str, Any] = Field(
        description='the OpenCV JSON form {"K", "dist", "rvec", "tvec", "image_size"} (court frame)'
    )
    activate: bool = Field(default=True, description="make it the court's active camera")


class PixelsRequest(StrictModel):
    pixels: list[FinitePair] = Field(
        max_length=100_000, description="image points [u, v] in pixels (OpenCV convention)"
    )


class TopdownRequest(PixelsRequest):
    mode: Literal["auto", "points", "heatmap"] = "auto"


class FloorPlan(BaseModel):
    outline: list[list[list[float]]] = Field(description="wall/floor junctions: [[x, y], [x, y]] m")
    painted: list[list[list[float]]] = Field(description="painted floor lines: [[x, y], [x, y]] m")


class CourtLines(BaseModel):
    """The court drawn as data, for a page that draws it itself."""

    calibration_id: str
    image_size: list[int]
    court_m: list[float] = Field(description="court width and length in metres")
    fitted: list[list[list[float]]] = Field(
        description="the fitted camera's court: pixel polylines"
    )
    start: list[list[list[float]]] | None = Field(description="the start camera's court, if any")
    floor: FloorPlan


class Me(BaseModel):
    tenant_id: str
    tenant_name: str
    key_name: str


class PageConfig(BaseModel):
    """What the browser page needs to know before it talks to the API."""

    specs: list[dict[str, Any]]
    max_upload_bytes: int
    max_files: int
    image_types: list[str]
    video_types: list[str]


class CalibrationList(BaseModel):
    calibrations: list[CalibrationOut]
    next_offset: int | None = Field(description="`offset` of the next page; null on the last page")


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
        description="[u, v] pixels; null where the point is behind the camera or beyond the "
        "lens's usable field (past the fold of its distortion model)"
    )
    in_image: list[bool]
    calibration_id: str


class Health(BaseModel):
    status: Literal["ok"]


class Ready(BaseModel):
    status: Literal["ready"]
    revision: str | None
