"""Line evidence -> chains -> the lens's radial distortion -> straight segments -> image lines.

1. Chains: evidence pixels are linked to 8-neighbours that run the same way (normals within
   LINK_MAX_ANGLE_RAD, the step between them along the line, not across it), so crossing lines
   separate and a curved (distorted) line stays one chain.
2. Distortion: a court line is straight in the world, so the division model
   p_u = c + (p_d - c) / (1 + lambda |p_d - c|^2 / R^2) (c the image centre, R half its diagonal)
   that makes the long chains straightest is the lens's first radial term (plumb-line method).
3. Segments: each chain, undistorted, is split where it bends (recursive split at the farthest
   point from the chord) into straight pieces fitted by least squares.
4. Lines: collinear segments (a line broken by a player, a post or a gap) are merged.

Everything downstream (the global search) works in the undistorted pixel frame of step 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from app.calib import camera
from app.calib.lines import LineEvidence

LINK_MAX_ANGLE_RAD = np.deg2rad(8.0)
# A neighbour is "along" the line when the step to it is this far from the normal at least.
LINK_MAX_ACROSS = 0.8
# Chains shorter than this (px at 1920 px wide, scaled with the width) are noise for our purposes.
MIN_CHAIN_PX_AT_1920 = 24.0
# Distortion: chains at least this long (share of the image width) vote, on this lambda grid
# (the strongest barrel lenses of bench.synthetic's wide-angle views need about -0.6 in the
# middle of the picture and more towards its edges, which one term cannot follow).
DISTORTION_CHAIN_FRACTION = 0.12
LAMBDA_GRID = np.linspace(-1.2, 0.4, 161)
# A chain is straight under a lambda when its points lie within about this RMS (px) of a line
# (edge pixels' sub-pixel positions scatter by a few tenths of a pixel).
STRAIGHT_PX = 0.6
# The division model is not used where it would fold (1 + lambda r^2 below this).
MIN_DIVISION_DENOMINATOR = 0.25
# A second lambda: support at least this share of the best's, this far from it.
SECOND_LENS_SUPPORT = 0.5
SECOND_LENS_MIN_DIFFERENCE = 0.08
# The least-squares refinement looks this many grid steps either way of the consensus.
REFINE_GRID_STEPS = 15
# A straight piece fits its line with at most this RMS (px), else it is split.
SPLIT_RMS_PX = 0.8
# A chain whose points, ordered along it, step across it by more than this is a web of lines
# joined at crossings; its lines are taken out one by one (within RUN_TOLERANCE_PX of a line
# through two of RUN_PROBES probe points, in runs broken at gaps over RUN_MAX_GAP_PX).
WEB_MAX_ACROSS_STEP_PX = 3.0
RUN_TOLERANCE_PX = 1.2
RUN_PROBES = 24
RUN_MAX_GAP_PX = 6.0
# Collinear merge: directions within this angle, and every endpoint this close to the other line
# (px, plus a share of the gap between the pieces).
MERGE_MAX_ANGLE_RAD = np.deg2rad(1.5)
MERGE_MAX_OFFSET_PX = 2.0
MERGE_OFFSET_PER_GAP = 0.01


@dataclass(frozen=True)
class Segments:
    """Straight pieces of evidence in the undistorted frame (see module doc).

    a, b: (S, 2) endpoints; normal: (S, 2) unit normals; length_px: (S,); support_px: (S,) number
    of evidence pixels; rms_px: (S,) fit residual; ridge_share: (S,) share of RIDGE pixels (1 for
    a painted line, 0 for a junction edge); contrast: (S,) mean contrast.
    """

    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray
    length_px: np.ndarray
    support_px: np.ndarray
    rms_px: np.ndarray
    ridge_share: np.ndarray
    contrast: np.ndarray

    def __len__(self) -> int:
        return int(self.a.shape[0])


@dataclass(frozen=True)
class Undistortion:
    """The division model of the module doc: centre (2,), radius R (px) and lambda."""

    centre: np.ndarray
    radius_px: float
    lam: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Distorted -> undistorted pixels, (..., 2)."""
        d = np.asarray(points, dtype=np.float64) - self.centre
        r2 = np.sum(d * d, axis=-1, keepdims=True) / (self.radius_px * self.radius_px)
        return self.centre + d / (1.0 + self.lam * r2)

    def k1_for_focal(self, focal_px: float) -> float:
        """The Brown k1 (normalised by the focal length) this lambda amounts to, to first order."""
        return float(self.lam * (focal_px / self.radius_px) ** 2)


@numba.njit(cache=True)
def _find(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(cache=True, nogil=True)
def _link(
    ys: np.ndarray,
    xs: np.ndarray,
    index: np.ndarray,
    normal: np.ndarray,
    max_angle: float,
    max_across: float,
) -> np.ndarray:
    """Union-find over evidence pixels; returns each pixel's root."""
    n = ys.shape[0]
    parent = np.arange(n)
    h, w = index.shape
    for k in range(n):
        y, x = ys[k], xs[k]
        a = normal[y, x]
        ca, sa = np.cos(a), np.sin(a)
        # each undirected neighbour pair once: right, down-left, down, down-right
        for dy, dx in ((0, 1), (1, -1), (1, 0), (1, 1)):
            qy, qx = y + dy, x + dx
            if qy >= h or qx < 0 or qx >= w:
                continue
            j = index[qy, qx]
            if j < 0:
                continue
            diff = abs(a - normal[qy, qx])
            diff = min(diff, np.pi - diff)
            if diff > max_angle:
                continue
            step = np.sqrt(dx * dx + dy * dy)
            if abs(ca * dx + sa * dy) / step > max_across:
                continue
            ri = _find(parent, k)
            rj = _find(parent, j)
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    for k in range(n):
        parent[k] = _find(parent, k)
    return parent


@dataclass(frozen=True)
class Chains:
    """Linked evidence: `points` (P, 2) sub-pixel positions (distorted frame), `start` (C + 1,)
    offsets of each chain's points, `ridge` (P,) bool, `contrast` (P,)."""

    points: np.ndarray
    start: np.ndarray
    ridge: np.ndarray
    contrast: np.ndarray

    def __len__(self) -> int:
        return int(self.start.shape[0] - 1)

    def chain(self, c: int) -> np.ndarray:
        return self.points[self.start[c] : self.start[c + 1]]


def chains_of(evidence: LineEvidence, min_chain_px: float | None = None) -> Chains:
    """Link the (not ignored) evidence pixels into chains, longest first."""
    h, w = evidence.shape
    if min_chain_px is None:
        min_chain_px = max(8.0, MIN_CHAIN_PX_AT_1920 * w / 1920.0)
    mask = evidence.mask()
    ys, xs = np.nonzero(mask)
    index = np.full((h, w), -1, np.int64)
    index[ys, xs] = np.arange(len(ys))
    roots = _link(
        ys.astype(np.int64),
        xs.astype(np.int64),
        index,
        evidence.normal_rad,
        LINK_MAX_ANGLE_RAD,
        LINK_MAX_ACROSS,
    )
    order = np.argsort(roots, kind="stable")
    roots_sorted = roots[order]
    cuts = np.flatnonzero(np.diff(roots_sorted)) + 1
    bounds = np.concatenate([[0], cuts, [len(order)]])
    sizes = np.diff(bounds)
    angle = evidence.normal_rad[ys, xs].astype(np.float64)
    offset = evidence.offset_px[ys, xs].astype(np.float64)
    sub = np.column_stack([xs + offset * np.cos(angle), ys + offset * np.sin(angle)])
    ridge = evidence.kind[ys, xs] == 1
    contrast = evidence.contrast[ys, xs]
    keep = [c for c in np.argsort(-sizes, kind="stable") if sizes[c] >= min_chain_px]
    pieces = [order[bounds[c] : bounds[c + 1]] for c in keep]
    if not pieces:
        return Chains(np.zeros((0, 2)), np.zeros(1, np.int64), np.zeros(0, bool), np.zeros(0))
    members = np.concatenate(pieces)
    start = np.concatenate([[0], np.cumsum([len(p) for p in pieces])]).astype(np.int64)
    return Chains(sub[members], start, ridge[members], contrast[members].astype(np.float64))


def _line_fit_rms(points: np.ndarray) -> float:
    centred = points - points.mean(axis=0)
    cov = centred.T @ centred / len(points)
    return float(np.sqrt(max(np.linalg.eigvalsh(cov)[0], 0.0)))


def _straightness_px(points: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """(len(LAMBDA_GRID),) RMS distance (px of the picture) of a chain's points from the line
    fitted to them after undistortion with each lambda of the grid; inf where the division
    model folds over the chain. Residuals are measured in the picture's pixels, not the
    undistorted frame's: a strong barrel lambda spreads the frame out towards the edges, and
    measured there every chain would look less straight the stronger the lens."""
    d = points - centre
    r2 = np.sum(d * d, axis=1) / (radius * radius)
    out = np.full(len(LAMBDA_GRID), np.inf)
    for k, lam in enumerate(LAMBDA_GRID):
        den = 1.0 + lam * r2
        if np.any(den < MIN_DIVISION_DENOMINATOR):
            continue
        und = d / den[:, None]
        centred = und - und.mean(axis=0)
        _, vecs = np.linalg.eigh(centred.T @ centred)
        out[k] = float(np.sqrt(np.mean((centred @ vecs[:, 0] * den) ** 2)))
    return out


def undistortion_candidates(chains: Chains, image_size: tuple[int, int]) -> list[Undistortion]:
    """The division-model lambdas that straighten the long chains (plumb-line method), most
    supported first: the best, and a second when the chains also agree clearly on another.

    A consensus, not a least-squares fit: each chain votes, by the square root of its number of
    points (a long chain is a more precise witness, not a more trustworthy one: a score
    graphic's edge is long), for the lambdas that make it straight to about STRAIGHT_PX (a soft
    count), and the best lambda is
    then refined by least squares over the chains straight there. Least squares over all chains
    let the few that no lambda makes straight (a player's outline, two lines joined at a corner,
    a curved advert) pull the estimate anywhere: on bench.synthetic's wide-angle views it came
    out as a mild pincushion for strong barrel lenses. A second lambda is kept when its support
    is at least SECOND_LENS_SUPPORT of the best's: a score graphic's long straight edges vote for
    no distortion at all, however strong the lens, and only the court can tell them apart."""
    width, height = image_size
    centre = camera.picture_centre(image_size)
    radius = 0.5 * float(np.hypot(width, height))
    min_len = DISTORTION_CHAIN_FRACTION * width
    voters = [
        chains.chain(c)
        for c in range(len(chains))
        if float(np.hypot(*np.ptp(chains.chain(c), axis=0))) >= min_len
    ]
    if not voters:
        return [Undistortion(centre, radius, 0.0)]
    rms = np.array([_straightness_px(pts, centre, radius) for pts in voters])
    weights = np.sqrt(np.array([len(v) for v in voters], dtype=np.float64))
    support = (weights[:, None] * np.exp(-0.5 * (rms / STRAIGHT_PX) ** 2)).sum(axis=0)
    if not np.any(support > 0.0):
        return [Undistortion(centre, radius, 0.0)]
    n = len(LAMBDA_GRID)
    peaks = [
        k
        for k in range(n)
        if (k == 0 or support[k] >= support[k - 1]) and (k == n - 1 or support[k] >= support[k + 1])
    ]
    peaks.sort(key=lambda k: -support[k])
    chosen = [peaks[0]]
    for k in peaks[1:]:
        if support[k] < SECOND_LENS_SUPPORT * support[peaks[0]]:
            break
        if abs(LAMBDA_GRID[k] - LAMBDA_GRID[peaks[0]]) >= SECOND_LENS_MIN_DIFFERENCE:
            chosen.append(k)
            break
    return [Undistortion(centre, radius, _refined_lambda(rms, weights, k)) for k in chosen]


def _refined_lambda(rms: np.ndarray, weights: np.ndarray, k: int) -> float:
    """The lambda near grid point k that minimises the squared residuals of the chains straight
    at k (parabolic interpolation between grid points)."""
    inliers = rms[:, k] <= 2.0 * STRAIGHT_PX
    if not inliers.any():
        return float(LAMBDA_GRID[k])
    cost = (weights[inliers, None] * np.minimum(rms[inliers], 3.0 * STRAIGHT_PX) ** 2).sum(axis=0)
    lo, hi = max(0, k - REFINE_GRID_STEPS), min(len(LAMBDA_GRID), k + REFINE_GRID_STEPS + 1)
    best = lo + int(np.argmin(cost[lo:hi]))
    lam = float(LAMBDA_GRID[best])
    if 0 < best < len(LAMBDA_GRID) - 1:
        c0, c1, c2 = cost[best - 1], cost[best], cost[best + 1]
        denom = c0 - 2.0 * c1 + c2
        if denom > 0.0 and np.isfinite(denom):
            lam += float(0.5 * (c0 - c2) / denom * (LAMBDA_GRID[1] - LAMBDA_GRID[0]))
    return lam


def estimate_undistortion(chains: Chains, image_size: tuple[int, int]) -> Undistortion:
    """The division-model lambda that straightens the long chains best (0 if none is long)."""
    return undistortion_candidates(chains, image_size)[0]


def _split(points: np.ndarray, out: list[tuple[int, int]], lo: int, hi: int) -> None:
    """Recursive split of points[lo:hi] (ordered along the chain) into straight pieces.

    A piece is straight when its least-squares line fits with RMS <= SPLIT_RMS_PX (edge pixels
    jitter by a pixel, so single deviations say little); otherwise it is split at the point of
    the smoothed chain farthest from the chord, where a bend or a corner is.
    """
    piece = points[lo:hi]
    if hi - lo < 8 or _line_fit_rms(piece) <= SPLIT_RMS_PX:
        out.append((lo, hi))
        return
    a, b = piece[0], piece[-1]
    chord = b - a
    length = float(np.hypot(*chord))
    if length < 1e-9:
        out.append((lo, hi))
        return
    normal = np.array([-chord[1], chord[0]]) / length
    window = max(3, (hi - lo) // 20)
    dev = np.abs(np.convolve((piece - a) @ normal, np.ones(window) / window, mode="same"))
    k = int(np.argmax(dev[window:-window])) + window if hi - lo > 2 * window + 1 else (hi - lo) // 2
    _split(points, out, lo, lo + k + 1)
    _split(points, out, lo + k, hi)


def _is_simple_curve(points: np.ndarray) -> bool:
    """Whether points ordered along their principal direction trace one line or gentle curve
    (each step moves little across it), not a web of lines joined at their crossings."""
    if len(points) < 8:
        return True
    centred = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)
    across = centred @ vecs[:, 0]
    return float(np.abs(np.diff(across)).max()) <= WEB_MAX_ACROSS_STEP_PX


def _straight_runs(
    points: np.ndarray, min_length_px: float, pieces: list[tuple[int, int]]
) -> np.ndarray:
    """The straight lines of a web of points (N, 2), best supported first: the line through two
    of its points that passes within RUN_TOLERANCE_PX of the most points takes them; its points
    are split into runs at gaps, and runs at least `min_length_px` long become pieces. Returns
    the order of the points that `pieces` (ranges into that order) refers to."""
    remaining = np.arange(len(points))
    ordered: list[np.ndarray] = []
    start = 0
    while len(remaining) >= 8:
        sub = points[remaining]
        probes = sub[np.unique(np.linspace(0, len(sub) - 1, RUN_PROBES).round().astype(int))]
        best_count, best_inliers = 0, np.zeros(0, dtype=np.int64)
        for i in range(len(probes)):
            for j in range(i + 1, len(probes)):
                d = probes[j] - probes[i]
                length = float(np.hypot(*d))
                if length < min_length_px:
                    continue
                n = np.array([-d[1], d[0]]) / length
                inliers = np.flatnonzero(np.abs((sub - probes[i]) @ n) <= RUN_TOLERANCE_PX)
                if len(inliers) > best_count:
                    best_count, best_inliers = len(inliers), inliers
        if best_count < 8:
            break
        run_points = sub[best_inliers]
        centred = run_points - run_points.mean(axis=0)
        _, vecs = np.linalg.eigh(centred.T @ centred)
        along = centred @ vecs[:, 1]
        order = np.argsort(along, kind="stable")
        gaps = np.flatnonzero(np.diff(along[order]) > RUN_MAX_GAP_PX) + 1
        for run in np.split(order, gaps):
            if len(run) >= 4 and np.ptp(along[run]) >= min_length_px:
                ordered.append(remaining[best_inliers[run]])
                pieces.append((start, start + len(run)))
                start += len(run)
        remaining = np.delete(remaining, best_inliers)
    taken = np.concatenate(ordered) if ordered else np.zeros(0, dtype=np.int64)
    rest = np.setdiff1d(np.arange(len(points)), taken)
    return np.concatenate([taken, rest]).astype(np.int64)


def _order_along(points: np.ndarray) -> np.ndarray:
    """Indices ordering points along their principal direction."""
    centred = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)
    return np.argsort(centred @ vecs[:, 1], kind="stable")


def segments_of(chains: Chains, undistortion: Undistortion, min_length_px: float) -> Segments:
    """Straight pieces (undistorted frame) of every chain, at least `min_length_px` long."""
    rows = []
    for c in range(len(chains)):
        lo, hi = chains.start[c], chains.start[c + 1]
        pts = undistortion.apply(chains.points[lo:hi])
        order = _order_along(pts)
        pts = pts[order]
        ridge = chains.ridge[lo:hi][order]
        contrast = chains.contrast[lo:hi][order]
        pieces: list[tuple[int, int]] = []
        if _is_simple_curve(pts):
            _split(pts, pieces, 0, len(pts))
        else:
            # a web of lines joined at crossings: take its straight lines out one by one
            reorder = _straight_runs(pts, min_length_px, pieces)
            pts, ridge, contrast = pts[reorder], ridge[reorder], contrast[reorder]
        for p_lo, p_hi in pieces:
            piece = pts[p_lo:p_hi]
            if len(piece) < 4:
                continue
            mean = piece.mean(axis=0)
            centred = piece - mean
            vals, vecs = np.linalg.eigh(centred.T @ centred / len(piece))
            direction = vecs[:, 1]
            along = centred @ direction
            a = mean + along.min() * direction
            b = mean + along.max() * direction
            length = float(along.max() - along.min())
            if length < min_length_px:
                continue
            rows.append(
                (
                    *a,
                    *b,
                    -direction[1],
                    direction[0],
                    length,
                    float(len(piece)),
                    float(np.sqrt(max(vals[0], 0.0))),
                    float(ridge[p_lo:p_hi].mean()),
                    float(contrast[p_lo:p_hi].mean()),
                )
            )
    if not rows:
        empty = np.zeros((0, 2))
        z = np.zeros(0)
        return Segments(empty, empty, empty, z, z, z, z, z)
    arr = np.array(rows)
    order = np.argsort(-arr[:, 6], kind="stable")
    arr = arr[order]
    return Segments(
        a=arr[:, 0:2],
        b=arr[:, 2:4],
        normal=arr[:, 4:6],
        length_px=arr[:, 6],
        support_px=arr[:, 7],
        rms_px=arr[:, 8],
        ridge_share=arr[:, 9],
        contrast=arr[:, 10],
    )


@dataclass(frozen=True)
class ImageLines:
    """Infinite lines n . p = d (n unit, (L, 2); d (L,)) with the segments that support them.

    extent: (L, 2, 2) the two outermost supported points; support_px: (L,) total supported
    length; contrast: (L,) length-weighted mean contrast (delta E); ridge_share: (L,)
    length-weighted share of painted-line evidence; members: segment indices per line.
    """

    normal: np.ndarray
    offset: np.ndarray
    extent: np.ndarray
    support_px: np.ndarray
    contrast: np.ndarray
    ridge_share: np.ndarray
    members: tuple[tuple[int, ...], ...]

    def __len__(self) -> int:
        return int(self.normal.shape[0])

    def homogeneous(self) -> np.ndarray:
        """(L, 3) lines (a, b, c) with a x + b y + c = 0."""
        return np.column_stack([self.normal, -self.offset])

    def strength(self) -> np.ndarray:
        """(L,) how much a line looks like a court line: its length times its contrast relative
        to the image's typical line (capped at twice it). Plank seams, shadows and reflections
        are long too, but faint."""
        if len(self.support_px) == 0:
            return np.zeros(0)
        typical = float(np.median(self.contrast)) or 1.0
        return self.support_px * np.minimum(self.contrast / typical, 2.0)


def merge_collinear(segments: Segments) -> ImageLines:
    """Greedy merge, longest segment first: a segment joins a line when it runs the same way and
    both its endpoints lie on it (within MERGE_MAX_OFFSET_PX plus a share of the gap)."""
    lines: list[dict] = []
    for s in range(len(segments)):
        a, b = segments.a[s], segments.b[s]
        direction = (b - a) / max(segments.length_px[s], 1e-9)
        joined = False
        for line in lines:
            n = line["normal"]
            cross = abs(direction[0] * n[0] + direction[1] * n[1])  # sin of the angle between
            # a short piece's own direction is uncertain (ends good to about a pixel)
            allowed = MERGE_MAX_ANGLE_RAD + np.arctan(MERGE_MAX_OFFSET_PX / segments.length_px[s])
            if cross > np.sin(allowed):
                continue
            along = np.array([-n[1], n[0]])
            ends = np.array(line["extent"]) @ along
            ts = np.array([a @ along, b @ along])
            gap = max(0.0, max(ts.min() - ends.max(), ends.min() - ts.max()))
            limit = MERGE_MAX_OFFSET_PX + MERGE_OFFSET_PER_GAP * gap
            if abs(a @ n - line["offset"]) > limit or abs(b @ n - line["offset"]) > limit:
                continue
            line["points"].extend([a, b])
            line["weights"].extend([segments.length_px[s]] * 2)
            line["members"].append(s)
            line["support"] += segments.length_px[s]
            line["ridge"] += segments.length_px[s] * segments.ridge_share[s]
            line["contrast"] += segments.length_px[s] * segments.contrast[s]
            _refit(line)
            joined = True
            break
        if not joined:
            line = {
                "points": [a, b],
                "weights": [segments.length_px[s]] * 2,
                "members": [s],
                "support": float(segments.length_px[s]),
                "ridge": float(segments.length_px[s] * segments.ridge_share[s]),
                "contrast": float(segments.length_px[s] * segments.contrast[s]),
            }
            _refit(line)
            lines.append(line)
    if not lines:
        return ImageLines(
            np.zeros((0, 2)),
            np.zeros(0),
            np.zeros((0, 2, 2)),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0),
            (),
        )
    lines.sort(key=lambda line: -line["support"])
    return ImageLines(
        normal=np.array([line["normal"] for line in lines]),
        offset=np.array([line["offset"] for line in lines]),
        extent=np.array([line["extent"] for line in lines]),
        support_px=np.array([line["support"] for line in lines]),
        contrast=np.array([line["contrast"] / line["support"] for line in lines]),
        ridge_share=np.array([line["ridge"] / line["support"] for line in lines]),
        members=tuple(tuple(line["members"]) for line in lines),
    )


def _refit(line: dict) -> None:
    """Weighted total-least-squares line through the member endpoints; extent = outermost."""
    pts = np.array(line["points"])
    wts = np.array(line["weights"])
    mean = (pts * wts[:, None]).sum(axis=0) / wts.sum()
    centred = pts - mean
    cov = (centred * wts[:, None]).T @ centred
    _, vecs = np.linalg.eigh(cov)
    direction = vecs[:, 1]
    normal = np.array([-direction[1], direction[0]])
    along = centred @ direction
    line["normal"] = normal
    line["offset"] = float(mean @ normal)
    line["extent"] = [mean + along.min() * direction, mean + along.max() * direction]
