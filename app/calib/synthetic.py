"""Synthetic data for the paper's protocol (section VII) and for realistic test images and clips.

- Target cameras and the wiggle operator of Table 3 (start cameras at near / medium / far distance).
- Edge images of a known camera (`render_edge_image`, the one court rasteriser) and the five noise
  types of Fig. 8 plus "none".
- Metrics: mean reprojection error (MRE) on the court nodes G_c, the bounding box grid G_b and the
  16 x 16 floor grid G_p.
- Realistic renders: a ray-cast BGR image of a court (wooden floor, plaster walls, red 50 mm lines,
  tin, glass back wall, dark surroundings) and clips with moving player-like blobs.

Noise densities (the paper gives none). Every noise pattern is defined relative to the image, so the
normalised distance map, and therefore the fitness landscape, looks the same at every resolution:
- salt: `SALT_DOTS` = 4000 single white pixels at uniformly random positions (0.19 % of a 1920 x 1080
  image; mean distance to the nearest dot ~11 px there), the same count at every size;
- horizontal / vertical lines: 1 px lines every `LINE_SPACING_FRACTION` = 1/16 of the image height
  (67 px at 1080 rows), random phase; "grid" is both with independent phases;
- grid45: the grid rotated by 45 degrees (8-connected diagonals, same perpendicular spacing).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numba
import numpy as np

from app.calib.camera import (
    DISTORTION_GENES,
    GENE,
    N_GENES,
    as_population,
    court_extrinsics,
    floor_to_pixel,
    project_points,
    undistort_normalized,
)
from app.calib.court import CourtModel, bounding_box_grid, court_model, floor_grid, get_spec
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
    width, height = _check_image_size(image_size)
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


# ----------------------------------------------------------------------------------------------
# Realistic court renders (ray casting through the lens model)

SUPERSAMPLING = 2  # 2 x 2 samples per pixel, box-filtered: anti-aliased edges
UNDISTORT_GRID_STEP_PX = 8  # rays are exact on this grid and bilinear between (error < 0.01 px)
SENSOR_NOISE_SIGMA = 1.5  # grey levels, per channel
TEXTURE_SIZE = 256

# surfaces (codes shared with the kernel)
_FLOOR, _FRONT, _LEFT, _RIGHT, _BACK = 0, 1, 2, 3, 4

# Edges that are painted lines; the rest of the model is wall/floor and wall/wall junctions.
PAINTED_EDGES: tuple[str, ...] = (
    "short_left_outer",
    "short_left_inner",
    "short_right_inner",
    "short_right_outer",
    "half_court",
    "box_left_side",
    "box_left_back",
    "box_right_side",
    "box_right_back",
    "tin",
    "service",
    "front_out",
    "left_out",
    "right_out",
    "back_out",
)

# How far the walls reach above their out lines' upper edges, metres; above is the dark hall.
FRONT_WALL_ABOVE_OUT_M = 0.5
SIDE_WALL_ABOVE_OUT_M = 0.3
BACK_GLASS_ABOVE_OUT_M = 0.25

# Plain-looking colours, BGR 0..255.
_COLOURS = np.array(
    [
        [146.0, 190.0, 224.0],  # 0 maple floor
        [226.0, 230.0, 233.0],  # 1 plaster
        [40.0, 42.0, 188.0],  # 2 red paint
        [150.0, 150.0, 158.0],  # 3 tin board
        [58.0, 60.0, 64.0],  # 4 floor outside the court
        [38.0, 34.0, 30.0],  # 5 hall / ceiling
    ]
)
# per-surface light (front wall lit head-on, side walls a bit darker, one more than the other)
_SURFACE_LIGHT = np.array([1.0, 1.0, 0.93, 0.88, 1.0])
PLANK_WIDTH_M = 0.075
PLANK_LENGTH_M = 2.1


def _check_image_size(image_size: Sequence[int]) -> tuple[int, int]:
    if len(image_size) != 2:
        raise ValueError(f"image_size must be (width, height), got {image_size}")
    width, height = int(image_size[0]), int(image_size[1])
    if width < 2 or height < 2:
        raise ValueError(f"image_size must be at least 2 x 2, got {image_size}")
    return width, height


def _periodic_noise(rng: np.random.Generator, size: int, sigma_texels: float) -> np.ndarray:
    """Smooth, tileable noise (size, size) in [-1, 1]: white noise low-passed in the Fourier domain."""
    white = rng.standard_normal((size, size))
    freq = np.fft.fftfreq(size)
    gain = np.exp(-2.0 * (np.pi * sigma_texels) ** 2 * (freq[:, None] ** 2 + freq[None, :] ** 2))
    smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * gain))
    smooth /= np.abs(smooth).max()
    return smooth.astype(np.float64)


@numba.njit(cache=True, inline="always")
def _texture(tex: np.ndarray, u: float, v: float) -> float:
    """Bilinear, wrapping lookup in a square texture at texel coordinates (u, v)."""
    n = tex.shape[0]
    fu = np.floor(u)
    fv = np.floor(v)
    a = u - fu
    b = v - fv
    i0 = int(fv) % n
    j0 = int(fu) % n
    i1 = (i0 + 1) % n
    j1 = (j0 + 1) % n
    top = tex[i0, j0] * (1.0 - a) + tex[i0, j1] * a
    bottom = tex[i1, j0] * (1.0 - a) + tex[i1, j1] * a
    return top * (1.0 - b) + bottom * b


@numba.njit(cache=True, inline="always")
def _hash01(i: int, j: int, seed: int) -> float:
    h = (i * 374761393 + j * 668265263 + seed * 982451653) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return h / 4294967296.0


@numba.njit(cache=True)
def _shade_samples(
    ray_x: np.ndarray,
    ray_y: np.ndarray,
    ray_ok: np.ndarray,
    grid_origin_px: float,
    grid_step_px: float,
    samples_per_px: int,
    r_world_from_cam: np.ndarray,
    centre: np.ndarray,
    box: np.ndarray,
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    seg_surface: np.ndarray,
    colours: np.ndarray,
    light: np.ndarray,
    tex: np.ndarray,
    seed: int,
    out: np.ndarray,
) -> None:
    """Colour of every supersample (out: (H*s, W*s, 3)) by casting its ray into the court box.

    `ray_x`, `ray_y`, `ray_ok`: undistorted normalised coordinates on a coarse pixel grid (rows v,
    columns u) starting at `grid_origin_px` with `grid_step_px` spacing. `box`: width, length,
    front-wall top z, side-wall top z at the front and at the back, glass top z, tin band top z,
    half line width (z is down, so tops are negative).
    """
    width_m, length_m = box[0], box[1]
    front_top, side_top_front, side_top_back = box[2], box[3], box[4]
    glass_top, tin_top, half_line = box[5], box[6], box[7]
    rows, cols = out.shape[0], out.shape[1]
    grid_rows, grid_cols = ray_x.shape
    inf = np.inf
    cx, cy, cz = centre[0], centre[1], centre[2]
    for i in range(rows):
        v = (i + 0.5) / samples_per_px - 0.5
        gv = (v - grid_origin_px) / grid_step_px
        r0 = min(max(int(np.floor(gv)), 0), grid_rows - 2)
        b = gv - r0
        for j in range(cols):
            u = (j + 0.5) / samples_per_px - 0.5
            gu = (u - grid_origin_px) / grid_step_px
            c0 = min(max(int(np.floor(gu)), 0), grid_cols - 2)
            a = gu - c0
            if not (
                ray_ok[r0, c0]
                and ray_ok[r0, c0 + 1]
                and ray_ok[r0 + 1, c0]
                and ray_ok[r0 + 1, c0 + 1]
            ):
                out[i, j, 0] = 0.0
                out[i, j, 1] = 0.0
                out[i, j, 2] = 0.0
                continue
            xn = (ray_x[r0, c0] * (1 - a) + ray_x[r0, c0 + 1] * a) * (1 - b) + (
                ray_x[r0 + 1, c0] * (1 - a) + ray_x[r0 + 1, c0 + 1] * a
            ) * b
            yn = (ray_y[r0, c0] * (1 - a) + ray_y[r0, c0 + 1] * a) * (1 - b) + (
                ray_y[r0 + 1, c0] * (1 - a) + ray_y[r0 + 1, c0 + 1] * a
            ) * b
            m = r_world_from_cam
            dx = m[0, 0] * xn + m[0, 1] * yn + m[0, 2]
            dy = m[1, 0] * xn + m[1, 1] * yn + m[1, 2]
            dz = m[2, 0] * xn + m[2, 1] * yn + m[2, 2]

            # nearest opaque surface: court floor, hall floor, front wall, side walls
            best_s = inf
            surface = -1
            inside_floor = False
            if dz != 0.0:
                s = -cz / dz
                if s > 0.0:
                    best_s = s
                    surface = _FLOOR
                    x = cx + s * dx
                    y = cy + s * dy
                    inside_floor = 0.0 <= x <= width_m and 0.0 <= y <= length_m
            if dy != 0.0:
                s = -cy / dy
                if 0.0 < s < best_s:
                    x = cx + s * dx
                    z = cz + s * dz
                    if 0.0 <= x <= width_m and front_top <= z <= 0.0:
                        best_s = s
                        surface = _FRONT
            if dx != 0.0:
                for side in range(2):
                    wall_x = 0.0 if side == 0 else width_m
                    s = (wall_x - cx) / dx
                    if 0.0 < s < best_s:
                        y = cy + s * dy
                        z = cz + s * dz
                        top = side_top_front + (side_top_back - side_top_front) * y / length_m
                        if 0.0 <= y <= length_m and top <= z <= 0.0:
                            best_s = s
                            surface = _LEFT if side == 0 else _RIGHT
            px = cx + best_s * dx
            py = cy + best_s * dy
            pz = cz + best_s * dz

            if surface == -1:
                # the hall above the walls: dark, darker looking up
                shade = 1.0 + 0.5 * dz / np.sqrt(dx * dx + dy * dy + dz * dz)
                red = colours[5, 2] * shade
                green = colours[5, 1] * shade
                blue = colours[5, 0] * shade
            elif surface == _FLOOR and not inside_floor:
                n = 1.0 + 0.12 * _texture(tex, px / 0.05, py / 0.05)
                blue = colours[4, 0] * n
                green = colours[4, 1] * n
                red = colours[4, 2] * n
            else:
                painted = False
                for k in range(seg_a.shape[0]):
                    if seg_surface[k] != surface:
                        continue
                    ex = seg_b[k, 0] - seg_a[k, 0]
                    ey = seg_b[k, 1] - seg_a[k, 1]
                    ez = seg_b[k, 2] - seg_a[k, 2]
                    qx = px - seg_a[k, 0]
                    qy = py - seg_a[k, 1]
                    qz = pz - seg_a[k, 2]
                    t = (qx * ex + qy * ey + qz * ez) / (ex * ex + ey * ey + ez * ez)
                    t = min(max(t, 0.0), 1.0)
                    rx = qx - t * ex
                    ry = qy - t * ey
                    rz = qz - t * ez
                    if rx * rx + ry * ry + rz * rz <= half_line * half_line:
                        painted = True
                        break
                lit = light[surface]
                if surface == _FLOOR:
                    # maple strips along the court, staggered butt joints, grain, a broad light pool
                    plank = int(np.floor(px / PLANK_WIDTH_M))
                    offset = _hash01(plank, 0, seed) * PLANK_LENGTH_M
                    piece = int(np.floor((py + offset) / PLANK_LENGTH_M))
                    tone = 1.0 + 0.12 * (_hash01(plank, piece + 1, seed) - 0.5)
                    grain = 0.05 * _texture(tex, px / 0.004, py / 0.06)
                    across = px / PLANK_WIDTH_M - plank
                    along = (py + offset) / PLANK_LENGTH_M - piece
                    seam = 1.0
                    if min(across, 1.0 - across) * PLANK_WIDTH_M < 0.0015:
                        seam = 0.85
                    if min(along, 1.0 - along) * PLANK_LENGTH_M < 0.0015:
                        seam = 0.85
                    pool = 1.0 - 0.06 * ((px - 0.5 * width_m) ** 2 / 10.0 + (py - 5.0) ** 2 / 30.0)
                    n = lit * pool * (tone + grain) * seam
                    base = 2 if painted else 0
                else:
                    # plaster: two octaves of mottling, a little darker towards the top
                    if surface == _FRONT:
                        s1, s2 = px, pz
                    else:
                        s1, s2 = py, pz
                    mottle = 0.02 * _texture(tex, s1 / 0.02, s2 / 0.02) + 0.03 * _texture(
                        tex, s1 / 0.25 + 97.0, s2 / 0.25 + 31.0
                    )
                    n = lit * (1.0 + mottle + 0.012 * pz)
                    base = 1
                    if painted:
                        base = 2
                    elif surface == _FRONT and pz >= tin_top:
                        base = 3
                blue = colours[base, 0] * n
                green = colours[base, 1] * n
                red = colours[base, 2] * n

            # the glass back wall between the camera and what it sees: slight tint, painted out line
            if dy != 0.0:
                s = (length_m - cy) / dy
                if 0.0 < s < best_s:
                    x = cx + s * dx
                    z = cz + s * dz
                    if 0.0 <= x <= width_m and glass_top <= z <= 0.0:
                        blue = 0.9 * blue + 10.0
                        green = 0.9 * green + 8.0
                        red = 0.9 * red + 6.0
                        for k in range(seg_a.shape[0]):
                            if seg_surface[k] == _BACK:
                                ez = seg_b[k, 2] - seg_a[k, 2]
                                ex = seg_b[k, 0] - seg_a[k, 0]
                                t = min(max((x - seg_a[k, 0]) / ex, 0.0), 1.0)
                                if abs(z - (seg_a[k, 2] + t * ez)) <= half_line:
                                    blue = colours[2, 0]
                                    green = colours[2, 1]
                                    red = colours[2, 2]
            out[i, j, 0] = blue
            out[i, j, 1] = green
            out[i, j, 2] = red


def _surface_of_edge(model: CourtModel, a: np.ndarray, b: np.ndarray) -> int:
    width, length = model.spec.width_m, model.spec.length_m
    for surface, axis, value in (
        (_FLOOR, 2, 0.0),
        (_FRONT, 1, 0.0),
        (_LEFT, 0, 0.0),
        (_RIGHT, 0, width),
        (_BACK, 1, length),
    ):
        if abs(a[axis] - value) < 1e-9 and abs(b[axis] - value) < 1e-9:
            return surface
    raise ValueError("painted edge does not lie on a court surface")


def _painted_segments(model: CourtModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    seg_a, seg_b, surfaces = [], [], []
    for name, (ia, ib) in zip(model.edge_names, model.edges, strict=True):
        if name in PAINTED_EDGES:
            a, b = model.nodes[ia], model.nodes[ib]
            seg_a.append(a)
            seg_b.append(b)
            surfaces.append(_surface_of_edge(model, a, b))
    return np.array(seg_a), np.array(seg_b), np.array(surfaces, dtype=np.int64)


def _court_box(model: CourtModel) -> np.ndarray:
    half = model.spec.line_width_m / 2.0
    front_out_z = model.node("front_out_left")[2]
    back_out_z = model.node("back_out_left")[2]
    return np.array(
        [
            model.spec.width_m,
            model.spec.length_m,
            front_out_z - half - FRONT_WALL_ABOVE_OUT_M,
            front_out_z - half - SIDE_WALL_ABOVE_OUT_M,
            back_out_z - half - SIDE_WALL_ABOVE_OUT_M,
            back_out_z - half - BACK_GLASS_ABOVE_OUT_M,
            model.node("tin_left")[2] + half,  # the tin board reaches the tin line's lower edge
            half,
        ]
    )


def _render_clean(
    genome: np.ndarray, image_size: tuple[int, int], spec: str, rng: np.random.Generator
) -> np.ndarray:
    """Noise-free render, float32 BGR (H, W, 3) in 0..255."""
    width, height = image_size
    g = as_population(genome)[0]
    model = court_model(get_spec(spec))
    step = float(UNDISTORT_GRID_STEP_PX)
    us = -0.5 + step * np.arange(int(np.ceil(width / step)) + 2)
    vs = -0.5 + step * np.arange(int(np.ceil(height / step)) + 2)
    grid_u, grid_v = np.meshgrid(us, vs)
    with np.errstate(all="ignore"):
        ray_x, ray_y, ray_ok = undistort_normalized(
            (grid_u - g[2]) / g[0], (grid_v - g[3]) / g[1], g[DISTORTION_GENES]
        )
    r, t = court_extrinsics(g)
    r_world_from_cam = np.ascontiguousarray(r[0].T)
    centre = -r_world_from_cam @ t[0]
    seg_a, seg_b, seg_surface = _painted_segments(model)
    texture = _periodic_noise(rng, TEXTURE_SIZE, 2.0)
    seed = int(rng.integers(1 << 30))
    samples = np.empty((height * SUPERSAMPLING, width * SUPERSAMPLING, 3), np.float32)
    _shade_samples(
        np.ascontiguousarray(ray_x),
        np.ascontiguousarray(ray_y),
        np.ascontiguousarray(ray_ok),
        -0.5,
        step,
        SUPERSAMPLING,
        r_world_from_cam,
        centre,
        _court_box(model),
        seg_a,
        seg_b,
        seg_surface,
        _COLOURS,
        _SURFACE_LIGHT,
        texture,
        seed,
        samples,
    )
    return cv2.resize(samples, (width, height), interpolation=cv2.INTER_AREA)


def _add_sensor_noise(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    noisy = image + rng.normal(0.0, SENSOR_NOISE_SIGMA, image.shape).astype(np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def render_court_image(
    genome: np.ndarray,
    image_size: tuple[int, int],
    spec: str = "wsf",
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """A realistic BGR uint8 (H, W, 3) image of an empty court seen by `genome`.

    Every pixel's ray (2 x 2 supersamples) is cast through the lens model into the court: a maple
    floor, off-white plaster walls, the tin board, red 50 mm lines centred on the model's line centres,
    a glass back wall with its out line, a dark hall outside; plus mild sensor noise. `rng` seeds the
    textures and the noise; None means seed 0, so renders are reproducible by default.
    """
    size = _check_image_size(image_size)
    rng = np.random.default_rng(0 if rng is None else rng)
    return _add_sensor_noise(_render_clean(genome, size, spec, rng), rng)


# ----------------------------------------------------------------------------------------------
# Clips with moving players

PLAYER_HEIGHT_M = 1.8
_SHIRT_COLOURS = np.array(
    [[120, 40, 20], [30, 30, 160], [40, 110, 30], [25, 25, 25], [20, 140, 200], [110, 30, 110]],
    dtype=np.float64,
)
_SKIN_COLOURS = np.array([[140, 170, 215], [80, 105, 150], [105, 135, 185]], dtype=np.float64)


def player_paths(
    n_frames: int, n_players: int, rng: np.random.Generator, spec: str = "wsf"
) -> np.ndarray:
    """Floor positions (n_frames, n_players, 2) in metres: smooth loops around the T over the clip.

    Each player runs a figure-of-eight (Lissajous) loop through the T area, crossing the short line,
    the half-court line and the service boxes; players start half a loop apart, so they rarely
    overlap and every floor pixel they cover is free for most of the clip.
    """
    if n_frames < 1 or n_players < 0:
        raise ValueError("n_frames must be >= 1 and n_players >= 0")
    court = get_spec(spec)
    model = court_model(court)
    t_x, t_y = model.node("T")[:2]
    phase = np.arange(n_frames)[:, None] / n_frames
    player_phase = (np.arange(n_players) / max(n_players, 1))[None, :] + rng.uniform(0, 1)
    amp_x = rng.uniform(1.6, 2.2, n_players)[None, :]
    amp_y = rng.uniform(1.6, 2.4, n_players)[None, :]
    twist = rng.uniform(0, 2 * np.pi, n_players)[None, :]
    angle = 2 * np.pi * (phase + player_phase)
    x = t_x + amp_x * np.sin(angle)
    y = t_y + 0.4 + amp_y * np.sin(2 * angle + twist)
    margin = 0.4
    x = np.clip(x, margin, court.width_m - margin)
    y = np.clip(y, margin, court.length_m - margin)
    return np.stack([x, y], axis=2)


def _draw_player(
    frame: np.ndarray,
    genome: np.ndarray,
    floor_xy: np.ndarray,
    shirt: np.ndarray,
    skin: np.ndarray,
) -> None:
    """Shadow, legs, torso and head of one player, drawn in place on a float32 BGR frame."""
    foot = floor_to_pixel(genome, floor_xy)[0]
    head_top = floor_to_pixel(genome, floor_xy, plane_z_m=-PLAYER_HEIGHT_M)[0]
    if not (np.all(np.isfinite(foot)) and np.all(np.isfinite(head_top))):
        return
    up = head_top - foot
    height_px = float(np.hypot(*up))
    if height_px < 4:
        return
    up_unit = up / height_px
    angle_deg = float(np.degrees(np.arctan2(up_unit[0], -up_unit[1])))

    # a soft shadow: an ellipse on the floor around the feet, projected, blurred, multiplied in
    around = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = floor_xy + np.stack([0.4 * np.cos(around), 0.25 * np.sin(around) + 0.1], axis=1)
    ring_px = floor_to_pixel(genome, ring)
    if np.all(np.isfinite(ring_px)):
        pad = int(height_px * 0.2) + 4
        lo = np.floor(ring_px.min(axis=0)).astype(int) - pad
        hi = np.ceil(ring_px.max(axis=0)).astype(int) + pad
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, [frame.shape[1], frame.shape[0]])
        if np.all(hi > lo):
            mask = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.float32)
            cv2.fillPoly(
                mask, [np.round((ring_px - lo) * 16).astype(np.int32)], 1.0, cv2.LINE_AA, 4
            )
            blur = max(1, int(height_px * 0.04)) * 2 + 1
            mask = cv2.GaussianBlur(mask, (blur, blur), 0)
            roi = frame[lo[1] : hi[1], lo[0] : hi[0]]
            roi *= 1.0 - 0.45 * mask[:, :, None]

    def at(fraction: float) -> tuple[int, int]:
        p = foot + up * fraction
        return int(round(p[0] * 16)), int(round(p[1] * 16))

    def axes(half_width: float, half_height: float) -> tuple[int, int]:
        return max(1, int(round(half_width * height_px * 16))), max(
            1, int(round(half_height * height_px * 16))
        )

    legs = tuple(float(c) for c in 0.55 * skin)
    torso = tuple(float(c) for c in shirt)
    face = tuple(float(c) for c in skin)
    cv2.ellipse(frame, at(0.25), axes(0.1, 0.25), angle_deg, 0, 360, legs, -1, cv2.LINE_AA, 4)
    cv2.ellipse(frame, at(0.62), axes(0.14, 0.2), angle_deg, 0, 360, torso, -1, cv2.LINE_AA, 4)
    radius = max(1, int(round(0.065 * height_px * 16)))
    cv2.circle(frame, at(0.925), radius, face, -1, cv2.LINE_AA, 4)


def render_clip_frames(
    genome: np.ndarray,
    image_size: tuple[int, int],
    n_frames: int,
    rng: np.random.Generator | int | None,
    n_players: int = 2,
    spec: str = "wsf",
) -> list[np.ndarray]:
    """Frames (BGR uint8) of the court of `render_court_image` with players moving over the floor.

    The court is rendered once (consuming `rng` first, exactly as `render_court_image(genome,
    image_size, spec, rng)` would), then `player_paths(n_frames, n_players, rng, spec)` draws the
    paths, then the players' colours are drawn. Players are composited far to near, each sized by
    projecting a 1.8 m person standing at their floor position. Pixels no player (or shadow) touches
    are identical to the court render in every frame.
    """
    size = _check_image_size(image_size)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    rng = np.random.default_rng(rng)
    court = render_court_image(genome, size, spec, rng)
    paths = player_paths(n_frames, n_players, rng, spec)
    shirts = _SHIRT_COLOURS[rng.choice(len(_SHIRT_COLOURS), n_players, replace=n_players > 6)]
    skins = _SKIN_COLOURS[rng.integers(len(_SKIN_COLOURS), size=n_players)]
    g = as_population(genome)[0]
    court_float = court.astype(np.float32)
    frames = []
    for positions in paths:
        frame = court_float.copy()
        # painter's order: the player furthest from the camera first
        feet = np.column_stack([positions, np.zeros(n_players)])
        _, depth = project_points(g, feet)
        for p in np.argsort(-depth):
            _draw_player(frame, g, positions[p], shirts[p], skins[p])
        frames.append(np.clip(np.rint(frame), 0, 255).astype(np.uint8))
    return frames


def write_video(frames: Sequence[np.ndarray], path: str | Path, fps: float = 25.0) -> None:
    """Write BGR frames of one size to a video file (MPEG-4 part 2, 'mp4v', in .mp4 or .avi)."""
    if len(frames) == 0:
        raise ValueError("no frames to write")
    height, width = frames[0].shape[:2]
    fourcc = cv2.VideoWriter.fourcc(*"mp4v")
    writer = cv2.VideoWriter(str(path), fourcc, float(fps), (width, height))
    if not writer.isOpened():
        raise RuntimeError(f"cannot open a video writer for {path}")
    try:
        for frame in frames:
            if frame.shape[:2] != (height, width) or frame.ndim != 3:
                raise ValueError("all frames must be BGR images of the same size")
            writer.write(np.ascontiguousarray(frame, dtype=np.uint8))
    finally:
        writer.release()
