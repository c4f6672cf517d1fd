"""Which court surface each pixel shows under a camera, and the evidence that lies off the court.

Once a camera is known, much of what is not court can be named: a glass side wall mirrors the
floor's lines, so their images sit on the wall's plane although no line is painted there; crowds
and adverts seen through or on glass walls sit there too; the hall around the court is no surface
at all. `surface_labels` casts each pixel's ray into the court box (floor and the walls seen from
inside; a wall between the camera and the court, like the glass back wall a broadcast camera looks
through, is treated as transparent). `evidence_on_court` keeps evidence on the floor and the front
wall, and on the other walls only along the model's lines there.
"""

from __future__ import annotations

import cv2
import numpy as np

from app.calib import camera, render
from app.calib.court import CourtModel
from app.calib.lines import LineEvidence

NONE, FLOOR, FRONT, LEFT, RIGHT, BACK = 0, 1, 2, 3, 4, 5
# walls reach this far above their out lines (m)
WALL_ABOVE_OUT_M = 0.3
LABEL_STEP_PX = 2


def surface_labels(
    genome: np.ndarray, image_size: tuple[int, int], model: CourtModel, step_px: int = LABEL_STEP_PX
) -> np.ndarray:
    """uint8 (H, W): the court surface (FLOOR, FRONT, LEFT, RIGHT, BACK, or NONE) each pixel's
    ray meets first, on a grid `step_px` apart (nearest-neighbour up to full size)."""
    width, height = image_size
    g = camera.as_population(genome)[0]
    us = np.arange(0, width, step_px, dtype=np.float64)
    vs = np.arange(0, height, step_px, dtype=np.float64)
    gu, gv = np.meshgrid(us, vs)
    with np.errstate(all="ignore"):
        xn, yn, ok = camera.undistort_normalized(
            (gu - g[2]) / g[0], (gv - g[3]) / g[1], g[camera.DISTORTION_GENES]
        )
    r, t = camera.court_extrinsics(g)
    rotation = r[0]
    centre = -rotation.T @ t[0]
    rays = np.stack([xn, yn, np.ones_like(xn)], axis=-1) @ rotation  # R^T d, per pixel
    spec = model.spec
    w_m, l_m = spec.width_m, spec.length_m
    front_top = float(model.node("front_out_left")[2]) - WALL_ABOVE_OUT_M
    back_top = float(model.node("back_out_left")[2]) - WALL_ABOVE_OUT_M
    best = np.full(xn.shape, np.inf)
    label = np.zeros(xn.shape, np.uint8)
    with np.errstate(all="ignore"):

        def consider(code: int, s: np.ndarray, inside: np.ndarray) -> None:
            hit = ok & inside & (s > 0) & (s < best)
            best[hit] = s[hit]
            label[hit] = code

        def point(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return (
                centre[0] + s * rays[..., 0],
                centre[1] + s * rays[..., 1],
                centre[2] + s * rays[..., 2],
            )

        s = -centre[2] / rays[..., 2]
        x, y, _ = point(s)
        consider(FLOOR, s, (x >= 0) & (x <= w_m) & (y >= 0) & (y <= l_m))
        # walls count only when the camera is on the court's side of them
        if centre[1] > 0.0:
            s = -centre[1] / rays[..., 1]
            x, _, z = point(s)
            consider(FRONT, s, (x >= 0) & (x <= w_m) & (z <= 0) & (z >= front_top))
        if centre[1] < l_m:
            s = (l_m - centre[1]) / rays[..., 1]
            x, _, z = point(s)
            consider(BACK, s, (x >= 0) & (x <= w_m) & (z <= 0) & (z >= back_top))
        for code, wall_x, seen in ((LEFT, 0.0, centre[0] > 0.0), (RIGHT, w_m, centre[0] < w_m)):
            if not seen:
                continue
            s = (wall_x - centre[0]) / rays[..., 0]
            _, y, z = point(s)
            top = front_top + (back_top - front_top) * y / l_m
            consider(code, s, (y >= 0) & (y <= l_m) & (z <= 0) & (z >= top))
    full = cv2.resize(label, (width, height), interpolation=cv2.INTER_NEAREST)
    return full


def evidence_on_court(
    evidence: LineEvidence, genome: np.ndarray, model: CourtModel, tolerance_px: float
) -> LineEvidence:
    """The evidence with what lies off the court under `genome` marked ignored: evidence is kept
    on the floor and the front wall, and elsewhere (side and back walls, glass, the hall) only
    within `tolerance_px` of the model's own lines there."""
    height, width = evidence.shape
    labels = surface_labels(genome, (width, height), model)
    wall_edges = [
        name
        for name, (a, b) in zip(model.edge_names, model.edges, strict=True)
        if not (model.nodes[a][2] == 0.0 and model.nodes[b][2] == 0.0)
    ]
    near_lines = render.draw_court(
        np.zeros((height, width), np.uint8),
        genome,
        model.subset(wall_edges),
        255,
        max(1, int(round(2 * tolerance_px))),
    )
    keep = (labels == FLOOR) | (labels == FRONT) | (near_lines > 0)
    # the floor's own junctions with the walls sit on the boundary of the floor's label
    keep |= (
        cv2.dilate(
            (labels == FLOOR).astype(np.uint8),
            np.ones((3, 3), np.uint8),
            iterations=int(tolerance_px) + 1,
        )
        > 0
    )
    return LineEvidence(
        kind=evidence.kind,
        normal_rad=evidence.normal_rad,
        offset_px=evidence.offset_px,
        contrast=evidence.contrast,
        width_px=evidence.width_px,
        ignore=evidence.ignore | ~keep,
        noise=evidence.noise,
    )
