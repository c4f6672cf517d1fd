"""Verification: how well the court a camera projects lies on the picture's line evidence.

Every camera projects the whole court model (floor and walls); each court sample scores whether
evidence of the right kind (ridges for painted lines) lies within a tolerance and runs the same
way, against the chance of that on this picture here (`chance_maps`): per camera, the supported
and visible length of every court edge and a log-likelihood ratio (`edge_support`). A cheaper
version ranks hundreds of thousands of hypotheses (`coarse_scores`); `distinct_best` keeps the
best of those that differ. The search ranks its hypotheses with it, the refinement its
candidates, the verdict judges the final camera on its figures.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np

from app.calib import camera, parallel
from app.calib.camera import (
    MIN_SAMPLE_DEPTH_M,
    extrinsics_njit,
    project_point_njit,
    seen_pixel_njit,
)
from app.calib.court import CourtModel, sample_edges
from app.calib.lines import EvidenceMaps

# Verification: sample spacing (m), distance tolerance (px at 1920 px wide) for ranking raw
# hypotheses (a homography from four lines lands a few pixels off) and, after polishing, for
# choosing among them; direction tolerance.
VERIFY_SPACING_M = 0.25
RANK_TOLERANCE_PX_AT_1920 = 19.2
VERIFY_TOLERANCE_PX_AT_1920 = 5.0
VERIFY_MAX_ANGLE_RAD = np.deg2rad(20.0)
# The most line length (share of the image diagonal) one verification sample may stand for.
MAX_SAMPLE_SHARE_OF_DIAGONAL = 0.05
# Probability that a court line in view (not on ignored pixels) shows as evidence within the
# tolerance, by what the line is: painted floor lines and side-wall out lines nearly always show;
# the service line and front-wall out line mostly (the out line is often at the picture's top
# edge); the tin is a board, often covered by adverts; junctions of glass walls or in shadow
# often do not show; the back wall's line and corners are seen through or on glass, close to
# the camera, and rarely show. Priors from how courts look, not fitted to any image.
P_HIT_BY_EDGE = {
    "floor_painted": 0.7,
    "side_out": 0.6,
    "service": 0.6,
    "front_out": 0.5,
    "tin": 0.35,
    "floor_junction": 0.45,
    "front_corner": 0.35,
    "back_wall": 0.25,
}


def edge_hit_probability(model: CourtModel) -> np.ndarray:
    """P_HIT_BY_EDGE for each edge of the model (E,)."""
    out = np.empty(len(model.edges))
    for e, name in enumerate(model.edge_names):
        if name.startswith("back_") and name not in ("back_floor_left", "back_floor_right"):
            kind = "back_wall"
        elif name in ("left_out", "right_out"):
            kind = "side_out"
        elif name in ("service", "front_out", "tin"):
            kind = name
        elif name.startswith("front_") and "corner" in name:
            kind = "front_corner"
        elif model.painted()[e]:
            kind = "floor_painted"
        else:
            kind = "floor_junction"
        out[e] = P_HIT_BY_EDGE[kind]
    return out


# Distinct hypotheses: reference floor points must differ by this share of the image width.
DISTINCT_SHARE_OF_WIDTH = 0.02


@dataclass(frozen=True)
class VerifySamples:
    """Court samples for verification: points (M, 3), unit directions of their edges (M, 3),
    edge index (M,), painted (M,) bool, spacing (m)."""

    points: np.ndarray
    directions: np.ndarray
    edge: np.ndarray
    painted: np.ndarray
    p_hit: np.ndarray  # (M,) edge_hit_probability of each sample's edge
    spacing_m: float
    n_edges: int


def verify_samples(model: CourtModel, spacing_m: float = VERIFY_SPACING_M) -> VerifySamples:
    samples = sample_edges(model, spacing_m)
    counts = np.diff(samples.offsets)
    edge = np.repeat(np.arange(len(model.edges)), counts)
    vec = model.nodes[model.edges[:, 1]] - model.nodes[model.edges[:, 0]]
    unit = vec / np.linalg.norm(vec, axis=1, keepdims=True)
    return VerifySamples(
        points=np.ascontiguousarray(samples.points),
        directions=np.ascontiguousarray(unit[edge]),
        edge=edge.astype(np.int64),
        painted=model.painted()[edge],
        p_hit=edge_hit_probability(model)[edge],
        spacing_m=spacing_m,
        n_edges=len(model.edges),
    )


@dataclass(frozen=True)
class ChanceMaps:
    """How likely a line placed at random would find evidence running its way, per place.

    values (B, h, w) float32 on a grid `scale` times coarser than the image: for normal
    directions in bin b (of B over [0, pi)), the chance that a point is within `tolerance_px`
    of evidence with such a normal: the local density of that evidence (box filter over
    CHANCE_WINDOW_SHARE of the width) times the width of the tolerance band.
    """

    values: np.ndarray
    scale: int
    tolerance_px: float


CHANCE_BINS = 6
CHANCE_SCALE = 2  # the chance maps' grid is this many times coarser than the image
CHANCE_WINDOW_SHARE = 0.12
CHANCE_MIN = 0.02
CHANCE_MAX = 0.95


def chance_maps(maps: EvidenceMaps, tolerance_px: float) -> ChanceMaps:
    h, w = maps.shape
    scale = CHANCE_SCALE
    angle = np.arctan2(maps.normals[:, 1], maps.normals[:, 0]) % np.pi
    bins = np.minimum((angle * (CHANCE_BINS / np.pi)).astype(np.int64), CHANCE_BINS - 1)
    xs = np.clip(np.rint(maps.points[:, 0]).astype(np.int64), 0, w - 1) // scale
    ys = np.clip(np.rint(maps.points[:, 1]).astype(np.int64), 0, h - 1) // scale
    hs, ws = (h + scale - 1) // scale, (w + scale - 1) // scale
    counts = np.zeros((CHANCE_BINS, hs, ws), np.float32)
    np.add.at(counts, (bins, ys, xs), 1.0)
    window = max(3, int(round(CHANCE_WINDOW_SHARE * w / scale)) | 1)
    values = np.empty_like(counts)
    # evidence pixels per image pixel (a coarse cell holds scale^2 pixels), times the band width
    band = (2.0 * tolerance_px + 1.0) / float(scale * scale)
    for b in range(CHANCE_BINS):
        values[b] = cv2.boxFilter(counts[b], -1, (window, window)) * band
    np.clip(values, CHANCE_MIN, CHANCE_MAX, out=values)
    return ChanceMaps(values, scale, float(tolerance_px))


@numba.njit(cache=True, inline="always")
def _sample_evidence(
    iu: int,
    iv: int,
    du: float,
    dv: float,
    step_px: float,
    painted: bool,
    p_hit: float,
    dist_ridge: np.ndarray,
    near_ridge: np.ndarray,
    dist_any: np.ndarray,
    near_any: np.ndarray,
    normals: np.ndarray,
    tolerance: float,
    max_sin: float,
    chance: np.ndarray,
    chance_scale: int,
) -> tuple[float, float, int]:
    """(support in [0, 1], log-likelihood ratio per tolerance length, index of the nearest
    evidence pixel of the right kind or -1) of one court sample seen
    at pixel (iu, iv) with its line running (du, dv) over step_px: support when evidence of the
    right kind (ridges for painted lines) lies within `tolerance` and runs the same way, against
    the chance of such support here for a line with this normal (direction bins interpolated)."""
    if painted:
        d = dist_ridge[iv, iu]
        k = near_ridge[iv, iu]
    else:
        d = dist_any[iv, iu]
        k = near_any[iv, iu]
    support = 0.0
    if (
        k >= 0
        and d <= tolerance
        and abs(normals[k, 0] * du + normals[k, 1] * dv) <= max_sin * step_px
    ):
        support = 1.0 - d * d / (tolerance * tolerance)
    n_bins = chance.shape[0]
    angle = np.arctan2(du, -dv)
    if angle < 0.0:
        angle += np.pi
    pos = angle * n_bins / np.pi - 0.5
    b0 = int(np.floor(pos))
    frac = pos - b0
    b1 = (b0 + 1) % n_bins
    b0 = b0 % n_bins
    cu = min(iu // chance_scale, chance.shape[2] - 1)
    cv = min(iv // chance_scale, chance.shape[1] - 1)
    c = (1.0 - frac) * chance[b0, cv, cu] + frac * chance[b1, cv, cu]
    llr = support * np.log(p_hit / c) + (1.0 - support) * np.log((1.0 - p_hit) / (1.0 - c))
    return support, llr, k


@numba.njit(cache=True, nogil=True)
def _verify_njit(
    pop: np.ndarray,
    points: np.ndarray,
    directions: np.ndarray,
    edge: np.ndarray,
    painted: np.ndarray,
    p_hits: np.ndarray,
    n_edges: int,
    step_m: float,
    spacing_m: float,
    fold_tan2: np.ndarray,
    dist_ridge: np.ndarray,
    near_ridge: np.ndarray,
    dist_any: np.ndarray,
    near_any: np.ndarray,
    normals: np.ndarray,
    evidence_points: np.ndarray,
    ignore: np.ndarray,
    tolerance: float,
    max_sin: float,
    chance: np.ndarray,
    chance_scale: int,
    supported: np.ndarray,
    visible: np.ndarray,
    llr: np.ndarray,
) -> None:
    """Per camera and court edge: supported and visible projected length (px); per camera the
    log-likelihood ratio of the evidence under "the court is here" against chance.

    One mark in the picture is evidence for one court line: a sample supported by evidence in a
    tolerance-sized cell of the picture that another edge of the same camera already took adds
    nothing to the ratio (its supported length still counts). Otherwise a wrong camera that
    squeezes several court lines onto the same few marks is paid for each of them."""
    h, w = ignore.shape
    max_sample_px = MAX_SAMPLE_SHARE_OF_DIAGONAL * np.sqrt(h * h + w * w)
    cell_px = max(tolerance, 1.0)
    # owner[cell] = row * n_edges + edge of the last camera row that took the cell; rows are
    # distinct, so the grid needs no clearing between cameras
    owner = np.full((int(h / cell_px) + 1, int(w / cell_px) + 1), -1, np.int64)
    r = np.empty((3, 3))
    t = np.empty(3)
    for i in range(pop.shape[0]):
        g = pop[i]
        extrinsics_njit(g, r, t)
        for e in range(n_edges):
            supported[i, e] = 0.0
            visible[i, e] = 0.0
        total = 0.0
        for j in range(points.shape[0]):
            x, y, z = points[j, 0], points[j, 1], points[j, 2]
            u, v, iu, iv, seen = seen_pixel_njit(r, t, g, x, y, z, fold_tan2[i], ignore)
            if not seen:
                continue
            u2, v2, depth2 = project_point_njit(
                r,
                t,
                g,
                x + step_m * directions[j, 0],
                y + step_m * directions[j, 1],
                z + step_m * directions[j, 2],
            )
            du = u2 - u
            dv = v2 - v
            step_px = np.sqrt(du * du + dv * dv)
            if depth2 <= MIN_SAMPLE_DEPTH_M or step_px == 0.0:
                continue
            # one lookup stands for this much line: a camera with a line grazing its lens must
            # not win on a few lookups that stand for thousands of pixels
            length_px = min(step_px * (spacing_m / step_m), max_sample_px)
            e = edge[j]
            visible[i, e] += length_px
            support, sample_llr, k = _sample_evidence(
                iu,
                iv,
                du,
                dv,
                step_px,
                painted[j],
                p_hits[j],
                dist_ridge,
                near_ridge,
                dist_any,
                near_any,
                normals,
                tolerance,
                max_sin,
                chance,
                chance_scale,
            )
            supported[i, e] += length_px * support
            if support > 0.0:
                cv = min(max(int(evidence_points[k, 1] / cell_px), 0), owner.shape[0] - 1)
                cu = min(max(int(evidence_points[k, 0] / cell_px), 0), owner.shape[1] - 1)
                taker = owner[cv, cu]
                stamp = i * n_edges + e
                if taker // n_edges == i and taker != stamp:
                    continue  # another edge of this camera took the mark (-1: nobody's)
                owner[cv, cu] = stamp
            total += (length_px / tolerance) * sample_llr
        llr[i] = total


def edge_support(
    genomes: np.ndarray,
    samples: VerifySamples,
    maps: EvidenceMaps,
    tolerance_px: float,
    max_angle_rad: float = VERIFY_MAX_ANGLE_RAD,
    chance: ChanceMaps | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Supported and visible projected length (px) per camera and court edge, (N, E) each, and
    each camera's log-likelihood ratio (N,) against chance (see `_verify_njit`)."""
    pop = np.ascontiguousarray(camera.as_population(genomes))
    supported = np.empty((len(pop), samples.n_edges))
    visible = np.empty((len(pop), samples.n_edges))
    llr = np.empty(len(pop))
    if chance is None or chance.tolerance_px != tolerance_px:
        chance = chance_maps(maps, tolerance_px)
    fold_tan2 = camera.lens_fold_tan2(pop)
    parallel.over_rows(
        len(pop),
        lambda a, b: _verify_njit(
            pop[a:b],
            samples.points,
            samples.directions,
            samples.edge,
            samples.painted,
            samples.p_hit,
            samples.n_edges,
            0.02,
            samples.spacing_m,
            fold_tan2[a:b],
            maps.dist_ridge,
            maps.near_ridge,
            maps.dist_any,
            maps.near_any,
            maps.normals,
            maps.points,
            maps.ignore.view(np.uint8),
            float(tolerance_px),
            float(np.sin(max_angle_rad)),
            chance.values,
            chance.scale,
            supported[a:b],
            visible[a:b],
            llr[a:b],
        ),
    )
    return supported, visible, llr


COARSE_SPACING_M = 0.6
# sample spacing of the first cut (floor or walls alone)
FLOOR_PASS_SPACING_M = 0.8


@numba.njit(cache=True, nogil=True)
def _coarse_njit(
    pop: np.ndarray,
    points: np.ndarray,
    same_edge_as_previous: np.ndarray,
    p_hits: np.ndarray,
    painted: np.ndarray,
    dist_ridge: np.ndarray,
    near_ridge: np.ndarray,
    dist_any: np.ndarray,
    near_any: np.ndarray,
    normals: np.ndarray,
    ignore: np.ndarray,
    tolerances: np.ndarray,
    max_sin: float,
    chances: np.ndarray,
    chance_scale: int,
    out: np.ndarray,
) -> None:
    """A cheap first ranking: the log-likelihood ratio of `_verify_njit` over a sparse sampling,
    each sample's line direction and length taken from the previous sample of its edge (one
    projection per sample instead of two), at each of `tolerances` (T,) with its chance map
    `chances[k]`, into out (N, T)."""
    h, w = ignore.shape
    max_sample_px = 2.0 * MAX_SAMPLE_SHARE_OF_DIAGONAL * np.sqrt(h * h + w * w)
    r = np.empty((3, 3))
    t = np.empty(3)
    for i in range(pop.shape[0]):
        g = pop[i]
        extrinsics_njit(g, r, t)
        out[i, :] = 0.0
        pu = 0.0
        pv = 0.0
        previous_ok = False
        for j in range(points.shape[0]):
            u, v, depth = project_point_njit(r, t, g, points[j, 0], points[j, 1], points[j, 2])
            ok = depth > MIN_SAMPLE_DEPTH_M and 0.0 <= u <= w - 1.0 and 0.0 <= v <= h - 1.0
            if ok and previous_ok and same_edge_as_previous[j]:
                du = u - pu
                dv = v - pv
                step = np.sqrt(du * du + dv * dv)
                iu = int(u + 0.5)
                iv = int(v + 0.5)
                if step > 0.0 and not ignore[iv, iu]:
                    length = min(step, max_sample_px)
                    for k in range(tolerances.shape[0]):
                        _, sample_llr, _ = _sample_evidence(
                            iu,
                            iv,
                            du,
                            dv,
                            step,
                            painted[j],
                            p_hits[j],
                            dist_ridge,
                            near_ridge,
                            dist_any,
                            near_any,
                            normals,
                            tolerances[k],
                            max_sin,
                            chances[k],
                            chance_scale,
                        )
                        out[i, k] += (length / tolerances[k]) * sample_llr
            previous_ok = ok
            pu = u
            pv = v


def coarse_scores(
    genomes: np.ndarray,
    model: CourtModel,
    maps: EvidenceMaps,
    tolerances_px: tuple[float, ...],
    part: str = "court",
) -> np.ndarray:
    """`_coarse_njit` over a sparse sampling of the court, or (sparser: a first cut through
    hundreds of thousands of hypotheses) of its floor or its walls only (`part`: "court",
    "floor", "walls"): (N, T), one column per tolerance (one projection serves them all)."""
    if part == "court":
        samples = verify_samples(model, COARSE_SPACING_M)
    else:
        on_floor = (model.nodes[model.edges][..., 2] == 0.0).all(axis=1)
        if part not in ("floor", "walls"):
            raise ValueError(f"part must be 'court', 'floor' or 'walls', got {part!r}")
        keep = on_floor if part == "floor" else ~on_floor
        edges = [name for name, kept in zip(model.edge_names, keep, strict=True) if kept]
        samples = verify_samples(model.subset(edges), FLOOR_PASS_SPACING_M)
    same = np.concatenate([[False], samples.edge[1:] == samples.edge[:-1]])
    chances = np.stack([chance_maps(maps, tol).values for tol in tolerances_px])
    out = np.empty((len(genomes), len(tolerances_px)))
    pop = np.ascontiguousarray(camera.as_population(genomes))
    tolerances = np.array(tolerances_px, dtype=np.float64)
    parallel.over_rows(
        len(pop),
        lambda a, b: _coarse_njit(
            pop[a:b],
            samples.points,
            same,
            samples.p_hit,
            samples.painted,
            maps.dist_ridge,
            maps.near_ridge,
            maps.dist_any,
            maps.near_any,
            maps.normals,
            maps.ignore.view(np.uint8),
            tolerances,
            float(np.sin(VERIFY_MAX_ANGLE_RAD)),
            chances,
            CHANCE_SCALE,
            out[a:b],
        ),
    )
    return out


def reference_pixels(genomes: np.ndarray, model: CourtModel) -> np.ndarray:
    """Pixels (N, 6, 2) of six floor points (corners, T, half_back): to tell cameras apart."""
    names = ("floor_front_left", "floor_front_right", "floor_back_left", "floor_back_right", "T")
    pts = np.array([model.node(n) for n in names] + [model.node("half_back")])
    pixels, depth = camera.project_points(camera.as_population(genomes), pts)
    pixels = np.where(depth[..., None] > 0, pixels, 1e6)
    return pixels


def distinct_best(
    genomes: np.ndarray, scores: np.ndarray, model: CourtModel, image_size: tuple[int, int], k: int
) -> np.ndarray:
    """Indices of up to k best-scoring cameras, each differing from the better ones (a floor
    reference point moved by more than DISTINCT_SHARE_OF_WIDTH of the width)."""
    order = np.argsort(-scores, kind="stable")
    chosen: list[int] = []
    if len(order) == 0:
        return np.zeros(0, np.int64)
    pixels = reference_pixels(genomes[order[: 50 * k]], model)
    limit = DISTINCT_SHARE_OF_WIDTH * image_size[0]
    kept_pixels: list[np.ndarray] = []
    for rank, idx in enumerate(order[: 50 * k]):
        p = pixels[rank]
        clipped = np.clip(p, -2 * image_size[0], 3 * image_size[0])
        if any(np.max(np.linalg.norm(clipped - q, axis=1)) < limit for q in kept_pixels):
            continue
        chosen.append(int(idx))
        kept_pixels.append(clipped)
        if len(chosen) == k:
            break
    return np.array(chosen, dtype=np.int64)


def verify_tolerance_px(image_width: int) -> float:
    return max(2.5, VERIFY_TOLERANCE_PX_AT_1920 * image_width / 1920.0)


def rank_tolerance_px(image_width: int) -> float:
    return max(5.0, RANK_TOLERANCE_PX_AT_1920 * image_width / 1920.0)
