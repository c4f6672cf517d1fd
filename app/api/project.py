"""Pixels <-> court floor metres through the court's active camera (served from memory)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import orjson
from anyio import to_thread
from fastapi import APIRouter, Request
from fastapi.responses import Response

from app.api.camera_cache import CachedCamera
from app.api.deps import AppState, CallerDep
from app.api.errors import ApiError
from app.api.json_body import body_openapi, parsed_body
from app.api.routing import ApiRoute
from app.calib import camera
from app.calib.camera import PreparedCamera
from app.schemas import ImagePointsRequest, ImagePointsResponse, ProjectRequest, ProjectResponse

router = APIRouter(tags=["project"], route_class=ApiRoute)


def _calibrated(entry: CachedCamera) -> PreparedCamera:
    if entry.camera is None:
        raise ApiError(
            404,
            "no_calibration",
            f"court {entry.court_id!r} has no calibration yet: upload frames or a clip first",
        )
    return entry.camera


async def _court_camera(state: AppState, tenant_id: str, court_id: str) -> CachedCamera:
    """The court's cached camera: from memory on the event loop (the usual case), or loaded from
    the database in a thread when it is not cached yet (or its entry is stale)."""
    entry = state.cameras.peek(tenant_id, court_id)
    if entry is None:
        entry = await to_thread.run_sync(state.cameras.get, tenant_id, court_id)
    return entry


# Output precision: 1 micrometre on the floor, 1/10000 pixel in the image. Far below any camera's
# accuracy, and short numbers halve the cost of writing 100 000 points as JSON.
FLOOR_DECIMALS = 6
PIXEL_DECIMALS = 4


def _pairs_or_null(
    values: np.ndarray, decimals: int, finite: np.ndarray | None = None
) -> np.ndarray | list[list[float] | None]:
    """(M, 2) with NaN rows -> JSON-ready rows, null for those rows: the rounded array itself
    when every row is finite (orjson writes it directly), else a list with None rows.
    `finite`: the rows known to be finite, when the caller knows (saves a pass)."""
    rounded = values.round(decimals)
    if finite is None:
        finite = np.isfinite(values).all(axis=1)
    if finite.all():
        return rounded
    rows: list[list[float] | None] = rounded.tolist()
    for i in np.flatnonzero(~finite):
        rows[i] = None
    return rows


def _json(payload: dict[str, object]) -> Response:
    # built by hand with orjson: 100 000 points through FastAPI's encoder (or the stdlib's) cost
    # several times more than the maths; non-finite rows are already None (never [NaN, NaN])
    body = orjson.dumps(payload, option=orjson.OPT_SERIALIZE_NUMPY)
    return Response(body, media_type="application/json")


def _as_array(pairs: Sequence[Sequence[float]]) -> np.ndarray:
    # the validated body holds pairs (lists of 2 floats): flattening them is twice as fast as
    # numpy's conversion of nested lists
    flat = itertools.chain.from_iterable(pairs)
    return np.fromiter(flat, dtype=np.float64, count=2 * len(pairs)).reshape(-1, 2)


def floor_points_response(
    prepared: PreparedCamera,
    pixels: Sequence[Sequence[float]],
    court_size_m: tuple[float, float],
    calibration_id: str | None,
) -> Response:
    """The ProjectResponse of `pixels` through a camera (also used per calibration)."""
    width_m, length_m = court_size_m
    floor_xy, status = prepared.pixel_to_floor(_as_array(pixels))
    ok = status == camera.RAY_OK
    inside = (
        ok
        & (floor_xy[:, 0] >= 0.0)
        & (floor_xy[:, 0] <= width_m)
        & (floor_xy[:, 1] >= 0.0)
        & (floor_xy[:, 1] <= length_m)
    )
    return _json(
        {
            # the kernel leaves NaN exactly where the status is not RAY_OK
            "points": _pairs_or_null(floor_xy, FLOOR_DECIMALS, finite=ok),
            "inside_court": inside,
            "calibration_id": calibration_id,
        }
    )


def image_points_response(
    genome: np.ndarray,
    points: Sequence[Sequence[float]],
    image_size: tuple[int, int],
    calibration_id: str | None,
) -> Response:
    """The ImagePointsResponse of floor `points` through `genome` (also used per calibration)."""
    # past the lens fold a floor point "projects" to a ghost pixel, often inside the picture
    pixels = camera.floor_to_image_pixel(genome, _as_array(points))
    in_image = camera.pixels_in_image(pixels, image_size)
    return _json(
        {
            "pixels": _pairs_or_null(pixels, PIXEL_DECIMALS),
            "in_image": in_image,
            "calibration_id": calibration_id,
        }
    )


# Both handlers are `async def` and compute on the event loop: the camera comes from memory and the
# kernels are compiled, so a request's work is proportional to its points (1 point: tens of
# microseconds; 100 000, the most a body may hold: tens of milliseconds, less than reading and
# validating that body, which FastAPI does on the loop anyway). A thread hop per request cost
# more than 1-point requests themselves and, under load, milliseconds of GIL hand-over.


@router.post("/project", response_model=ProjectResponse, openapi_extra=body_openapi(ProjectRequest))
async def project(request: Request, caller: CallerDep) -> Response:
    """Image pixels -> floor (x, y) metres in the court frame; null where the ray misses."""
    body = await parsed_body(request, ProjectRequest)  # one pass: see app.api.json_body
    entry = await _court_camera(caller.state, caller.tenant_id, body.court_id)
    return floor_points_response(
        _calibrated(entry),
        body.pixels,
        (entry.court_width_m, entry.court_length_m),
        entry.calibration_id,
    )


@router.post("/courts/{court_id}/image-points", response_model=ImagePointsResponse)
async def image_points(court_id: str, body: ImagePointsRequest, caller: CallerDep) -> Response:
    """Floor (x, y) metres -> image pixels; null where the point is behind the camera or beyond
    the lens's usable field (past the fold of its distortion model)."""
    entry = await _court_camera(caller.state, caller.tenant_id, court_id)
    prepared = _calibrated(entry)
    assert entry.image_size is not None
    return image_points_response(
        prepared.genome, body.points, entry.image_size, entry.calibration_id
    )
