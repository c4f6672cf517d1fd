"""A court's cameras: choose the active one, import one, export one as OpenCV YAML.

A court keeps every calibration it ever had; the active one is what `/project` uses. Choosing
another makes nothing disappear.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter
from fastapi.responses import Response

from app.api.deps import SessionDep, TenantDep, WriteSessionDep
from app.api.errors import ApiError
from app.api.routing import ApiRoute
from app.api.serialize import calibration_out
from app.calib import camera
from app.db import repo
from app.db.models import Calibration, Court
from app.schemas import ActivateCamera, CalibrationOut, CameraImport, ErrorResponse
from app.viewer.camera_text import opencv_yaml

router = APIRouter(tags=["cameras"], route_class=ApiRoute)

_ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorResponse} for code in (401, 404, 422)
}
MAX_IMPORT_IMAGE_PX = 16384


@router.post("/courts/{court_id}/camera", response_model=CalibrationOut, responses=_ERRORS)
def set_active_camera(
    court_id: str, body: ActivateCamera, session: WriteSessionDep, tenant_id: TenantDep
) -> CalibrationOut:
    """Make one of the court's calibrations the active camera (what `/project` uses from now
    on, within the camera cache's refresh interval). The previous one stays in the history."""
    court = repo.get_owned(session, Court, tenant_id, court_id)
    cal = repo.get_owned(session, Calibration, tenant_id, body.calibration_id)
    if cal.court_id != court.id:
        raise ApiError(
            422,
            "calibration_of_another_court",
            f"calibration {cal.id} belongs to another court; pick one from "
            f"GET /courts/{court.id}/calibrations",
        )
    court.active_calibration_id = cal.id
    session.commit()
    return calibration_out(cal, active=True)


@router.post(
    "/courts/{court_id}/calibrations/import",
    status_code=201,
    response_model=CalibrationOut,
    responses=_ERRORS,
)
def import_camera(
    court_id: str, body: CameraImport, session: WriteSessionDep, tenant_id: TenantDep
) -> CalibrationOut:
    """Store an existing camera (the OpenCV JSON form, court frame) as a calibration of the
    court. It has no picture and no fitness; by default it becomes the active camera."""
    court = repo.get_owned(session, Court, tenant_id, court_id)
    try:
        genome, image_size = camera.camera_from_json(body.camera)
    except (ValueError, TypeError, KeyError) as exc:
        raise ApiError(422, "invalid_camera", f"camera: {exc}") from None
    if image_size is None:
        raise ApiError(
            422,
            "invalid_camera",
            'camera: "image_size": [width, height] is needed (the pixels the camera maps)',
        )
    if max(image_size) > MAX_IMPORT_IMAGE_PX:
        raise ApiError(422, "invalid_camera", f"camera: image_size above {MAX_IMPORT_IMAGE_PX} px")
    if not np.all(np.isfinite(genome)) or genome[0] <= 0 or genome[1] <= 0:
        raise ApiError(422, "invalid_camera", "camera: focal lengths must be positive numbers")
    opencv = camera.to_opencv(genome, image_size)
    cal = Calibration(
        tenant_id=tenant_id,
        court_id=court.id,
        job_id=None,
        spec=court.spec,
        genome=[float(v) for v in genome],
        opencv=opencv,
        fitness=None,
        quality={},
        result={"source": "import", "opencv": opencv, "genome": [float(v) for v in genome]},
        image_width=image_size[0],
        image_height=image_size[1],
    )
    session.add(cal)
    session.flush()
    if body.activate:
        court.active_calibration_id = cal.id
    session.commit()
    return calibration_out(cal, active=body.activate)


@router.get(
    "/calibrations/{calibration_id}/camera.yaml",
    responses={200: {"content": {"application/x-yaml": {}}}, 404: {"model": ErrorResponse}},
)
def get_camera_yaml(calibration_id: str, session: SessionDep, tenant_id: TenantDep) -> Response:
    """The camera as an OpenCV FileStorage YAML file (K, dist, rvec, tvec, image size; court
    frame), readable with `cv2.FileStorage(path, cv2.FILE_STORAGE_READ)`."""
    cal = repo.get_owned(session, Calibration, tenant_id, calibration_id)
    return Response(
        opencv_yaml(cal.opencv, cal.id),
        media_type="application/x-yaml",
        headers={"Content-Disposition": f'attachment; filename="camera-{cal.id[:8]}.yaml"'},
    )
