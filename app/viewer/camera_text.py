"""A camera for people: its pose in court words, and the OpenCV YAML (FileStorage) export."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from app.calib import camera


def camera_pose(genome: np.ndarray, image_size: tuple[int, int]) -> dict[str, Any]:
    """Where the camera is and where it looks, in the court frame (metres, degrees).

    position_m: the camera centre (x, y, z; z down, so a camera above the floor has z < 0);
    height_m: its height above the floor (positive); pan_deg: the viewing direction seen from
    above, 0 = straight at the front wall, positive = turned towards the right side wall; tilt_deg:
    how far it looks below the horizontal; roll_deg: rotation about the viewing direction,
    positive = the picture's right side lower; field of view across and down the image.
    """
    g = camera.as_population(genome)[0]
    r, t = camera.court_extrinsics(g)
    rotation, translation = r[0], t[0]
    centre = -rotation.T @ translation
    right, down, forward = rotation  # the camera's axes in court coordinates
    width, height = image_size
    return {
        "position_m": [float(v) for v in centre],
        "height_m": float(-centre[2]),
        "pan_deg": math.degrees(math.atan2(forward[0], -forward[1])),
        "tilt_deg": math.degrees(math.atan2(forward[2], math.hypot(forward[0], forward[1]))),
        "roll_deg": math.degrees(math.atan2(right[2], math.hypot(right[0], right[1]))),
        "fov_deg": [
            math.degrees(2 * math.atan2(width / 2.0, float(g[0]))),
            math.degrees(2 * math.atan2(height / 2.0, float(g[1]))),
        ],
    }


YAML_COMMENT = (
    "squashcal camera. Court frame: metres, origin at the floor corner of the front wall and the "
    "LEFT side wall (seen from the back), x to the right side wall, y to the back wall, z down. "
    "cv2.projectPoints(points, rvec, tvec, K, dist) gives pixels (origin at the centre of the "
    "top-left pixel)."
)


def opencv_yaml(opencv: dict[str, Any], calibration_id: str | None = None) -> str:
    """The OpenCV JSON form as a YAML document `cv2.FileStorage` reads back (K, dist, rvec, tvec,
    image_width, image_height; dist as a 1x5 matrix, rvec/tvec as 3x1)."""
    storage = cv2.FileStorage(
        "camera.yaml",
        cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY | cv2.FILE_STORAGE_FORMAT_YAML,
    )
    storage.writeComment(YAML_COMMENT)
    if calibration_id is not None:
        storage.write("calibration_id", calibration_id)
    width, height = (int(v) for v in opencv["image_size"])
    storage.write("image_width", width)
    storage.write("image_height", height)
    storage.write("K", np.asarray(opencv["K"], dtype=np.float64).reshape(3, 3))
    storage.write("dist", np.asarray(opencv["dist"], dtype=np.float64).reshape(1, 5))
    storage.write("rvec", np.asarray(opencv["rvec"], dtype=np.float64).reshape(3, 1))
    storage.write("tvec", np.asarray(opencv["tvec"], dtype=np.float64).reshape(3, 1))
    text: str = storage.releaseAndGetString()
    return text
