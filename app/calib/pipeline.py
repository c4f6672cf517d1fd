"""Image -> calibrated camera: the one function the worker and the CLI call.

Stages (each reported through `progress(stage, fraction, info)`):
1. "edges": the image's edge map (`edges.extract_edges`, or the image itself if it already is a
   white-on-black edge image); edges where players moved (`moving_mask`) are removed.
2. "optimising": a start camera (given, or the best of a grid of typical squash camera placements,
   scored in one `population_fitness` call), then the paper's GA (`ga.run_ga`) from it.
3. "refining": a local least-squares fit of the projected line samples to the edges (a robust
   chamfer distance with bilinear, hence sub-pixel, lookups).
Then quality figures; below the thresholds `CourtNotFound` is raised instead of returning a
confident wrong camera.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy import ndimage, optimize

from app.calib import camera, edges, render
from app.calib.court import CourtModel, LineSamples, court_model, sample_edges, spacing_for_image
from app.calib.fitness import distance_map, population_fitness
from app.calib.ga import DEFAULT_BUNDLE, bundle_fitness_map, get_bundle, run_ga

ProgressFn = Callable[[str, float, dict[str, Any]], None]

DEFAULT_MAX_GENERATIONS = 3000


class CourtNotFound(Exception):
    """The image does not show a court the camera could be fitted to; `quality` says why."""

    def __init__(self, message: str, quality: dict[str, float] | None = None) -> None:
        super().__init__(message)
        self.quality = dict(quality or {})


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
    start_genome: np.ndarray
    timings_s: dict[str, float]
    quality: dict[str, float]
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "opencv": camera.to_opencv(self.genome, self.image_size),
            "genome": [float(v) for v in self.genome],
            "start_genome": [float(v) for v in self.start_genome],
            "fitness": float(self.fitness),
            "generations": int(self.generations),
            "seed": int(self.seed),
            "bundle": self.bundle,
            "spec": self.spec,
            "stop_reason": self.stop_reason,
            "timings_s": {k: round(float(v), 6) for k, v in self.timings_s.items()},
            "quality": {k: float(v) for k, v in self.quality.items()},
            **self.extra,
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
    c_u, c_v = (width - 1) / 2.0, (height - 1) / 2.0
    genomes = np.empty((len(centres_m), camera.N_GENES))
    for i, (r, c, f) in enumerate(zip(rotations, centres_m, focal_px, strict=True)):
        rvec, _ = cv2.Rodrigues(r)
        genomes[i] = camera.from_opencv(
            {
                "K": [[f, 0.0, c_u], [0.0, f, c_v], [0.0, 0.0, 1.0]],
                "dist": [0.0] * 5,
                "rvec": rvec.ravel(),
                "tvec": -r @ c,
            }
        )
    return genomes


def _focal_to_fill(
    centres_m: np.ndarray,
    targets_m: np.ndarray,
    nodes_m: np.ndarray,
    fill: np.ndarray,
    image_size: tuple[int, int],
) -> np.ndarray:
    """Focal length (N,) at which the court nodes in front of each camera span `fill` (N,) of the
    image around its centre (1 = the farthest node just touches the image border)."""
    width, height = image_size
    unit = look_at_genomes(
        centres_m, targets_m, np.zeros(len(centres_m)), np.ones(len(centres_m)), (1, 1)
    )
    unit[:, 2:4] = 0.0
    pixels, depth = camera.project_points(unit, nodes_m)
    in_front = depth > 0.1
    span_u = np.where(in_front, np.abs(pixels[..., 0]), 0.0).max(axis=1)
    span_v = np.where(in_front, np.abs(pixels[..., 1]), 0.0).max(axis=1)
    span_u = np.maximum(span_u, 1e-3)
    span_v = np.maximum(span_v, 1e-3)
    return fill * np.minimum(0.5 * width / span_u, 0.5 * height / span_v)


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
        grid.roll_deg,
        grid.fill,
        indexing="ij",
    )
    behind, height, cam_x, aim_x, aim_y, roll, fill = (m.ravel() for m in mesh)
    scale_x = model.spec.width_m / 6.4  # the grid is written for a 6.4 m singles court
    centres = np.column_stack([cam_x * scale_x, length + behind, -height])
    targets = np.column_stack([aim_x * scale_x, aim_y, np.zeros_like(aim_y)])
    focal = _focal_to_fill(centres, targets, model.nodes, fill, image_size)
    return look_at_genomes(centres, targets, np.deg2rad(roll), focal, image_size)


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


def line_gap_px(image_size: tuple[int, int]) -> int:
    """Widest painted line (px) whose two Canny edges are merged into one band: 50 mm seen from a
    few metres fills ~1% of the image width."""
    return max(3, int(round(0.008 * image_size[0])))


def band_distance_map(edge_image: np.ndarray, gap_px: int) -> np.ndarray:
    """Distance (px, float32) to the nearest edge after closing gaps up to `gap_px`.

    Canny marks both borders of a painted line; the court model is the line's centre line, which
    lies between them. Closing merges the two borders into a solid band, so a sample on the line
    centre is at distance 0 instead of half a line width.
    """
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (gap_px + 1, gap_px + 1))
    closed = cv2.morphologyEx(edge_image, cv2.MORPH_CLOSE, kernel)
    return distance_map(closed)


def sample_distances(
    genome: np.ndarray, points: np.ndarray, dmap: np.ndarray, ignore: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear distance (M,) at each projected point and whether it counts (M,) bool.

    A point counts when it is in front of the camera, inside the image and not on `ignore`
    (moving pixels); uncounted points have distance +inf.
    """
    height, width = dmap.shape
    pixels, depth = camera.project_points(genome, points)
    u, v = pixels[:, 0], pixels[:, 1]
    counts = (depth > 0.05) & (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    counts &= np.isfinite(u) & np.isfinite(v)
    if ignore is not None and counts.any():
        iu = np.rint(u[counts]).astype(np.int64)
        iv = np.rint(v[counts]).astype(np.int64)
        idx = np.flatnonzero(counts)
        counts[idx[ignore[iv, iu]]] = False
    distance = np.full(len(points), np.inf)
    if counts.any():
        distance[counts] = ndimage.map_coordinates(
            dmap, [v[counts], u[counts]], order=1, mode="nearest"
        )
    return distance, counts


# Genes the refinement moves, and the step that is "one unit" for each (px, m, rad, coefficient):
# p1, p2, k3 stay as the GA left them: edges of a few court lines do not pin them down.
REFINE_GENES = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11])
REFINE_UNITS = np.array([10.0, 10.0, 5.0, 5.0, 0.02, 0.02, 0.05, 2e-3, 2e-3, 2e-3, 0.01, 0.01])


def refine_camera(
    genome: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None = None,
    truncation_px: float = 4.0,
    max_evaluations: int = 1500,
) -> np.ndarray:
    """Least-squares fit of the camera to the edges, from `genome`.

    Residual per line sample: tau d / sqrt(d^2 + tau^2), d the bilinear distance to the nearest
    edge and tau `truncation_px`: quadratic near an edge, saturating at tau for outliers (edges
    of other things, missing lines); samples outside the image or on moving pixels count tau.
    """
    start = np.asarray(genome, dtype=np.float64).copy()
    points = samples.points
    tau = float(truncation_px)

    def residuals(x: np.ndarray) -> np.ndarray:
        g = start.copy()
        g[REFINE_GENES] += x * REFINE_UNITS
        d, _ = sample_distances(g, points, dmap, ignore)
        d = np.minimum(d, 1e6)
        return tau * d / np.sqrt(d * d + tau * tau)

    fit = optimize.least_squares(
        residuals,
        np.zeros(len(REFINE_GENES)),
        method="trf",
        diff_step=1e-3,
        max_nfev=max_evaluations,
        x_scale=1.0,
    )
    refined = start.copy()
    refined[REFINE_GENES] += fit.x * REFINE_UNITS
    return refined


def fit_quality(
    genome: np.ndarray,
    samples: LineSamples,
    dmap: np.ndarray,
    ignore: np.ndarray | None,
    inlier_px: float,
) -> dict[str, float]:
    """How well the fitted court sits on the image's edges.

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
    supported = 0
    for e in range(len(samples.offsets) - 1):
        lo, hi = samples.offsets[e], samples.offsets[e + 1]
        n = int(counts[lo:hi].sum())
        if n >= 3 and inlier[lo:hi].sum() >= 0.6 * n:
            supported += 1
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
MIN_INLIER_EXCESS = 0.5
MIN_SUPPORTED_EDGES = 6
MIN_COURT_IN_IMAGE = 0.25


def court_not_found_reason(quality: dict[str, float]) -> str | None:
    """Why the fit is not a court (one phrase), or None if it passes the thresholds."""
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
START_CANDIDATES_POLISHED = 6
POLISH_TRUNCATION_FRACTION = 0.03
REFINE_TRUNCATION_PX = 3.0
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
    """Best start camera: grid of placements scored in one population_fitness call, the top few
    polished by a wide-basin chamfer fit, the fittest of those returned."""
    height, width = fmap.shape
    candidates = candidate_starts((width, height), model)
    scores = population_fitness(candidates, samples, fmap)
    top = np.argsort(-scores)[:START_CANDIDATES_POLISHED]
    tau = POLISH_TRUNCATION_FRACTION * width
    polished = np.array(
        [refine_camera(candidates[i], samples, dmap, ignore, tau, max_evaluations=400) for i in top]
    )
    polished_scores = population_fitness(polished, samples, fmap)
    best = int(np.argmax(polished_scores))
    info = {
        "grid_candidates": float(len(candidates)),
        "grid_best_fitness": float(scores[top[0]]),
        "polished_best_fitness": float(polished_scores[best]),
    }
    return polished[best], info


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
    refine: bool = True,
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
    edge_image = prepare_edge_image(arr, moving_mask)
    ignore = moving_mask_of(moving_mask, (width, height)) if moving_mask is not None else None
    edge_fraction = float((edge_image > 0).mean())
    if edge_fraction == 0.0:
        raise CourtNotFound("court not found: the image has no edges", {"edge_pixel_fraction": 0.0})
    fmap = bundle_fitness_map(edge_image, bundle_config)
    band_dmap = band_distance_map(edge_image, line_gap_px((width, height)))
    samples = sample_edges(model, spacing_for_image(width))
    timings["edges"] = time.perf_counter() - t_start
    report("edges", 1.0, {"edge_pixel_fraction": edge_fraction})

    t0 = time.perf_counter()
    report("optimising", 0.0, {"generation": 0})
    start_info: dict[str, float] = {}
    if start_given is None:
        start, start_info = find_start(fmap, samples, band_dmap, ignore, model)
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
    genome = np.asarray(ga.genome, dtype=np.float64).copy()
    if refine:
        genome = refine_camera(genome, samples, band_dmap, ignore, REFINE_TRUNCATION_PX)
    timings["refine"] = time.perf_counter() - t0
    report("refining", 1.0, {})

    inlier_px = INLIER_PX_AT_1920 * max(width, 640) / 1920.0
    quality = fit_quality(genome, samples, band_dmap, ignore, inlier_px)
    quality["edge_pixel_fraction"] = edge_fraction
    quality.update(start_info)
    timings["total"] = time.perf_counter() - t_start
    reason = court_not_found_reason(quality)
    if reason is not None:
        raise CourtNotFound(f"court not found: {reason}", quality)
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
