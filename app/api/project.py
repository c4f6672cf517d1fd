"""Pixels <-> court floor metres through the court's active camera (served from memory)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import orjson
from fastapi import APIRouter
from fastapi.responses import Response

from app.api.camera_cache import CachedCamera
from app.api.deps import StateDep, TenantDep
from app.api.errors import ApiError
from app.calib import camera
from app.schemas import ImagePointsRequest, ImagePointsResponse, ProjectRequest, ProjectResponse

router = APIRouter(tags=["project"])


def _calibrated(entry: CachedCamera) -> np.ndarray:
    if entry.genome is None:
        raise ApiError(
            404,
            "no_calibration",
            f"court {entry.court_id!r} has no calibration yet: upload frames or a clip first",
        )
    return entry.genome


# Output precision: 1 micrometre on the floor, 1/10000 pixel in the image. Far below any camera's
# accuracy, and short numbers halve the cost of writing 100 000 points as JSON.
FLOOR_DECIMALS = 6
PIXEL_DECIMALS = 4


def _pairs_or_null(values: np.ndarray, decimals: int) -> list[list[float] | None]:
    """(M, 2) with NaN rows -> JSON-ready list with None for those rows."""
    finite = np.isfinite(values).all(axis=1)
    rows: list[list[float] | None] = np.round(values, decimals).tolist()
    for i in np.flatnonzero(~finite):
        rows[i] = None
    return rows


def _json(payload: dict[str, object]) -> Response:
    # built by hand with orjson: 100 000 points through FastAPI's encoder (or the stdlib's) cost
    # several times more than the maths; non-finite rows are already None, so no NaN reaches it
    return Response(orjson.dumps(payload), media_type="application/json")


def _as_array(pairs: Sequence[Sequence[float]]) -> np.ndarray:
    return np.asarray(pairs, dtype=np.float64).reshape(-1, 2)


def floor_points_response(
    genome: np.ndarray,
    pixels: Sequence[Sequence[float]],
    court_size_m: tuple[float, float],
    calibration_id: str | None,
) -> Response:
    """The ProjectResponse of `pixels` through `genome` (also used per calibration)."""
    width_m, length_m = court_size_m
    floor_xy, status = camera.pixel_to_floor(genome, _as_array(pixels))
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
            "points": _pairs_or_null(floor_xy, FLOOR_DECIMALS),
            "inside_court": inside.tolist(),
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
            "in_image": in_image.tolist(),
            "calibration_id": calibration_id,
        }
    )


@router.post("/project", response_model=ProjectResponse)
def project(body: ProjectRequest, state: StateDep, tenant_id: TenantDep) -> Response:
    """Image pixels -> floor (x, y) metres in the court frame; null where the ray misses."""
    entry = state.cameras.get(tenant_id, body.court_id)
    genome = _calibrated(entry)
    return floor_points_response(
        genome, body.pixels, (entry.court_width_m, entry.court_length_m), entry.calibration_id
    )


@router.post("/courts/{court_id}/image-points", response_model=ImagePointsResponse)
def image_points(
    court_id: str, body: ImagePointsRequest, state: StateDep, tenant_id: TenantDep
) -> Response:
    """Floor (x, y) metres -> image pixels; null where the point is behind the camera or beyond
    the lens's usable field (past the fold of its distortion model)."""
    entry = state.cameras.get(tenant_id, court_id)
    genome = _calibrated(entry)
    assert entry.image_size is not None
    return image_points_response(genome, body.points, entry.image_size, entry.calibration_id)
