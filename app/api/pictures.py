"""Pictures of a calibration, its court lines as data, and pixel <-> floor through ITS camera.

The active camera of a court is what `/project` uses; these endpoints answer for any calibration
of the court's history (the browser page shows older ones too). Pictures are drawn on request
from the stored background (`app.viewer.pictures`); calibrations never change, so responses may
be cached by the browser.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import cv2
import numpy as np
from anyio import to_thread
from fastapi import APIRouter, Query
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from app import media
from app.api.camera_cache import CachedCamera
from app.api.deps import Caller, CallerDep, SessionDep, StateDep, TenantDep
from app.api.errors import ApiError
from app.api.project import floor_points_response, image_points_response
from app.api.routing import ApiRoute
from app.calib import camera, render
from app.calib.court import court_model, get_spec
from app.db import repo
from app.db.models import Calibration, Job
from app.schemas import (
    CourtLines,
    ErrorResponse,
    ImagePointsRequest,
    ImagePointsResponse,
    PixelsRequest,
    ProjectResponse,
    TopdownRequest,
)
from app.settings import Settings
from app.viewer import pictures

router = APIRouter(tags=["pictures"], route_class=ApiRoute)

_PNG: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/png": {}}, "description": "a PNG picture"},
    404: {"model": ErrorResponse},
    422: {"model": ErrorResponse},
}
WidthQuery = Annotated[
    int | None,
    Query(ge=16, le=8192, description="shrink the picture to this many pixels wide (thumbnails)"),
]
MAX_QUERY_POINTS = 2000
# the stored line evidence (written by the worker since the page arrived)
EVIDENCE_FILE = "edges.png"


def _png(image: np.ndarray) -> Response:
    ok, encoded = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    if not ok:
        raise RuntimeError("PNG encoding failed")
    # a calibration never changes: let the browser keep its pictures for an hour
    return Response(
        encoded.tobytes(),
        media_type="image/png",
        headers={"Cache-Control": "private, max-age=3600"},
    )


def _genome(cal: Calibration) -> np.ndarray:
    return np.asarray(cal.genome, dtype=np.float64)


def _start_genome(cal: Calibration) -> np.ndarray | None:
    start = (cal.result or {}).get("start_genome")
    return None if start is None else np.asarray(start, dtype=np.float64)


def _read(path: Path, flags: int) -> np.ndarray | None:
    if not path.is_file():
        return None
    return cv2.imread(str(path), flags)


def _background(settings: Settings, cal: Calibration) -> np.ndarray:
    """The stored background, or for an imported camera (no picture) a plain dark canvas."""
    image = _read(media.calibration_dir(settings, cal.id) / "background.png", cv2.IMREAD_COLOR)
    if image is None:
        return np.full((cal.image_height, cal.image_width, 3), 48, np.uint8)
    return image


def _evidence(settings: Settings, cal: Calibration) -> np.ndarray:
    stored = _read(media.calibration_dir(settings, cal.id) / EVIDENCE_FILE, cv2.IMREAD_GRAYSCALE)
    if stored is not None:
        return stored
    image = _read(media.calibration_dir(settings, cal.id) / "background.png", cv2.IMREAD_COLOR)
    if image is None:  # imported camera: no picture, no evidence
        return np.zeros((cal.image_height, cal.image_width), np.uint8)
    # calibrated before the evidence was stored: the same extraction, without the players' mask
    return pictures.line_evidence(image)


def _owned(session: SessionDep, tenant_id: str, calibration_id: str) -> Calibration:
    return repo.get_owned(session, Calibration, tenant_id, calibration_id)


@router.get("/calibrations/{calibration_id}/overlay.png", responses=_PNG)
async def get_overlay(
    calibration_id: str,
    state: StateDep,
    session: SessionDep,
    tenant_id: TenantDep,
    camera_: Annotated[
        str,
        Query(
            alias="camera",
            pattern="^(fitted|start|both)$",
            description="which court to draw: the fitted camera's, the start camera's, or both",
        ),
    ] = "fitted",
    width: WidthQuery = None,
) -> Response:
    """The background with the court model drawn over it (green: fitted; orange: start camera)."""
    cal = _owned(session, tenant_id, calibration_id)
    start = _start_genome(cal) if camera_ in ("start", "both") else None
    if camera_ == "start" and start is None:
        raise ApiError(404, "no_start_camera", f"calibration {cal.id} has no start camera")

    def draw() -> Response:
        background = _background(state.settings, cal)
        return _png(
            pictures.overlay_picture(
                background, _genome(cal), cal.spec, start, width, show_fitted=camera_ != "start"
            )
        )

    return await run_in_threadpool(draw)


@router.get("/calibrations/{calibration_id}/edges.png", responses=_PNG)
async def get_edges(
    calibration_id: str,
    state: StateDep,
    session: SessionDep,
    tenant_id: TenantDep,
    width: WidthQuery = None,
) -> Response:
    """The line evidence the fit used (light on black), where players moved left out."""
    cal = _owned(session, tenant_id, calibration_id)
    return await run_in_threadpool(
        lambda: _png(pictures.evidence_picture(_evidence(state.settings, cal), width))
    )


def _parse_points(text: str) -> np.ndarray:
    """ "u,v;u,v;..." -> (M, 2)."""
    rows = [part for part in text.split(";") if part.strip()]
    if len(rows) > MAX_QUERY_POINTS:
        raise ApiError(
            422,
            "too_many_points",
            f"at most {MAX_QUERY_POINTS} points fit in the query; POST them as JSON instead",
        )
    try:
        values = np.array([[float(v) for v in row.split(",")] for row in rows], dtype=np.float64)
    except ValueError:
        values = np.empty((0, 3))
    if len(rows) and (values.ndim != 2 or values.shape[1] != 2 or not np.isfinite(values).all()):
        raise ApiError(
            422,
            "invalid_points",
            "points must be pixel pairs 'u,v' separated by ';', e.g. points=640,500;300,610",
        )
    return values.reshape(-1, 2)


def _topdown(cal: Calibration, pixels: np.ndarray | None, mode: str) -> Response:
    floor = None
    if pixels is not None and len(pixels):
        floor, status = camera.pixel_to_floor(_genome(cal), pixels)
        floor = floor[status == camera.RAY_OK]
    image = pictures.topdown_picture(
        cal.spec, _genome(cal), (cal.image_width, cal.image_height), floor, mode
    )
    return _png(image)


@router.get("/calibrations/{calibration_id}/topdown.png", responses=_PNG)
async def get_topdown(
    calibration_id: str,
    session: SessionDep,
    tenant_id: TenantDep,
    points: Annotated[
        str | None,
        Query(
            description="image pixels 'u,v;u,v;...' to mark at their floor positions "
            f"(at most {MAX_QUERY_POINTS}; POST for more)"
        ),
    ] = None,
    mode: Annotated[
        str,
        Query(
            pattern="^(auto|points|heatmap)$",
            description="points: a marker each; heatmap: their density; auto: heatmap from "
            f"{pictures.HEATMAP_MIN_POINTS} points on",
        ),
    ] = "auto",
) -> Response:
    """The court from above: the floor this camera sees (shaded), the camera, and the floor
    positions of `points` (pixels projected through this calibration's camera)."""
    cal = _owned(session, tenant_id, calibration_id)
    pixels = _parse_points(points) if points else None
    return await run_in_threadpool(_topdown, cal, pixels, mode)


@router.post("/calibrations/{calibration_id}/topdown.png", responses=_PNG)
async def post_topdown(
    calibration_id: str, body: TopdownRequest, session: SessionDep, tenant_id: TenantDep
) -> Response:
    """As GET, for many pixels (e.g. a match's foot positions as a heatmap)."""
    cal = _owned(session, tenant_id, calibration_id)
    pixels = np.asarray(body.pixels, dtype=np.float64).reshape(-1, 2)
    return await run_in_threadpool(_topdown, cal, pixels, body.mode)


@router.get("/calibrations/{calibration_id}/convergence.png", responses=_PNG)
async def get_convergence(
    calibration_id: str, session: SessionDep, tenant_id: TenantDep
) -> Response:
    """Best and mean fitness per generation of each optimisation stage, and each stage's time."""
    cal = _owned(session, tenant_id, calibration_id)
    result = cal.result or {}
    timings = dict(result.get("timings_s") or {})
    if cal.job_id is not None:
        job_timings = repo.get_owned(session, Job, tenant_id, cal.job_id).timings or {}
        if "background" in job_timings:  # the worker's own stage, before the pipeline's
            timings = {"background": job_timings["background"], **timings}
    return await run_in_threadpool(
        lambda: _png(pictures.convergence_picture(result.get("convergence"), timings))
    )


def _rounded_lines(lines: list[np.ndarray]) -> list[list[list[float]]]:
    return [np.round(line, 2).tolist() for line in lines]


@router.get("/calibrations/{calibration_id}/lines", response_model=CourtLines)
def get_lines(calibration_id: str, session: SessionDep, tenant_id: TenantDep) -> dict[str, Any]:
    """The court drawn as data: the fitted (and start) camera's court in image pixels as
    polylines, and the floor plan in metres (court frame), for a page to draw itself."""
    cal = _owned(session, tenant_id, calibration_id)
    model = court_model(cal.spec)
    start = _start_genome(cal)
    spec = get_spec(cal.spec)
    return {
        "calibration_id": cal.id,
        "image_size": [cal.image_width, cal.image_height],
        "court_m": [spec.width_m, spec.length_m],
        "fitted": _rounded_lines(render.court_polylines(_genome(cal), model)),
        "start": None if start is None else _rounded_lines(render.court_polylines(start, model)),
        "floor": pictures.floor_lines_m(cal.spec),
    }


async def _calibration_camera(caller: Caller, calibration_id: str) -> CachedCamera:
    """One calibration's camera: from memory on the event loop, or loaded in a thread on a miss."""
    cameras = caller.state.cameras
    entry = cameras.peek_calibration(caller.tenant_id, calibration_id)
    if entry is None:
        entry = await to_thread.run_sync(cameras.calibration, caller.tenant_id, calibration_id)
    return entry


# async, from memory, like /project (see there): a calibration's camera never changes
@router.post("/calibrations/{calibration_id}/project", response_model=ProjectResponse)
async def project_with_calibration(
    calibration_id: str, body: PixelsRequest, caller: CallerDep
) -> Response:
    """Image pixels -> floor (x, y) metres through this calibration's camera (active or not)."""
    entry = await _calibration_camera(caller, calibration_id)
    assert entry.camera is not None
    return floor_points_response(
        entry.camera, body.pixels, (entry.court_width_m, entry.court_length_m), entry.calibration_id
    )


@router.post("/calibrations/{calibration_id}/image-points", response_model=ImagePointsResponse)
async def image_points_with_calibration(
    calibration_id: str, body: ImagePointsRequest, caller: CallerDep
) -> Response:
    """Floor (x, y) metres -> image pixels through this calibration's camera (active or not)."""
    entry = await _calibration_camera(caller, calibration_id)
    assert entry.camera is not None and entry.image_size is not None
    return image_points_response(
        entry.camera.genome, body.points, entry.image_size, entry.calibration_id
    )
