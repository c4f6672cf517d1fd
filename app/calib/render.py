"""Drawing the projected court: the one rasteriser behind edge images, the literal fitness and overlays."""

from __future__ import annotations

import cv2
import numpy as np

from app.calib.camera import court_extrinsics, lens_fold_radius, project_points
from app.calib.court import CourtModel, sample_edges

# Edges are drawn as polylines through samples this far apart, so lens distortion bends them.
DRAW_SPACING_M = 0.02


def court_polylines(genome: np.ndarray, model: CourtModel) -> list[np.ndarray]:
    """Projected court edges as pixel polylines (K, 2) float64, split where points go behind the camera
    or past the lens fold."""
    samples = sample_edges(model, DRAW_SPACING_M)
    pixels, depth = project_points(genome, samples.points)
    # points past the lens fold project back into the picture as ghost loops: leave them out
    r, t = court_extrinsics(genome)
    cam = samples.points @ r[0].T + t[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        radius2 = (cam[:, 0] ** 2 + cam[:, 1] ** 2) / cam[:, 2] ** 2
    drawable = (depth > 1e-6) & (radius2 < lens_fold_radius(genome) ** 2)
    lines: list[np.ndarray] = []
    for e in range(len(samples.offsets) - 1):
        lo, hi = samples.offsets[e], samples.offsets[e + 1]
        front = drawable[lo:hi]
        px = pixels[lo:hi]
        # split into runs of consecutive in-front samples
        edges = np.flatnonzero(np.diff(np.concatenate([[0], front.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if stop - start >= 2:
                lines.append(px[start:stop])
    return lines


def draw_court(
    image: np.ndarray,
    genome: np.ndarray,
    model: CourtModel,
    color: int | tuple[int, int, int] = 255,
    thickness_px: int = 1,
) -> np.ndarray:
    """Draw the projected court onto a copy of `image` (grey or BGR), anti-aliasing off."""
    out = image.copy()
    # cv2 draws integer vertices; use its fixed-point shift to keep sub-pixel positions
    shift = 4
    scale = float(1 << shift)
    height, width = out.shape[:2]
    limit = 4.0 * max(width, height)  # keep far off-image vertices inside cv2's int range
    polylines = [
        np.round(np.clip(line, -limit, limit) * scale).astype(np.int32).reshape(-1, 1, 2)
        for line in court_polylines(genome, model)
    ]
    if polylines:
        cv2.polylines(
            out, polylines, False, color, thickness=thickness_px, lineType=cv2.LINE_8, shift=shift
        )
    return out


def rasterize_court(
    genome: np.ndarray, model: CourtModel, image_size: tuple[int, int], thickness_px: int = 1
) -> np.ndarray:
    """Binary uint8 (H, W) image of the projected court: 255 on the lines, 0 elsewhere."""
    width, height = image_size
    return draw_court(np.zeros((height, width), np.uint8), genome, model, 255, thickness_px)
