"""Synthetic data for the paper's protocol (section VII).

- Target cameras and the wiggle operator of Table 3 (start cameras at near / medium / far distance).
- Edge images of a known camera (`render_edge_image`, the one court rasteriser) and the five noise
  types of Fig. 8 plus "none".
- Metrics: mean reprojection error (MRE) on the court nodes G_c, the bounding box grid G_b and the
  16 x 16 floor grid G_p.

Realistic ray-cast renders of courts (images and clips) live in `scene.py`.

Noise densities (the paper gives none). Every noise pattern is defined relative to the image, so the
normalised distance map, and therefore the fitness landscape, looks the same at every resolution:
- salt: `SALT_DOTS` = 4000 single white pixels at uniformly random positions (0.19 % of a 1920 x 1080
  image; mean distance to the nearest dot ~11 px there), the same count at every size;
- horizontal / vertical lines: 1 px lines every `LINE_SPACING_FRACTION` = 1/16 of the image height
  (67 px at 1080 rows), random phase; "grid" is both with independent phases;
- grid45: the grid rotated by 45 degrees (8-connected diagonals, same perpendicular spacing).
"""

from __future__ import annotations

import numpy as np

from app.calib.camera import (
    DISTORTION_GENES,
    GENE,
    N_GENES,
    as_population,
    check_image_size,
    project_points,
)
from app.calib.court import CourtModel, bounding_box_grid, floor_grid
from app.calib.render import rasterize_court

# ----------------------------------------------------------------------------------------------
# Target camera and the wiggle operator (Table 3)

REFERENCE_IMAGE_SIZE = (1920, 1080)


def typical_target_camera(image_size: tuple[int, int] = REFERENCE_IMAGE_SIZE) -> np.ndarray:
    """A typical squash recording camera: centred behind the (glass) back wall, looking down the court.

    At 1920 x 1080: f = 1500 px, principal point at the image centre, t = (0, 2.3, 8.5) m in the
    paper frame (camera 4.7 m above the floor, 7.4 m behind the back wall), alpha = 0.3 rad and a mild
    barrel distortion. Other sizes scale the focal length by the limiting dimension, so the whole court
    stays in the image with the same margins whatever the aspect ratio.
    """
    width, height = check_image_size(image_size)
    scale = min(width / REFERENCE_IMAGE_SIZE[0], height / REFERENCE_IMAGE_SIZE[1])
    genome = np.zeros(N_GENES)
    genome[0:4] = [1500.0 * scale, 1500.0 * scale, width / 2.0, height / 2.0]
    genome[4:7] = [0.0, 2.3, 8.5]
    genome[GENE["alpha"]] = 0.3
    genome[DISTORTION_GENES] = [-0.12, 0.05, 0.001, -0.0005, 0.0]
    return genome


def _table3_row(
    intrinsic_px: float,
    t_xz_m: float,
    t_y_m: float,
    angle_rad: float,
    k12: float,
    p1: float,
    p2: float,
    k3: float,
) -> np.ndarray:
    row = np.empty(N_GENES)
    row[0:4] = intrinsic_px
    row[GENE["t_x"]] = row[GENE["t_z"]] = t_xz_m
    row[GENE["t_y"]] = t_y_m
    row[7:10] = angle_rad
    row[GENE["k1"]] = row[GENE["k2"]] = k12
    row[GENE["p1"]] = p1
    row[GENE["p2"]] = p2
    row[GENE["k3"]] = k3
    row.setflags(write=False)
    return row


# Table 3: the offset added (with a random sign) to each wiggled gene, per start distance. Pixel
# offsets are the paper's, meant for its 1920 x 1080 images.
TABLE3_OFFSETS: dict[str, np.ndarray] = {
    "near": _table3_row(10.0, 0.1, 0.1, 0.01, 0.1, 0.025, 0.01, 0.5),
    "medium": _table3_row(50.0, 0.5, 0.5, 0.1, 0.25, 0.1, 0.05, 1.5),
    "far": _table3_row(100.0, 1.0, 2.0, 0.2, 0.5, 0.2, 0.1, 3.0),
}
DISTANCES: tuple[str, ...] = tuple(TABLE3_OFFSETS)
N_WIGGLED_GENES = N_GENES // 2  # floor(15 / 2) = 7, "about half" of the genes (section VII)


def wiggle_camera(
    genome: np.ndarray, distance: str, rng: np.random.Generator | int | None
) -> np.ndarray:
    """Start camera for the protocol: 7 distinct random genes moved by +- the Table 3 offset."""
    if distance not in TABLE3_OFFSETS:
        raise ValueError(f"unknown distance {distance!r}; expected one of {', '.join(DISTANCES)}")
    rng = np.random.default_rng(rng)
    start = as_population(genome)[0].copy()
    genes = rng.choice(N_GENES, size=N_WIGGLED_GENES, replace=False)
    signs = rng.choice(np.array([-1.0, 1.0]), size=N_WIGGLED_GENES)
    start[genes] += signs * TABLE3_OFFSETS[distance][genes]
    return start


# ----------------------------------------------------------------------------------------------
# Edge images and noise (Fig. 8)

render_edge_image = rasterize_court

NOISE_TYPES: tuple[str, ...] = ("none", "salt", "horizontal", "vertical", "grid", "grid45")
SALT_DOTS = 4000
LINE_SPACING_FRACTION = 1.0 / 16.0


def noise_line_spacing_px(image_height_px: int) -> int:
    """Distance between neighbouring noise lines (perpendicular to them) for an image height."""
    return max(4, round(image_height_px * LINE_SPACING_FRACTION))


def add_noise(
    edge_image: np.ndarray, kind: str, rng: np.random.Generator | int | None
) -> np.ndarray:
    """A copy of a binary edge image (H, W) uint8 with one of the `NOISE_TYPES` added as 255 pixels."""
    if kind not in NOISE_TYPES:
        raise ValueError(f"unknown noise type {kind!r}; expected one of {', '.join(NOISE_TYPES)}")
    image = np.asarray(edge_image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"edge_image must be uint8 (H, W), got {image.dtype} {image.shape}")
    rng = np.random.default_rng(rng)
    out = image.copy()
    height, width = out.shape
    spacing = noise_line_spacing_px(height)
    if kind == "salt":
        flat = rng.choice(height * width, size=min(SALT_DOTS, height * width), replace=False)
        out.ravel()[flat] = 255
    if kind in ("horizontal", "grid"):
        out[int(rng.integers(spacing)) :: spacing, :] = 255
    if kind in ("vertical", "grid"):
        out[:, int(rng.integers(spacing)) :: spacing] = 255
    if kind == "grid45":
        # u + v = c and u - v = c, c every spacing * sqrt(2) so the perpendicular spacing matches
        step = max(2, round(spacing * np.sqrt(2.0)))
        rows = np.arange(height)[:, None]
        cols = np.arange(width)[None, :]
        phase_sum, phase_diff = rng.integers(step, size=2)
        on = ((rows + cols) % step == phase_sum) | ((rows - cols) % step == phase_diff)
        out[on] = 255
    return out


# ----------------------------------------------------------------------------------------------
# Metrics


def mean_reprojection_error(target: np.ndarray, result: np.ndarray, points: np.ndarray) -> float:
    """Mean pixel distance between the points (M, 3) projected by the target and by the result camera.

    A point behind either camera has no image position, so its error (and the mean) is infinite:
    such a result is a failure however well the other points fit.
    """
    px_target, depth_target = project_points(as_population(target)[0], points)
    px_result, depth_result = project_points(as_population(result)[0], points)
    if np.any(depth_target <= 0) or np.any(depth_result <= 0):
        return float("inf")
    error = np.linalg.norm(px_target - px_result, axis=1)
    if not np.all(np.isfinite(error)):
        return float("inf")
    return float(error.mean())


def protocol_points(model: CourtModel) -> dict[str, np.ndarray]:
    """The three geometries of section VII: court nodes, bounding box grid, 16 x 16 floor grid."""
    return {
        "G_c": model.nodes,
        "G_b": bounding_box_grid(model),
        "G_p": floor_grid(model.spec, 16, 16),
    }


def protocol_errors(target: np.ndarray, result: np.ndarray, model: CourtModel) -> dict[str, float]:
    """MRE in px on G_c, G_b and G_p (16 x 16); infinite where a point is behind either camera."""
    return {
        name: mean_reprojection_error(target, result, points)
        for name, points in protocol_points(model).items()
    }
