"""Fitness maps and population fitness (paper section VI-B, eq. 13).

The paper defines a genome's fitness as the sum of the fitness map under the rasterised projection
of the court (`literal_fitness`). The GA instead uses `population_fitness`: the court's sampled lines
are projected and the map is integrated along each projected sub-segment (trapezoid rule with the
Chebyshev pixel length, which is how many pixels an 8-connected rasterised line covers). It ranks
populations like the literal sum (tested) at a tiny fraction of the cost.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numba
import numpy as np

from app.calib.camera import (
    as_population,
    extrinsics_njit,
    project_point_njit,
)
from app.calib.court import CourtModel, LineSamples
from app.calib.render import rasterize_court

# Samples this close to the camera plane (or behind it) make their sub-segments count 0; the same
# threshold `render.court_polylines` uses to cut lines, so both fitness definitions agree.
MIN_DEPTH_M = 1e-6
# eq. 13: F = 1 - clip(ln(E + 1) / LOG_SCALE, 0, 1)
LOG_SCALE = 0.3
# numba freezes module-level arrays as constants


def _check_edge_image(edge_image: np.ndarray) -> np.ndarray:
    edges = np.asarray(edge_image)
    if edges.ndim != 2 or edges.size == 0:
        raise ValueError(f"edge image must be a non-empty (H, W) array, got shape {edges.shape}")
    return edges


def distance_map(edge_image: np.ndarray) -> np.ndarray:
    """Distance in pixels (float32 (H, W)) to the nearest edge pixel (edge = value > 0).

    OpenCV's DIST_L2 with a 3x3 mask is the chamfer transform of [29] with a = 0.955, b = 1.3693.
    An image without any edge pixel has no finite distance: the map is +inf everywhere.
    """
    edges = _check_edge_image(edge_image)
    if not np.any(edges > 0):
        return np.full(edges.shape, np.inf, dtype=np.float32)
    # distanceTransform measures the distance to the nearest ZERO pixel, so edges become zeros
    background = np.where(edges > 0, 0, 255).astype(np.uint8)
    return cv2.distanceTransform(background, cv2.DIST_L2, 3, dstType=cv2.CV_32F)


def fitness_map(edge_image: np.ndarray, transformed: bool = True) -> np.ndarray:
    """Lookup map of eq. 13 as float32 (H, W): F in [0, 1], or 2F - 1 in [-1, 1] if `transformed`.

    E is the distance map normalised by its maximum. With no edge pixel at all nothing can match,
    so F = 0 everywhere; with edges everywhere, F = 1.
    """
    distance = distance_map(edge_image)
    top = float(distance.max())
    f: np.ndarray
    if not np.isfinite(top):
        f = np.zeros(distance.shape, dtype=np.float32)
    elif top == 0.0:
        f = np.ones(distance.shape, dtype=np.float32)
    else:
        e = distance / np.float32(top)
        f = 1.0 - np.clip(np.log1p(e) / LOG_SCALE, 0.0, 1.0)
    if transformed:
        f = 2.0 * f - 1.0
    return np.ascontiguousarray(f, dtype=np.float32)


@numba.njit(cache=True, inline="always")
def bilinear_njit(fmap: np.ndarray, u: float, v: float) -> float:
    """Bilinear lookup at 0 <= u < W - 1, 0 <= v < H - 1 (the caller clamps, see `index_limit`).

    No clamps or branches here: that keeps the loop around it vectorisable with gathers, which
    halves the cost of the lookups.
    """
    iu = np.uint64(u)
    iv = np.uint64(v)
    fu = u - np.float64(iu)
    fv = v - np.float64(iv)
    one = np.uint64(1)
    a = fmap[iv, iu]
    b = fmap[iv, iu + one]
    c = fmap[iv + one, iu]
    d = fmap[iv + one, iu + one]
    top = a + fu * (b - a)
    bottom = c + fu * (d - c)
    return top + fv * (bottom - top)


@numba.njit(cache=True, inline="always")
def index_limit(size: int) -> float:
    """Largest coordinate below size - 1: the last pixel centre is then read as 1 - 2e-13 of the way
    from its neighbour, so `bilinear_njit` never indexes past the map."""
    return np.nextafter(float(size - 1), 0.0)


@numba.njit(cache=True)
def _clipped_segment(
    fmap: np.ndarray, u0: float, v0: float, u1: float, v1: float, u_max: float, v_max: float
) -> float:
    """Trapezoid contribution of the part of segment (u0, v0)-(u1, v1) inside the image.

    Liang-Barsky clipping: the literal fitness has no pixels outside the image, and a sample near
    the camera plane can project arbitrarily far out, so only the inside part may count.
    """
    if not (np.isfinite(u0) and np.isfinite(v0) and np.isfinite(u1) and np.isfinite(v1)):
        return 0.0
    du = u1 - u0
    dv = v1 - v0
    t0 = 0.0
    t1 = 1.0
    for k in range(4):
        if k == 0:
            p, q = -du, u0
        elif k == 1:
            p, q = du, u_max - u0
        elif k == 2:
            p, q = -dv, v0
        else:
            p, q = dv, v_max - v0
        if p == 0.0:
            if q < 0.0:
                return 0.0
        else:
            s = q / p
            if p < 0.0:
                if s > t1:
                    return 0.0
                t0 = max(t0, s)
            else:
                if s < t0:
                    return 0.0
                t1 = min(t1, s)
    h, w = fmap.shape
    u_lim = index_limit(w)
    v_lim = index_limit(h)
    a_u = min(max(u0 + t0 * du, 0.0), u_max)
    a_v = min(max(v0 + t0 * dv, 0.0), v_max)
    b_u = min(max(u0 + t1 * du, 0.0), u_max)
    b_v = min(max(v0 + t1 * dv, 0.0), v_max)
    length = max(abs(b_u - a_u), abs(b_v - a_v))
    if length == 0.0:
        return 0.0
    f_a = bilinear_njit(fmap, min(a_u, u_lim), min(a_v, v_lim))
    f_b = bilinear_njit(fmap, min(b_u, u_lim), min(b_v, v_lim))
    return 0.5 * (f_a + f_b) * length


class SampleArrays(NamedTuple):
    """Line samples laid out for the compiled fitness: coordinates as rows, edge joins as floats."""

    xyz: np.ndarray  # (3, M) float64: x, y, z rows, so the projection loop vectorises
    joins_next: np.ndarray  # (M,) float64: 1 where sample j and j + 1 lie on the same edge


def sample_arrays(samples: LineSamples) -> SampleArrays:
    points = np.asarray(samples.points, dtype=np.float64)
    offsets = np.asarray(samples.offsets, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or offsets.ndim != 1 or offsets[-1] != len(points):
        raise ValueError("samples must hold points (M, 3) and offsets (E + 1,) ending at M")
    if len(points) < 2:
        raise ValueError("samples must hold at least one edge (two points)")
    joins = np.ones(len(points))
    joins[offsets[1:] - 1] = 0.0
    return SampleArrays(np.ascontiguousarray(points.T), joins)


class Workspace(NamedTuple):
    """Scratch buffers (M,) for one genome's fitness, reused across a population and generations."""

    u: np.ndarray  # pixel of sample j, NaN if it is behind the camera
    v: np.ndarray
    u_in: np.ndarray  # pixel of sample j if inside the image, else 0 (index-safe)
    v_in: np.ndarray
    inside: np.ndarray  # 1.0 / 0.0
    segment: np.ndarray  # Chebyshev length of inside sub-segment j (j -> j + 1), else 0
    r: np.ndarray
    t: np.ndarray


@numba.njit(cache=True)
def make_workspace(n_samples: int) -> Workspace:
    return Workspace(
        np.empty(n_samples),
        np.empty(n_samples),
        np.empty(n_samples),
        np.empty(n_samples),
        np.empty(n_samples),
        np.empty(n_samples),
        np.empty((3, 3)),
        np.empty(3),
    )


@numba.njit(cache=True)
def _project_samples(g: np.ndarray, xyz: np.ndarray, fmap: np.ndarray, ws: Workspace) -> int:
    """Pass 1: index-safe pixels and inside flags of all samples; returns the count inside."""
    h, w = fmap.shape
    u_max = float(w - 1)
    v_max = float(h - 1)
    u_lim = index_limit(w)
    v_lim = index_limit(h)
    r, t = ws.r, ws.t
    extrinsics_njit(g, r, t)
    xs, ys, zs = xyz[0], xyz[1], xyz[2]
    u, v, u_in, v_in, inside = ws.u, ws.v, ws.u_in, ws.v_in, ws.inside
    n_inside = 0
    for j in range(xs.shape[0]):
        pu, pv, pz = project_point_njit(r, t, g, xs[j], ys[j], zs[j])
        front = pz > MIN_DEPTH_M
        # non-short-circuit `&` keeps this loop branch-free (vectorised); NaN compares False
        ins = front & (pu >= 0.0) & (pu <= u_max) & (pv >= 0.0) & (pv <= v_max)
        u[j] = pu if front else np.nan
        v[j] = pv if front else np.nan
        u_in[j] = min(pu, u_lim) if ins else 0.0
        v_in[j] = min(pv, v_lim) if ins else 0.0
        inside[j] = 1.0 if ins else 0.0
        n_inside += 1 if ins else 0
    return n_inside


@numba.njit(cache=True, fastmath={"reassoc", "nsz", "contract"})
def _integrate_inside(joins_next: np.ndarray, fmap: np.ndarray, ws: Workspace) -> float:
    """Passes 2-3: the trapezoid sum over fully inside sub-segments, regrouped per sample.

    sum_j s_j (F_j + F_j+1) / 2 = sum_j F_j (s_j-1 + s_j) / 2, with s_j the Chebyshev length of
    sub-segment j (0 unless both ends are inside and on the same edge). The regrouped form is a
    plain reduction over lookups, which LLVM vectorises with gathers (reassociation allowed here
    only: the order is fixed at compile time, so results stay reproducible).
    """
    u_in, v_in, inside, segment = ws.u_in, ws.v_in, ws.inside, ws.segment
    n = u_in.shape[0]
    for j in range(n - 1):
        length = max(abs(u_in[j + 1] - u_in[j]), abs(v_in[j + 1] - v_in[j]))
        segment[j] = joins_next[j] * inside[j] * inside[j + 1] * length
    segment[n - 1] = 0.0
    total = 0.5 * segment[0] * bilinear_njit(fmap, u_in[0], v_in[0])
    for j in range(1, n):
        total += 0.5 * (segment[j - 1] + segment[j]) * bilinear_njit(fmap, u_in[j], v_in[j])
    return total


@numba.njit(cache=True)
def _integrate_border(joins_next: np.ndarray, fmap: np.ndarray, ws: Workspace) -> float:
    """The inside parts of sub-segments with one or both ends outside the image."""
    h, w = fmap.shape
    u_max = float(w - 1)
    v_max = float(h - 1)
    u, v, inside = ws.u, ws.v, ws.inside
    total = 0.0
    for j in range(u.shape[0] - 1):
        if joins_next[j] == 0.0 or inside[j] * inside[j + 1] != 0.0:
            continue
        u0, v0, u1, v1 = u[j], v[j], u[j + 1], v[j + 1]
        # both ends beyond the same image side: nothing inside (the common case, decided fast)
        if (
            (u0 < 0.0 and u1 < 0.0)
            or (u0 > u_max and u1 > u_max)
            or (v0 < 0.0 and v1 < 0.0)
            or (v0 > v_max and v1 > v_max)
        ):
            continue
        # NaN (behind the camera) falls through to here and counts 0 in the clipper
        total += _clipped_segment(fmap, u0, v0, u1, v1, u_max, v_max)
    return total


@numba.njit(cache=True)
def genome_fitness_njit(
    g: np.ndarray, xyz: np.ndarray, joins_next: np.ndarray, fmap: np.ndarray, ws: Workspace
) -> float:
    """Fitness of one genome (see `population_fitness`); `fmap` float32 (H, W), H, W >= 2."""
    n_inside = _project_samples(g, xyz, fmap, ws)
    total = _integrate_inside(joins_next, fmap, ws) if n_inside > 1 else 0.0
    if n_inside < xyz.shape[1]:
        total += _integrate_border(joins_next, fmap, ws)
    return total


@numba.njit(cache=True)
def population_fitness_njit(
    pop: np.ndarray,
    xyz: np.ndarray,
    joins_next: np.ndarray,
    fmap: np.ndarray,
    ws: Workspace,
    out: np.ndarray,
    first_row: int,
) -> None:
    """Fitness of rows first_row.. of `pop` (N, 15) into the same rows of `out` (N,)."""
    for i in range(first_row, pop.shape[0]):
        out[i] = genome_fitness_njit(pop[i], xyz, joins_next, fmap, ws)


def check_fitness_map(fmap: np.ndarray) -> np.ndarray:
    """The map as the compiled code needs it: C-contiguous float32 (H, W) with H, W >= 2."""
    lookup = np.asarray(fmap)
    if lookup.ndim != 2 or lookup.shape[0] < 2 or lookup.shape[1] < 2:
        raise ValueError(f"fitness map must be an (H, W) array with H, W >= 2, got {lookup.shape}")
    return np.ascontiguousarray(lookup, dtype=np.float32)


class Scorer:
    """Population fitness on one map and one sample set, with the samples laid out and the scratch
    buffers made once: optimisers that score many small populations (or single genomes) on the
    same map pay that set-up once instead of on every call."""

    def __init__(self, samples: LineSamples, fmap: np.ndarray) -> None:
        self.arrays = sample_arrays(samples)
        self.fmap = check_fitness_map(fmap)
        self.workspace = make_workspace(self.arrays.xyz.shape[1])

    def __call__(self, pop: np.ndarray) -> np.ndarray:
        """Fitness (N,) float64 of a population (N, 15) or one genome (15,)."""
        population = np.ascontiguousarray(as_population(pop))
        out = np.empty(population.shape[0])
        population_fitness_njit(
            population, self.arrays.xyz, self.arrays.joins_next, self.fmap, self.workspace, out, 0
        )
        return out


def population_fitness(pop: np.ndarray, samples: LineSamples, fmap: np.ndarray) -> np.ndarray:
    """Fitness (N,) float64 of a population (N, 15) (or one genome (15,)) on a fitness map.

    Sum over consecutive samples within each court edge of 0.5 (F_i + F_i+1) max(|du|, |dv|), with
    bilinear lookups; the parts of sub-segments outside the image count 0, and sub-segments with a
    sample behind the camera (depth <= MIN_DEPTH_M) count 0. (Many calls on one map: `Scorer`.)
    """
    return Scorer(samples, fmap)(pop)


def literal_fitness(pop: np.ndarray, model: CourtModel, fmap: np.ndarray) -> np.ndarray:
    """The paper's definition (N,): rasterise each genome's court, mask the map with it, sum."""
    population = as_population(pop)
    lookup = check_fitness_map(fmap)
    height, width = lookup.shape
    out = np.empty(population.shape[0])
    for i, genome in enumerate(population):
        mask = rasterize_court(genome, model, (width, height)) > 0
        out[i] = float(lookup[mask].sum(dtype=np.float64))
    return out
