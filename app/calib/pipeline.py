"""Image -> calibrated camera: the one function the worker and the CLI call.

Stages (each reported through `progress(stage, fraction, info)`):
1. "edges": the image's edge map (`edges.extract_edges`, Canny as in the paper; or the image
   itself if it already is a white-on-black edge image); edges where players moved
   (`moving_mask`) are removed.
2. "optimising": a start camera, given or found by `find_start` (a grid of ~10 000 typical squash
   camera placements scored in one compiled call, the best few polished), then the paper's GA
   (`ga.run_ga`, the chosen bundle, seeded) from it.
3. "refining": a least-squares fit of the projected court lines to the edges (a robust, truncated
   chamfer distance with bilinear, hence sub-pixel, lookups), from the GA's camera, the same with
   a simpler lens, and the start; the lowest final cost wins.
Painted lines are fitted by their two borders (what Canny marks), junctions of surfaces by
themselves (`fitting_samples`). Then quality figures; below the thresholds `CourtNotFound` is
raised instead of returning a confident wrong camera.

Why the refinement: the GA maximises the paper's fitness, whose optimum is not the true camera
(it rewards long projected lines near any edge, and a lens that folds can lay lines on clutter);
on synthetic renders the GA alone ends 1-14 cm off on the floor, the refined camera 0.2-0.4 cm
(see the tests and bench.real for real images).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numba
import numpy as np
from scipy import optimize

from app.calib import camera, edges, render
from app.calib.camera import project_point_njit
from app.calib.court import CourtModel, LineSamples, court_model, sample_edges, spacing_for_image
from app.calib.fitness import bilinear_njit, distance_map, index_limit, population_fitness
from app.calib.ga import DEFAULT_BUNDLE, bundle_fitness_map, get_bundle, run_ga

ProgressFn = Callable[[str, float, dict[str, Any]], None]

DEFAULT_MAX_GENERATIONS = 3000


class CourtNotFound(Exception):
    """The image does not show a court the camera could be fitted to; `quality` says why and
    `genome` is the rejected best camera (None if there was nothing to fit), for diagnosis."""

    def __init__(
        self,
        message: str,
        quality: dict[str, float] | None = None,
        genome: np.ndarray | None = None,
    ) -> None:
        super().__init__(message)
        self.quality = dict(quality or {})
        self.genome = None if genome is None else np.asarray(genome, dtype=np.float64).copy()


@dataclass(frozen=True)
class CalibrationResult:
    genome: np.ndarray
    image_size: tuple[int, int]
    fitness: float
    generations: int
    seed: int
    bundle: str
    spec: str
    stop_reason: str
    start_genome: np.ndarray  # where the GA started (given, or found by the start search)
    ga_genome: np.ndarray  # the GA's best camera, before refinement
    ga_fitness: float
    refined_from: str  # which camera the refinement started from: "ga", "ga_simple_lens", "start"
    timings_s: dict[str, float]
    quality: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        return {
            "opencv": camera.to_opencv(self.genome, self.image_size),
            "genome": [float(v) for v in self.genome],
            "start_genome": [float(v) for v in self.start_genome],
            "ga_genome": [float(v) for v in self.ga_genome],
            "ga_fitness": float(self.ga_fitness),
            "refined_from": self.refined_from,
            "fitness": float(self.fitness),
            "generations": int(self.generations),
            "seed": int(self.seed),
            "bundle": self.bundle,
            "spec": self.spec,
            "stop_reason": self.stop_reason,
            "timings_s": {k: round(float(v), 6) for k, v in self.timings_s.items()},
            "quality": {k: float(v) for k, v in self.quality.items()},
        }


# ---------------------------------------------------------------------------------------------
# edges


def image_size_of(image: np.ndarray) -> tuple[int, int]:
    """(width, height) of a grey (H, W) or colour (H, W, C) image."""
    shape = np.shape(image)
    if len(shape) not in (2, 3) or (len(shape) == 3 and shape[2] not in (1, 3, 4)):
        raise ValueError(f"image must be (H, W), (H, W, 3) or (H, W, 4), got shape {shape}")
    return int(shape[1]), int(shape[0])


def prepare_edge_image(image: np.ndarray, moving_mask: np.ndarray | None = None) -> np.ndarray:
    """uint8 (H, W) edge image: the image itself if it is one, else its extracted edges.

    Edges within a few pixels of `moving_mask` (nonzero where players moved) are removed: they are
    players or their ghosts, not court.
    """
    width, height = image_size_of(image)
    if edges.is_edge_image(image):
        grey = edges.to_grey(image)
        edge_image = np.where(grey > 127, 255, 0).astype(np.uint8)
    else:
        edge_image = edges.extract_edges(image)
    if moving_mask is not None:
        moving = moving_mask_of(moving_mask, (width, height))
        edge_image[moving] = 0
    return edge_image


# Players' outlines blur over a few pixels; edges that close to a moving pixel are not trusted.
MOVING_MARGIN_PX = 3


def moving_mask_of(moving_mask: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """bool (H, W): pixels where something moved, grown by MOVING_MARGIN_PX."""
    mask = np.asarray(moving_mask)
    width, height = image_size
    if mask.ndim == 3 and mask.shape[2] == 1:
        mask = mask[:, :, 0]
    if mask.shape != (height, width):
        raise ValueError(
            f"moving_mask must have the image's shape ({height}, {width}), got {mask.shape}"
        )
    grown = cv2.dilate(
        (mask != 0).astype(np.uint8),
        cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * MOVING_MARGIN_PX + 1,) * 2),
    )
    return grown > 0


# ---------------------------------------------------------------------------------------------
# start cameras


def look_at_genomes(
    centres_m: np.ndarray,
    targets_m: np.ndarray,
    roll_rad: np.ndarray,
    focal_px: np.ndarray,
    image_size: tuple[int, int],
) -> np.ndarray:
    """Genomes (N, 15) of pinhole cameras at court points `centres_m` (N, 3) looking at
    `targets_m` (N, 3), rolled by `roll_rad` (N,), principal point at the image centre."""
    forward = targets_m - centres_m
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    down = np.array([0.0, 0.0, 1.0])  # court z points down, as the image's v does
    right = np.cross(down, forward)
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    up_in_image = np.cross(forward, right)  # the camera's y axis (image down)
    cos_r, sin_r = np.cos(roll_rad)[:, None], np.sin(roll_rad)[:, None]
    x_axis = cos_r * right + sin_r * up_in_image
    y_axis = -sin_r * right + cos_r * up_in_image
    rotations = np.stack([x_axis, y_axis, forward], axis=1)
    width, height = image_size
    genomes = np.zeros((len(centres_m), camera.N_GENES))
    genomes[:, 0] = genomes[:, 1] = focal_px
    genomes[:, 2], genomes[:, 3] = (width - 1) / 2.0, (height - 1) / 2.0
    # the genome's pose is in the paper frame: the inverse of camera.court_extrinsics
    r_paper = rotations @ camera.PAPER_FROM_COURT_R.T
    genomes[:, 7:10] = [camera.angles_from_rotation(r) for r in r_paper]
    t_court = -np.einsum("nij,nj->ni", rotations, centres_m)
    genomes[:, 4:7] = t_court + rotations @ camera.PAPER_ORIGIN_COURT_M
    return genomes


def _focal_to_fit(
    centres_m: np.ndarray, targets_m: np.ndarray, nodes_m: np.ndarray, image_size: tuple[int, int]
) -> np.ndarray:
    """Focal length (N,) at which the farthest of `nodes_m` (in front of each unrolled camera) just
    touches the image border, the principal point being the image centre."""
    width, height = image_size
    n = len(centres_m)
    unit = look_at_genomes(centres_m, targets_m, np.zeros(n), np.ones(n), (1, 1))
    unit[:, 2:4] = 0.0
    pixels, depth = camera.project_points(unit, nodes_m)
    in_front = depth > 0.1
    span_u = np.maximum(np.where(in_front, np.abs(pixels[..., 0]), 0.0).max(axis=1), 1e-3)
    span_v = np.maximum(np.where(in_front, np.abs(pixels[..., 1]), 0.0).max(axis=1), 1e-3)
    return np.minimum(0.5 * width / span_u, 0.5 * height / span_v)


@dataclass(frozen=True)
class StartGrid:
    """Typical squash camera placements: behind (or on) the back wall, centred or a bit off,
    from a low tripod to a high gallery; aimed along the court; court filling the frame more or
    less. All in the court frame (metres; z down, so heights are negative z)."""

    behind_back_wall_m: tuple[float, ...] = (0.3, 2.0, 4.5, 8.0, 13.0)
    height_m: tuple[float, ...] = (1.5, 2.5, 3.7, 5.2, 7.0)
    camera_x_m: tuple[float, ...] = (2.0, 3.2, 4.4)
    aim_x_m: tuple[float, ...] = (2.2, 3.2, 4.2)
    aim_y_m: tuple[float, ...] = (1.0, 3.0, 5.0)
    roll_deg: tuple[float, ...] = (-4.0, 0.0, 4.0)
    fill: tuple[float, ...] = (0.7, 0.85, 1.0, 1.2, 1.45)


def candidate_starts(
    image_size: tuple[int, int], model: CourtModel, grid: StartGrid | None = None
) -> np.ndarray:
    """Start cameras (N, 15) over the grid's placements, focal set by the fill factor."""
    grid = grid or StartGrid()
    length = model.spec.length_m
    mesh = np.meshgrid(
        grid.behind_back_wall_m,
        grid.height_m,
        grid.camera_x_m,
        grid.aim_x_m,
        grid.aim_y_m,
        indexing="ij",
    )
    behind, height, cam_x, aim_x, aim_y = (m.ravel() for m in mesh)
    scale_x = model.spec.width_m / 6.4  # the grid is written for a 6.4 m singles court
    centres = np.column_stack([cam_x * scale_x, length + behind, -height])
    targets = np.column_stack([aim_x * scale_x, aim_y, np.zeros_like(aim_y)])
    # Scale by the front part of the court (front wall to the service boxes): a camera on the back
    # wall does not see the back wall's own corners, however wide its lens.
    front_part = model.nodes[model.nodes[:, 1] <= 0.75 * length]
    focal = _focal_to_fit(centres, targets, front_part, image_size)
    # every placement with every roll and fill factor
    n_pose, n_roll, n_fill = len(centres), len(grid.roll_deg), len(grid.fill)
    pose = np.repeat(np.arange(n_pose), n_roll * n_fill)
    roll = np.tile(np.repeat(np.deg2rad(grid.roll_deg), n_fill), n_pose)
    fill = np.tile(np.asarray(grid.fill, dtype=np.float64), n_pose * n_roll)
    return look_at_genomes(centres[pose], targets[pose], roll, focal[pose] * fill, image_size)


def default_start_genome(image_size: tuple[int, int], spec: str = "wsf") -> np.ndarray:
    """One typical camera: centred 2 m behind the back wall, 3.7 m up, whole court in view."""
    model = court_model(spec)
    grid = StartGrid(
        behind_back_wall_m=(2.0,),
        height_m=(3.7,),
        camera_x_m=(3.2,),
        aim_x_m=(3.2,),
        aim_y_m=(3.0,),
        roll_deg=(0.0,),
        fill=(0.9,),
    )
    return candidate_starts(image_size, model, grid)[0]


# ---------------------------------------------------------------------------------------------
# refinement and quality: robust chamfer distance of the projected line samples


def fitting_samples(
    model: CourtModel, spacing_m: float, line_borders: bool = True
) -> tuple[LineSamples, np.ndarray]:
    """Line samples to fit edges with: painted lines by their two borders, creases as they are.

    Canny marks both borders of a painted line (50 mm, several pixels wide near the camera), not
    its centre line, which the court model holds; fitting the centre line to them pulls it onto
    one border. So each painted line is sampled twice, offset by half a line width to either side
    within its own surface (floor or wall), and each border finds its own edge. Wall/floor and
    wall/wall junctions are brightness steps with one edge on the junction itself.
    Each border is its own run of the returned samples (consecutive samples join up); the
    second value (R,) gives the court edge each run belongs to. With `line_borders` False every
    edge is sampled on its centre line (for edge images drawn that way, e.g. by
    `render.rasterize_court`).
    """
    base = sample_edges(model, spacing_m)
    half_width = model.spec.line_width_m / 2.0
    chunks: list[np.ndarray] = []
    owners: list[int] = []
    offsets = [0]
    for e, (a, b) in enumerate(model.edges):
        points = base.points[base.offsets[e] : base.offsets[e + 1]]
        surfaces = _surfaces_of(model, model.nodes[a], model.nodes[b])
        if line_borders and len(surfaces) == 1:
            direction = model.nodes[b] - model.nodes[a]
            side = np.cross(direction, surfaces[0])
            side *= half_width / np.linalg.norm(side)
            borders = [points + side, points - side]
        else:
            borders = [points]
        for border in borders:
            chunks.append(border)
            owners.append(e)
            offsets.append(offsets[-1] + len(border))
    samples = LineSamples(np.concatenate(chunks), np.asarray(offsets, dtype=np.int64))
    return samples, np.asarray(owners, dtype=np.int64)


def _surfaces_of(model: CourtModel, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
    """Normals of the court surfaces (floor, front/back wall, side walls) holding segment a-b:
    one for a painted line, two for a junction of surfaces."""
    spec = model.spec
    normals = []
    if a[2] == 0.0 and b[2] == 0.0:
        normals.append(np.array([0.0, 0.0, 1.0]))
    if a[1] == b[1] and a[1] in (0.0, spec.length_m):
        normals.append(np.array([0.0, 1.0, 0.0]))
    if a[0] == b[0] and a[0] in (0.0, spec.width_m):
        normals.append(np.array([1.0, 0.0, 0.0]))
    if not normals:
        raise ValueError("court edge lies on no court surface")
    return normals


@numba.njit(cache=True, inline="always")
def _sample_distance(
    r: np.ndarray,
    t: np.ndarray,
    g: np.ndarray,
    centre: np.ndarray,
    max_tan2: float,
    x: float,
    y: float,
    z: float,
    dmap: np.ndarray,
    ignore: np.ndarray,
) -> float:
    """Bilinear distance at one court point's pixel, or -1 if the point does not count."""
    h, w = dmap.shape
    u, v, depth = project_point_njit(r, t, g, x, y, z)
    # squared tangent of the angle off the optical axis: |X - C|^2 = depth^2 (1 + tan^2)
    off_axis2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
    if not (depth > MIN_DEPTH_M and off_axis2 <= depth * depth * (1.0 + max_tan2)):
        return -1.0
    if not (0.0 <= u <= w - 1.0 and 0.0 <= v <= h - 1.0):
        return -1.0
    if ignore.shape[0] > 0 and ignore[int(v + 0.5), int(u + 0.5)] != 0:
        return -1.0
    # the last row/column reads as its neighbour plus 1 - 2e-13 of the step: same lookup as the GA
    return bilinear_njit(dmap, min(u, index_limit(w)), min(v, index_limit(h)))


@numba.njit(cache=True)
def _sample_distances_njit(
    r: np.ndarray,
    t: np.ndarray,
    pop: np.ndarray,
    centres: np.ndarray,
    max_tan2: np.ndarray,
    points: np.ndarray,
    dmap: np.ndarray,
    ignore: np.ndarray,
    tau: float,
    distance: np.ndarray,
    cost: np.ndarray,
) -> None:
    """Per camera of `pop`: the robust chamfer cost into `cost` (N,) and, unless `distance` is
    empty (shape (0, 0): ranking many cameras needs only the cost), each sample's distance into
    `distance` (N, M), +inf where the sample does not count."""
    store = distance.shape[0] > 0
    tau2 = tau * tau
    for i in range(pop.shape[0]):
        total = 0.0
        for j in range(points.shape[0]):
            d = _sample_distance(
                r[i],
                t[i],
                pop[i],
                centres[i],
                max_tan2[i],
                points[j, 0],
                points[j, 1],
                points[j, 2],
                dmap,
                ignore,
            )
            # rho(d)^2 / tau^2 = d^2 / (d^2 + tau^2); samples that do not count give 1
            total += d * d / (d * d + tau2) if d >= 0.0 else 1.0
            if store:
                distance[i, j] = d if d >= 0.0 else np.inf
        cost[i] = total / points.shape[0]


# points nearer the camera plane than this are treated as not visible
MIN_DEPTH_M = 0.05
_NO_IGNORE = np.zeros((0, 0), dtype=np.uint8)


def _distances_and_costs(
    genomes: np.ndarray,
    points: np.ndarray,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    truncation_px: float,
    keep_distances: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Distances (N, M) (empty unless `keep_distances`) and robust costs (N,), one compiled call."""
    pop = np.ascontiguousarray(camera.as_population(genomes))
    r, t = camera.court_extrinsics(pop)
    distance = np.empty((len(pop), len(points)) if keep_distances else (0, 0))
    cost = np.empty(len(pop))
    _sample_distances_njit(
        r,
        t,
        pop,
        -np.einsum("nji,nj->ni", r, t),
        camera.lens_fold_radii(pop) ** 2,
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(dmap, dtype=np.float32),
        _NO_IGNORE if ignore is None else ignore.view(np.uint8),
        float(truncation_px),
        distance,
        cost,
    )
    return distance, cost


def sample_distances(
    genomes: np.ndarray, points: np.ndarray, dmap: np.ndarray, ignore: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear distance at each projected point and whether it counts: (M,) for one camera
    (15,), (N, M) for a population (N, 15), in one compiled call.

    A point counts when it is in front of the camera, inside the lens's monotonic field (see
    `camera.lens_fold_radius`: beyond it the polynomial maps far-off points back into the image
    as ghosts), inside the image and not on `ignore` (bool (H, W), moving pixels); uncounted
    points have distance +inf.
    """
    distance, _ = _distances_and_costs(genomes, points, dmap, ignore, 1.0, keep_distances=True)
    counts = np.isfinite(distance)
    if np.ndim(genomes) == 1:
        return distance[0], counts[0]
    return distance, counts


def _directions(columns: list[tuple[dict[str, float], float]]) -> np.ndarray:
    """(15, K) matrix: column k moves the named genes by the given amounts per unit step."""
    out = np.zeros((camera.N_GENES, len(columns)))
    for k, (genes, unit) in enumerate(columns):
        for name, weight in genes.items():
            out[camera.GENE[name], k] = weight * unit
    return out


_POSE = [
    ({"t_x": 1.0}, 0.02),
    ({"t_y": 1.0}, 0.02),
    ({"t_z": 1.0}, 0.05),
    ({"alpha": 1.0}, 2e-3),
    ({"beta": 1.0}, 2e-3),
    ({"gamma": 1.0}, 2e-3),
]
# What each refinement may move, one unit per column (px, m, rad, coefficient).
# Wide-basin polish of a start: a square-pixel pinhole (one focal length) and the pose only; far
# from the answer, distortion and principal point would bend the court onto the wrong edges.
PINHOLE_DIRECTIONS = _directions([({"f_u": 1.0, "f_v": 1.0}, 10.0), *_POSE])
# Closer in: the same plus k1, without which a wide lens cannot sit on its lines at all.
PINHOLE_K1_DIRECTIONS = _directions([({"f_u": 1.0, "f_v": 1.0}, 10.0), *_POSE, ({"k1": 1.0}, 0.01)])
# Final fit: everything but p1, p2, k3, which edges of a few court lines do not pin down.
FULL_DIRECTIONS = _directions(
    [
        ({"f_u": 1.0}, 10.0),
        ({"f_v": 1.0}, 10.0),
        ({"c_u": 1.0}, 5.0),
        ({"c_v": 1.0}, 5.0),
        *_POSE,
        ({"k1": 1.0}, 0.01),
        ({"k2": 1.0}, 0.01),
    ]
)


def robust_residuals(
    genome: np.ndarray,
    points: np.ndarray,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    truncation_px: float,
) -> np.ndarray:
    """Per line sample tau d / sqrt(d^2 + tau^2), (M,) for one camera or (N, M) for a
    population: d the bilinear distance to the nearest edge, tau `truncation_px`; samples that
    do not count (outside, behind, ignored) give tau."""
    tau = float(truncation_px)
    d, _ = sample_distances(genome, points, dmap, ignore)
    d = np.minimum(d, 1e6)
    return tau * d / np.sqrt(d * d + tau * tau)


def chamfer_costs(
    genomes: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    truncation_px: float,
) -> np.ndarray:
    """Mean squared robust residual over all line samples, divided by tau^2, for each camera
    of a population (N, 15) -> (N,): 0 when every sample is on an edge, 1 when none is near
    one. Lower is better; comparable between cameras (the least-squares objective of
    `refine_camera` up to a constant factor)."""
    _, cost = _distances_and_costs(
        genomes, samples.points, dmap, ignore, truncation_px, keep_distances=False
    )
    return cost


def chamfer_cost(
    genome: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    truncation_px: float,
) -> float:
    """`chamfer_costs` of one camera (15,)."""
    return float(chamfer_costs(genome, samples, dmap, ignore, truncation_px)[0])


# Radii (normalised, undistorted) searched for a fold of the lens polynomial: 4 is 76 degrees off
# axis, wider than any lens this model describes.
def lens_folds_in_image(genome: np.ndarray, image_size: tuple[int, int]) -> bool:
    """True if the lens turns back before the middle of the image's farther border: such a lens
    maps two directions to one pixel well inside the picture, and a fit can hide court lines in
    the fold. (Wide real lenses described by k1 alone may fold in the very corners; that is
    allowed.)"""
    g = camera.as_population(genome)[0]
    fold = camera.lens_fold_radius(g)
    if not np.isfinite(fold):
        return False
    width, height = image_size
    border_u = max(abs(0.0 - g[2]), abs(width - 1.0 - g[2])) / g[0]
    border_v = max(abs(0.0 - g[3]), abs(height - 1.0 - g[3])) / g[1]
    k1, k2, k3 = g[camera.GENE["k1"]], g[camera.GENE["k2"]], g[camera.GENE["k3"]]
    f2 = fold * fold
    r_fold_distorted = fold * (1.0 + f2 * (k1 + f2 * (k2 + f2 * k3)))
    return bool(r_fold_distorted < max(border_u, border_v))


def court_extent_fraction(
    genome: np.ndarray, samples: LineSamples, image_size: tuple[int, int]
) -> float:
    """Area of the bounding box of the court's visible line samples over the image area."""
    width, height = image_size
    pixels, depth = camera.project_points(genome, samples.points)
    u, v = pixels[:, 0], pixels[:, 1]
    seen = (depth > MIN_DEPTH_M) & (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    if seen.sum() < 2:
        return 0.0
    return float(np.ptp(u[seen]) * np.ptp(v[seen])) / float(width * height)


# A court seen from where squash is filmed spans a good part of the picture; a camera that
# shrinks it into a corner can always park it on some edges.
MIN_COURT_EXTENT = 0.05


def plausible(genome: np.ndarray, samples: LineSamples, image_size: tuple[int, int]) -> bool:
    """A camera worth comparing: its lens does not fold inside the image and the court spans at
    least MIN_COURT_EXTENT of it."""
    if lens_folds_in_image(genome, image_size):
        return False
    return court_extent_fraction(genome, samples, image_size) >= MIN_COURT_EXTENT


FD_RELATIVE_STEP = 1e-3  # forward-difference step per direction unit (see the directions above)


def refine_camera(
    genome: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None = None,
    truncation_px: float = 4.0,
    directions: np.ndarray = FULL_DIRECTIONS,
    max_evaluations: int = 200,
) -> np.ndarray:
    """Least-squares fit of the camera to the edges, from `genome`, along `directions` (15, K).

    Residual per line sample: tau d / sqrt(d^2 + tau^2), d the bilinear (so sub-pixel) distance
    to the nearest edge and tau `truncation_px`: quadratic near an edge, saturating at tau for
    outliers (edges of other things, missing lines); samples outside the image or on ignored
    pixels count tau.
    """
    start = np.asarray(genome, dtype=np.float64).copy()
    points = np.ascontiguousarray(samples.points, dtype=np.float64)
    tau = float(truncation_px)
    n = directions.shape[1]

    def residuals(x: np.ndarray) -> np.ndarray:
        return robust_residuals(start + directions @ x, points, dmap, ignore, tau)

    def jacobian(x: np.ndarray) -> np.ndarray:
        # forward differences (MINPACK's step rule), all n perturbed cameras in one compiled call
        steps = FD_RELATIVE_STEP * np.where(x >= 0.0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        shifted = x[None, :] + np.diag(steps)
        cameras = start[None, :] + np.vstack([x[None, :], shifted]) @ directions.T
        values = robust_residuals(cameras, points, dmap, ignore, tau)
        return ((values[1:] - values[0]) / (shifted - x[None, :]).diagonal()[:, None]).T

    # Levenberg-Marquardt (MINPACK): a dozen unknowns and ~1500 residuals, where it is several
    # times faster than the trust-region solvers; lens folds are rejected by the caller instead
    # of bounded here.
    fit = optimize.least_squares(
        # the budget counts Jacobians as n evaluations each, as MINPACK does for its own differences
        residuals,
        np.zeros(n),
        jac=jacobian,
        method="lm",
        max_nfev=max(2, max_evaluations // (n + 1)),
    )
    return start + directions @ fit.x


def fit_quality(
    genome: np.ndarray,
    samples: LineSamples,
    owners: np.ndarray,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    inlier_px: float,
) -> dict[str, float]:
    """How well the fitted court sits on the image's edges (`samples`, `owners` from
    `fitting_samples`).

    - inlier_fraction: counted line samples within `inlier_px` of an edge;
    - chance_inlier_fraction: the same for a random pixel (edge density), so that busy images
      whose edges are everywhere do not pass for a match;
    - inlier_excess: (inlier - chance) / (1 - chance), 0 for a chance fit, 1 for a perfect one;
    - inlier_rms_px: RMS distance of the inliers;
    - court_in_image_fraction: line samples in front of the camera and inside the image;
    - supported_edges: court edges with >= 3 counted samples of which >= 60% are inliers.
    """
    distance, counts = sample_distances(genome, samples.points, dmap, None)
    in_image = counts.copy()
    if ignore is not None:
        _, counts = sample_distances(genome, samples.points, dmap, ignore)
    visible = int(counts.sum())
    inlier = counts & (distance <= inlier_px)
    valid_pixels = dmap[~ignore] if ignore is not None else dmap.ravel()
    chance = float((valid_pixels <= inlier_px).mean()) if valid_pixels.size else 1.0
    fraction = float(inlier.sum()) / visible if visible else 0.0
    excess = (fraction - chance) / (1.0 - chance) if chance < 1.0 else 0.0
    run_of_sample = np.repeat(np.arange(len(owners)), np.diff(samples.offsets))
    edge_of_sample = owners[run_of_sample]
    n_edges = int(owners.max()) + 1
    counted_per_edge = np.bincount(edge_of_sample[counts], minlength=n_edges)
    inliers_per_edge = np.bincount(edge_of_sample[inlier], minlength=n_edges)
    supported = int(np.sum((counted_per_edge >= 3) & (inliers_per_edge >= 0.6 * counted_per_edge)))
    return {
        "inlier_fraction": fraction,
        "chance_inlier_fraction": chance,
        "inlier_excess": float(excess),
        "inlier_rms_px": float(np.sqrt(np.mean(distance[inlier] ** 2))) if inlier.any() else 0.0,
        "court_in_image_fraction": float(in_image.mean()),
        "supported_edges": float(supported),
        "inlier_px": float(inlier_px),
    }


# A court is "found" when the fit beats chance clearly, several court lines are on edges, and a
# good part of the court is in the picture.
MIN_INLIER_EXCESS = 0.6
MIN_SUPPORTED_EDGES = 12
MIN_COURT_IN_IMAGE = 0.25


def court_not_found_reason(quality: dict[str, float]) -> str | None:
    """Why the fit is not a court (one phrase), or None if it passes the thresholds."""
    if quality.get("court_extent_fraction", 1.0) < MIN_COURT_EXTENT:
        return (
            f"the best camera squeezes the court into {quality['court_extent_fraction']:.1%} of "
            f"the image (need {MIN_COURT_EXTENT:.0%})"
        )
    if quality["court_in_image_fraction"] < MIN_COURT_IN_IMAGE:
        return (
            f"only {quality['court_in_image_fraction']:.0%} of the court's lines would be in the "
            f"image (need {MIN_COURT_IN_IMAGE:.0%})"
        )
    if quality["inlier_excess"] < MIN_INLIER_EXCESS:
        return (
            f"the best camera puts {quality['inlier_fraction']:.0%} of the court's lines on edges, "
            f"against {quality['chance_inlier_fraction']:.0%} by chance"
        )
    if quality["supported_edges"] < MIN_SUPPORTED_EDGES:
        return (
            f"only {quality['supported_edges']:.0f} of the court's lines match edges "
            f"(need {MIN_SUPPORTED_EDGES})"
        )
    return None


# ---------------------------------------------------------------------------------------------
# the pipeline

# Start search: the best placements of the grid are polished by a wide-basin chamfer fit (tau a few
# percent of the image width) before the best of them seeds the GA.
START_POLISHED_PER_RANKING = 6
START_SEARCH_SPACING_FACTOR = 2.0
POLISH_TRUNCATION_FRACTION = 0.03
# truncation (px at 1920 px wide) of the robust chamfer residual in the refinement passes
REFINE_TRUNCATIONS_AT_1920 = (60.0, 12.0, 3.0)
# inlier tolerance for the quality figures, at 1920 px wide (scaled with the width)
INLIER_PX_AT_1920 = 3.0


def _validated_image(image: Any) -> np.ndarray:
    arr = np.asarray(image)
    if arr.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {arr.dtype}")
    width, height = image_size_of(arr)
    if width < 64 or height < 48:
        raise ValueError(f"image is too small to calibrate: {width}x{height} px")
    return arr


def find_start(
    fmap: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    model: CourtModel,
) -> tuple[np.ndarray, dict[str, float]]:
    """Best start camera over a grid of typical placements.

    Every placement is scored twice in one compiled call each: by the GA's fitness and by the
    wide-truncation chamfer cost (the two rank differently: the fitness rewards long projected
    lines on edges, the cost rewards every line being near one). The best few of each ranking
    are polished by a wide-basin chamfer fit of a square-pixel pinhole, and the polished camera
    with the lowest cost at the final refinement's truncation (among plausible ones) is
    returned.
    """
    height, width = fmap.shape
    size = (width, height)
    candidates = candidate_starts(size, model)
    tau = POLISH_TRUNCATION_FRACTION * width
    by_fitness = np.argsort(-population_fitness(candidates, samples, fmap))
    by_cost = np.argsort(chamfer_costs(candidates, samples, dmap, ignore, tau))
    chosen = list(
        dict.fromkeys(
            [*by_fitness[:START_POLISHED_PER_RANKING], *by_cost[:START_POLISHED_PER_RANKING]]
        )
    )
    # wide first, then down to the refinement's truncations: compared at the final truncation,
    # candidates must have settled there (a wide truncation alone favours courts shrunk onto busy
    # parts of the image, which are near many edges without being on any)
    scale = width / 1920.0
    fine_px = max(REFINE_TRUNCATIONS_AT_1920[-1] * scale, 1.5)
    polished = []
    for i in chosen:
        genome = refine_camera(candidates[i], samples, dmap, ignore, tau, PINHOLE_DIRECTIONS)
        for step_px in REFINE_TRUNCATIONS_AT_1920[1:]:
            genome = refine_camera(
                genome, samples, dmap, ignore, max(step_px * scale, 1.5), PINHOLE_K1_DIRECTIONS
            )
        polished.append(genome)
    costs = chamfer_costs(np.array(polished), samples, dmap, ignore, fine_px)
    for k, genome in enumerate(polished):
        if not plausible(genome, samples, size):
            costs[k] = np.inf
    best = int(np.argmin(costs))
    info = {
        "grid_candidates": float(len(candidates)),
        "start_cost": float(costs[best]),
        "start_from_cost_ranking": float(
            chosen[best] not in by_fitness[:START_POLISHED_PER_RANKING]
        ),
    }
    return polished[best], info


def simple_lens(genome: np.ndarray) -> np.ndarray:
    """The camera with only k1 of its distortion (k2, p1, p2, k3 = 0).

    The GA mutates every distortion term; over the few court lines in view, high-order terms
    can trade against the focal length and k1 and fit as well inside the court while bending the
    rest of the picture. Refinement also tries this simpler lens, and it wins when it fits better.
    """
    g = np.asarray(genome, dtype=np.float64).copy()
    for name in ("k2", "p1", "p2", "k3"):
        g[camera.GENE[name]] = 0.0
    return g


def refine_fully(
    genome: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    image_size: tuple[int, int],
) -> np.ndarray:
    """`refine_camera` with a shrinking truncation (REFINE_TRUNCATIONS_AT_1920, scaled with the
    image width): wide first, to pull lines that are many pixels off onto their edges, tight at
    the end, so that only the edges on the lines decide the sub-pixel position.

    A wide pass can also pull lines with no edge of their own onto other things' edges (sparse
    edge maps, clutter), so each pass is a proposal, kept only if it is `plausible` and lowers
    the chamfer cost at the finest truncation, the quantity the last pass minimises (a court
    shrunk onto a few edge pixels costs almost nothing, so the cost alone would take it).
    """
    scale = image_size[0] / 1920.0
    fine_px = max(REFINE_TRUNCATIONS_AT_1920[-1] * scale, 1.5)
    best = np.asarray(genome, dtype=np.float64)
    best_cost = chamfer_cost(best, samples, dmap, ignore, fine_px)
    for tau in REFINE_TRUNCATIONS_AT_1920:
        proposal = refine_camera(best, samples, dmap, ignore, max(tau * scale, 1.5))
        cost = chamfer_cost(proposal, samples, dmap, ignore, fine_px)
        if cost < best_cost and plausible(proposal, samples, image_size):
            best, best_cost = proposal, cost
    return best


def refine_best(
    cameras: dict[str, np.ndarray],
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    image_size: tuple[int, int],
) -> tuple[np.ndarray, str]:
    """Refine each named camera (`refine_fully`) and return the best and its name.

    The GA maximises its own fitness, whose optimum can sit off the court (a lens that folds long
    projected lines onto clutter scores high); its start is refined too, and the lowest final
    chamfer cost among plausible cameras wins.
    """
    fine_px = max(REFINE_TRUNCATIONS_AT_1920[-1] * image_size[0] / 1920.0, 1.5)
    best: tuple[float, np.ndarray, str] | None = None
    for name, genome in cameras.items():
        refined = refine_fully(genome, samples, dmap, ignore, image_size)
        cost = chamfer_cost(refined, samples, dmap, ignore, fine_px)
        if not plausible(refined, samples, image_size):
            cost = np.inf
        if best is None or cost < best[0]:
            best = (cost, refined, name)
    assert best is not None
    return best[1], best[2]


def calibrate(
    image: np.ndarray,
    *,
    start_genome: np.ndarray | None = None,
    bundle: str = DEFAULT_BUNDLE.name,
    seed: int = 0,
    max_generations: int = DEFAULT_MAX_GENERATIONS,
    time_budget_s: float | None = None,
    spec: str = "wsf",
    moving_mask: np.ndarray | None = None,
    progress: ProgressFn | None = None,
) -> CalibrationResult:
    """Fit the 15-parameter camera to one image (BGR/BGRA/grey photo, or an edge image).

    `time_budget_s` bounds the whole call's optimisation: the GA gets what the start search left
    of it. Raises ValueError for bad input and CourtNotFound when the best fit is not a court.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}

    def report(stage: str, fraction: float, info: dict[str, Any]) -> None:
        if progress is not None:
            progress(stage, float(min(max(fraction, 0.0), 1.0)), info)

    arr = _validated_image(image)
    bundle_config = get_bundle(bundle)
    model = court_model(spec)
    width, height = image_size_of(arr)
    if max_generations < 1:
        raise ValueError(f"max_generations must be at least 1, got {max_generations}")
    if time_budget_s is not None and not time_budget_s > 0:
        raise ValueError(f"time_budget_s must be positive, got {time_budget_s}")
    start_given = None
    if start_genome is not None:
        start_given = camera.as_population(start_genome)[0].copy()
        if not np.all(np.isfinite(start_given)):
            raise ValueError("start camera must be finite numbers")

    report("edges", 0.0, {})
    given_edges = edges.is_edge_image(arr)
    edge_image = prepare_edge_image(arr, moving_mask)
    ignore = moving_mask_of(moving_mask, (width, height)) if moving_mask is not None else None
    edge_fraction = float((edge_image > 0).mean())
    if edge_fraction == 0.0:
        raise CourtNotFound("court not found: the image has no edges", {"edge_pixel_fraction": 0.0})
    fmap = bundle_fitness_map(edge_image, bundle_config)
    dmap = distance_map(edge_image)
    # an edge image is taken to show line centres; Canny edges of a photo show line borders
    samples, owners = fitting_samples(model, spacing_for_image(width), not given_edges)
    timings["edges"] = time.perf_counter() - t_start
    report("edges", 1.0, {"edge_pixel_fraction": edge_fraction})

    t0 = time.perf_counter()
    report("optimising", 0.0, {"generation": 0})
    start_info: dict[str, float] = {}
    if start_given is None:
        # the search compares thousands of cameras and polishes a dozen: samples twice as
        # sparse as the final fit's are plenty for that and halve its cost
        search_samples, _ = fitting_samples(
            model, START_SEARCH_SPACING_FACTOR * spacing_for_image(width), not given_edges
        )
        start, start_info = find_start(fmap, search_samples, dmap, ignore, model)
    else:
        start = start_given
    timings["start_search"] = time.perf_counter() - t0

    ga_budget = None
    if time_budget_s is not None:
        ga_budget = max(time_budget_s - (time.perf_counter() - t_start), 0.1 * time_budget_s)

    def ga_progress(generation: int, best_fitness: float) -> None:
        fraction = generation / max_generations
        if ga_budget is not None:
            fraction = max(fraction, (time.perf_counter() - t_ga) / ga_budget)
        report("optimising", fraction, {"generation": generation, "best_fitness": best_fitness})

    t_ga = time.perf_counter()
    ga = run_ga(
        fmap,
        samples,
        start,
        bundle=bundle_config,
        seed=seed,
        max_generations=max_generations,
        time_budget_s=ga_budget,
        progress=ga_progress,
    )
    timings["optimise"] = time.perf_counter() - t_ga
    report("optimising", 1.0, {"generation": ga.generations, "best_fitness": ga.fitness})

    t0 = time.perf_counter()
    report("refining", 0.0, {})
    ga_genome = np.asarray(ga.genome, dtype=np.float64).copy()
    genome, refined_from = refine_best(
        {"ga": ga_genome, "ga_simple_lens": simple_lens(ga_genome), "start": start},
        samples,
        dmap,
        ignore,
        (width, height),
    )
    timings["refine"] = time.perf_counter() - t0
    report("refining", 1.0, {})

    inlier_px = INLIER_PX_AT_1920 * max(width, 640) / 1920.0
    quality = fit_quality(genome, samples, owners, dmap, ignore, inlier_px)
    quality["edge_pixel_fraction"] = edge_fraction
    quality["court_extent_fraction"] = court_extent_fraction(genome, samples, (width, height))
    quality.update(start_info)
    timings["total"] = time.perf_counter() - t_start
    reason = court_not_found_reason(quality)
    if reason is not None:
        raise CourtNotFound(f"court not found: {reason}", quality, genome)
    fitness = float(population_fitness(genome, samples, fmap)[0])
    return CalibrationResult(
        genome=genome,
        image_size=(width, height),
        fitness=fitness,
        generations=int(ga.generations),
        seed=int(seed),
        bundle=bundle_config.name,
        spec=model.spec.name,
        stop_reason=str(ga.stop_reason),
        start_genome=start,
        ga_genome=ga_genome,
        ga_fitness=float(ga.fitness),
        refined_from=refined_from,
        timings_s=timings,
        quality=quality,
    )


def draw_overlay(image: np.ndarray, genome: np.ndarray, spec: str = "wsf") -> np.ndarray:
    """BGR copy of `image` with the court of `genome` drawn on it (green, 2 px)."""
    arr = np.asarray(image)
    if arr.ndim == 2:
        bgr = cv2.cvtColor(arr, cv2.COLOR_GRAY2BGR)
    elif arr.ndim == 3 and arr.shape[2] == 4:
        bgr = cv2.cvtColor(arr, cv2.COLOR_BGRA2BGR)
    elif arr.ndim == 3 and arr.shape[2] == 1:
        bgr = cv2.cvtColor(arr[:, :, 0], cv2.COLOR_GRAY2BGR)
    else:
        bgr = arr
    thickness = max(1, int(round(bgr.shape[1] / 900)))
    return render.draw_court(bgr, genome, court_model(spec), (0, 255, 0), thickness)
