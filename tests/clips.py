"""Synthetic clips with camera cuts, zooms and dissolves for the shot and clip-background tests.

The one place the shot tests (and bench.clip_background) import the scene renderer from.
"""

from __future__ import annotations

import cv2
import numpy as np

from app.calib.camera import GENE
from app.calib.scene import render_clip_frames, render_court_image, write_video
from app.calib.synthetic import typical_target_camera

__all__ = [
    "close_up_camera",
    "dissolve",
    "main_camera",
    "render_clip_frames",
    "render_court_image",
    "write_video",
    "zoomed",
]


def main_camera(image_size: tuple[int, int]) -> np.ndarray:
    """The broadcast-like camera behind the back wall."""
    return typical_target_camera(image_size)


def close_up_camera(image_size: tuple[int, int]) -> np.ndarray:
    """The same camera position zoomed 2.2x onto the middle of the court (a replay close-up)."""
    genome = typical_target_camera(image_size)
    genome[GENE["f_u"]] *= 2.2
    genome[GENE["f_v"]] *= 2.2
    return genome


def zoomed(frame: np.ndarray, scale: float) -> np.ndarray:
    """The frame magnified by `scale` about its centre (a zoom of the lens, seen in the image)."""
    height, width = frame.shape[:2]
    centre_u, centre_v = (width - 1) / 2.0, (height - 1) / 2.0
    warp = np.array(
        [[scale, 0.0, (1.0 - scale) * centre_u], [0.0, scale, (1.0 - scale) * centre_v]]
    )
    return cv2.warpAffine(frame, warp, (width, height), flags=cv2.INTER_LINEAR)


def dissolve(a: np.ndarray, b: np.ndarray, weight_b: float) -> np.ndarray:
    """A frame of a cross-fade: (1 - weight_b) a + weight_b b."""
    return cv2.addWeighted(a, 1.0 - weight_b, b, weight_b, 0.0)
