"""A global search for the camera with no start: hypotheses from line assignments, verified on the
evidence.

1. Vanishing groups. Court lines run in three directions; in the image the lines of one direction
   meet in a vanishing point (possibly at infinity). `vanishing_groups` finds up to five groups
   of image lines by consensus over pairwise intersections, one after the other;
   `vanishing_triads` finds triples of points of three orthogonal directions at once.
2. Floor hypotheses. Two lines of one group taken as two floor lines across the court (y constant:
   front junction, short line, box backs, back junction) and two of another as two floor lines
   along it (x constant: side junctions, box sides, half-court line) meet in four image points of
   a known floor rectangle, up to the assignment: a homography. With square pixels and the
   principal point at the image centre, a homography of a plane fixes the focal length and the
   pose, and over-determines them: the image quadrangle says what shape (aspect ratio) its floor
   rectangle has, and only assignments of model lines with that shape survive
   (`floor_hypotheses`). All image quadruples and all assignments are checked in one compiled
   call.
3. Front-wall hypotheses (`front_wall_hypotheses`), the anamorphic formats' variants of the
   floor hypotheses (`aspect_variants`) and typical placements (`candidate_starts`) add more.
4. The search stage (`search_cameras`): every hypothesis is ranked on the evidence (`verify`:
   the length of its court lines that land on evidence running the same way, against chance)
   and held to where cameras stand (`placement`); the best distinct ones are polished (a short
   fit, `refine`) and ranked again, and the best few go on to the refinement.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from app.calib import camera, parallel, placement, refine, segments, verify
from app.calib.court import COURT_SPECS, CourtModel, court_model
from app.calib.lines import EvidenceMaps, LineEvidence
from app.calib.placement import (
    FOCAL_RANGE_OF_WIDTH,
    HEIGHT_RANGE_M,
    MAX_DISTANCE_FROM_COURT_M,
    MAX_ROLL_RAD,
    held_upright,
    placed_plausibly,
)
from app.calib.segments import ImageLines, Undistortion

# Vanishing groups: lines considered, and the angle (rad) by which a line may miss a vanishing
# point, on top of what its length explains (endpoints good to ~1.5 px).
VANISHING_MAX_LINES = 100
VANISHING_MAX_ANGLE_RAD = np.deg2rad(1.5)
VANISHING_ENDPOINT_PX = 1.5
# Lines per group taken into quadruples; more in the second search (after a refusal), where a
# court's lines can rank below other long lines of their direction (a tiled floor outside a
# tripod's glass back wall, glass panes' frames): 16 lines make 2.7 times the quadruples of 10.
QUADRUPLE_LINES_PER_GROUP = 10
QUADRUPLE_LINES_PER_GROUP_SECOND_SEARCH = 16
# Two groups can be the court's two floor directions only if their vanishing points allow it
# (see `could_be_orthogonal`); the cosine margin allows for a principal point off centre.
ORTHOGONAL_VP_MAX_COS = 0.25
# ... and for a principal point anywhere in the picture (a cropped photo), given a vertical
OFF_CENTRE_VP_MAX_COS = 0.8
# A quadruple spanning less than this share of the image area pins a camera too poorly.
MIN_QUAD_AREA_SHARE = 0.002
# Consistency of a homography with a rotation: |cos| of the angle between the floor axes, and
# relative difference of their lengths.
MAX_AXES_COS = 0.06
MAX_AXES_LENGTH_RATIO = 0.10


@dataclass(frozen=True)
class VanishingGroup:
    """Lines (indices into ImageLines) through one vanishing point `point` (homogeneous (3,))."""

    point: np.ndarray
    lines: np.ndarray
    support_px: float


def _line_directions(lines: ImageLines) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    mid = lines.extent.mean(axis=1)
    direction = np.column_stack([-lines.normal[:, 1], lines.normal[:, 0]])
    length = np.linalg.norm(lines.extent[:, 1] - lines.extent[:, 0], axis=1)
    return mid, direction, length


def _consistency_matrix(
    vps: np.ndarray, mid: np.ndarray, direction: np.ndarray, length: np.ndarray
) -> np.ndarray:
    """bool (P, L): which lines point at which homogeneous vanishing points (P, 3)."""
    norm_xy = np.linalg.norm(vps[:, :2], axis=1)
    at_infinity = np.abs(vps[:, 2]) < 1e-9 * np.maximum(norm_xy, 1e-300)
    safe_w = np.where(at_infinity, 1.0, vps[:, 2])
    finite_pt = vps[:, :2] / safe_w[:, None]
    towards = finite_pt[:, None, :] - mid[None, :, :]
    towards = np.where(
        at_infinity[:, None, None],
        (vps[:, None, :2] / np.maximum(norm_xy, 1e-300)[:, None, None]),
        towards,
    )
    towards /= np.maximum(np.linalg.norm(towards, axis=2, keepdims=True), 1e-9)
    sin_angle = np.abs(
        towards[:, :, 0] * direction[None, :, 1] - towards[:, :, 1] * direction[None, :, 0]
    )
    allowed = VANISHING_MAX_ANGLE_RAD + np.arctan(
        2.0 * VANISHING_ENDPOINT_PX / np.maximum(length, 1)
    )
    return sin_angle <= np.sin(allowed)[None, :]


def vanishing_groups(lines: ImageLines, n_groups: int = 5) -> list[VanishingGroup]:
    """Up to `n_groups` groups of lines sharing a vanishing point, strongest support first.

    Found greedily (each new point by consensus among the lines not yet explained, over the
    intersections of all pairs of them), then every group takes all lines through its point: a
    line may belong to two groups (the half-court line of a centred camera runs through the
    points of the floor's and of the walls' directions). Court lines run in more than three
    image directions: the side walls' out lines slope, so they meet elsewhere than the floor's
    lines along the court.
    """
    count = min(len(lines), VANISHING_MAX_LINES)
    if count < 2:
        return []
    homog = lines.homogeneous()[:count]
    mid, direction, length = _line_directions(lines)
    mid, direction, length = mid[:count], direction[:count], length[:count]
    support = lines.support_px[:count]
    ii, jj = np.triu_indices(count, 1)
    pair_vps = np.cross(homog[ii], homog[jj])
    valid = np.any(pair_vps != 0, axis=1)
    pair_vps = pair_vps[valid]
    consistent = _consistency_matrix(pair_vps, mid, direction, length)
    free = np.ones(count, dtype=bool)
    points: list[np.ndarray] = []
    for _ in range(n_groups):
        members = consistent & free[None, :]
        scores = members.astype(np.float64) @ support
        enough = members.sum(axis=1) >= 2
        if not enough.any():
            break
        best = int(np.argmax(np.where(enough, scores, -1.0)))
        vp = pair_vps[best]
        chosen = members[best]
        # refit the point to its members: least squares over a x + b y + c w = 0
        _, _, vt = np.linalg.svd(homog[chosen] * support[chosen, None])
        refit = vt[-1]
        refit_members = _consistency_matrix(refit[None, :], mid, direction, length)[0] & free
        if refit_members.sum() >= 2:
            vp = refit
        points.append(vp)
        free &= ~_consistency_matrix(vp[None, :], mid, direction, length)[0]
    groups = []
    all_members: np.ndarray | list[np.ndarray] = (
        _consistency_matrix(np.array(points), mid, direction, length) if points else []
    )
    for vp, members in zip(points, all_members, strict=True):
        idx = np.flatnonzero(members)
        groups.append(VanishingGroup(vp, idx, float(support[idx].sum())))
    return groups


# Vanishing triads: candidate points (distinct consensus sets, best first) paired into triads,
# focal lengths tried when one of the pair lies at infinity (the pair then does not fix it),
# and how many distinct triads are kept.
TRIAD_CANDIDATE_POINTS = 40
TRIAD_FOCAL_STEPS = 12
TRIADS = 5
# Two consensus sets are the same when they share more than this share of the smaller one.
SAME_MEMBERS_SHARE = 0.5


def _same_members(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two bool member masks (L,) share more than SAME_MEMBERS_SHARE of the smaller."""
    smaller = min(int(a.sum()), int(b.sum()))
    return bool(smaller and (a & b).sum() > SAME_MEMBERS_SHARE * smaller)


def _toward_centred(vp: np.ndarray) -> tuple[np.ndarray, bool]:
    """Unit direction from the principal point towards a vanishing point given relative to it
    (homogeneous), and whether the point is finite."""
    norm_xy = float(np.linalg.norm(vp[:2]))
    if abs(vp[2]) < 1e-9 * norm_xy:
        return vp[:2] / norm_xy, False
    d = vp[:2] / vp[2]
    return d / max(float(np.linalg.norm(d)), 1e-300), True


def vanishing_triads(
    lines: ImageLines, image_size: tuple[int, int], n_triads: int = TRIADS
) -> list[tuple[VanishingGroup, VanishingGroup, VanishingGroup]]:
    """Up to `n_triads` distinct triples of vanishing points of three orthogonal directions (a
    square-pixel camera with its principal point at the centre), with the lines through each,
    best supported first.

    The greedy `vanishing_groups` takes each line for the first point it fits: the half-court
    line of a camera behind the court runs through the floor's and the walls' vertical points
    alike, a player's legs make a point of their own, and the few short lines along the court
    (box sides, half-court line) are then left without a group. Here two candidate points
    (consensus sets of pairwise intersections) fix the focal length, and with it the third
    direction's point; the triple is scored by the support of every line through any of the
    three. Two candidates at right angles with one at infinity do not fix the focal length:
    a grid of focal lengths is tried."""
    count = min(len(lines), VANISHING_MAX_LINES)
    if count < 3:
        return []
    width = image_size[0]
    centre = camera.picture_centre(image_size)
    to_centred = np.array([[1.0, 0.0, -centre[0]], [0.0, 1.0, -centre[1]], [0.0, 0.0, 1.0]])
    from_centred = np.linalg.inv(to_centred)
    homog = lines.homogeneous()[:count]
    mid, direction, length = _line_directions(lines)
    mid, direction, length = mid[:count], direction[:count], length[:count]
    support = lines.support_px[:count]
    ii, jj = np.triu_indices(count, 1)
    points = np.cross(homog[ii], homog[jj])
    points = points[np.any(points != 0, axis=1)]
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    consistent = _consistency_matrix(points, mid, direction, length)
    scores = consistent.astype(np.float64) @ support
    # any two lines meet somewhere: a point's evidence is the support of its lines beyond the
    # two strongest, and only points with more lines than that make triads
    by_support = np.where(consistent, support[None, :], 0.0)
    pair_support = np.sort(by_support, axis=1)[:, -2:].sum(axis=1)
    kept: list[int] = []
    for p in np.argsort(-scores, kind="stable"):
        if scores[p] <= 0.0 or len(kept) >= TRIAD_CANDIDATE_POINTS:
            break
        if consistent[p].sum() < 3 or any(
            _same_members(consistent[p], consistent[q]) for q in kept
        ):
            continue
        kept.append(int(p))
    focal_min, focal_max = (share * width for share in FOCAL_RANGE_OF_WIDTH)
    found: list[tuple[float, int, int, np.ndarray]] = []
    for ia, a in enumerate(kept):
        for b in kept[ia + 1 :]:
            va, vb = to_centred @ points[a], to_centred @ points[b]
            da, finite_a = _toward_centred(va)
            db, finite_b = _toward_centred(vb)
            if finite_a and finite_b:
                f2 = -float(va[:2] @ vb[:2]) / float(va[2] * vb[2])
                if not focal_min**2 <= f2 <= focal_max**2:
                    continue
                focals = np.array([np.sqrt(f2)])
            elif finite_a or finite_b:
                if abs(float(da @ db)) > MAX_AXES_COS:
                    continue
                focals = np.geomspace(focal_min, focal_max, TRIAD_FOCAL_STEPS)
            else:
                continue
            thirds = []
            for f in focals:
                k, k_inv = np.diag([f, f, 1.0]), np.diag([1.0 / f, 1.0 / f, 1.0])
                third = from_centred @ (k @ np.cross(k_inv @ va, k_inv @ vb))
                thirds.append(third / np.linalg.norm(third))
            through_third = _consistency_matrix(np.array(thirds), mid, direction, length)
            members = consistent[a] | consistent[b]
            totals = (members[None, :] | through_third).astype(np.float64) @ support
            # every focal length is a triad of its own: where it is free, the third point may
            # land on the lines of another direction, or on a player's legs
            for total, third in zip(totals, thirds, strict=True):
                found.append((float(total - pair_support[a] - pair_support[b]), a, b, third))
    found.sort(key=lambda item: -item[0])
    triads: list[tuple[VanishingGroup, VanishingGroup, VanishingGroup]] = []
    kept_masks: list[np.ndarray] = []
    for _, a, b, third in found:
        masks = np.vstack(
            [
                consistent[a],
                consistent[b],
                _consistency_matrix(third[None], mid, direction, length)[0],
            ]
        )
        # the same triad: the same three points
        if any(
            all(any(_same_members(m, other) for other in earlier) for m in masks)
            for earlier in kept_masks
        ):
            continue
        kept_masks.append(masks)
        triads.append(
            tuple(  # type: ignore[arg-type]
                VanishingGroup(vp, np.flatnonzero(m), float(support[m].sum()))
                for vp, m in zip((points[a], points[b], third), masks, strict=True)
            )
        )
        if len(triads) >= n_triads:
            break
    return triads


def floor_line_values(model: CourtModel) -> tuple[np.ndarray, np.ndarray]:
    """(y values of floor lines across the court, x values of floor lines along it), metres."""
    nodes = {name: model.node(name) for name in model.node_names}
    across = sorted(
        {
            float(nodes["floor_front_left"][1]),
            float(nodes["T"][1]),
            float(nodes["box_left_inner_back"][1]),
            float(nodes["floor_back_left"][1]),
        }
    )
    along = sorted(
        {
            float(nodes["floor_front_left"][0]),
            float(nodes["box_left_short"][0]),
            float(nodes["T"][0]),
            float(nodes["box_right_short"][0]),
            float(nodes["floor_front_right"][0]),
        }
    )
    return np.array(across), np.array(along)


@numba.njit(cache=True)
def _square_to_quad(q: np.ndarray) -> np.ndarray:
    """Homography (3, 3) mapping (0,0), (1,0), (0,1), (1,1) to q[0], q[1], q[2], q[3] (Heckbert)."""
    x0, y0 = q[0, 0], q[0, 1]
    x1, y1 = q[1, 0], q[1, 1]
    x2, y2 = q[3, 0], q[3, 1]  # (1, 1)
    x3, y3 = q[2, 0], q[2, 1]  # (0, 1)
    sx = x0 - x1 + x2 - x3
    sy = y0 - y1 + y2 - y3
    h = np.zeros((3, 3))
    if sx == 0.0 and sy == 0.0:
        h[0, 0], h[0, 1], h[0, 2] = x1 - x0, x3 - x0, x0
        h[1, 0], h[1, 1], h[1, 2] = y1 - y0, y3 - y0, y0
        h[2, 2] = 1.0
        return h
    dx1, dx2 = x1 - x2, x3 - x2
    dy1, dy2 = y1 - y2, y3 - y2
    det = dx1 * dy2 - dx2 * dy1
    if det == 0.0:
        return h
    g = (sx * dy2 - dx2 * sy) / det
    hh = (dx1 * sy - sx * dy1) / det
    h[0, 0], h[0, 1], h[0, 2] = x1 - x0 + g * x1, x3 - x0 + hh * x3, x0
    h[1, 0], h[1, 1], h[1, 2] = y1 - y0 + g * y1, y3 - y0 + hh * y3, y0
    h[2, 0], h[2, 1], h[2, 2] = g, hh, 1.0
    return h


@numba.njit(cache=True)
def _intersect(l1: np.ndarray, l2: np.ndarray) -> tuple[float, float, bool]:
    x = l1[1] * l2[2] - l1[2] * l2[1]
    y = l1[2] * l2[0] - l1[0] * l2[2]
    w = l1[0] * l2[1] - l1[1] * l2[0]
    if abs(w) < 1e-12:
        return 0.0, 0.0, False
    return x / w, y / w, True


@numba.njit(cache=True, inline="always")
def _axes_consistent(h: np.ndarray, f: float, max_cos: float, max_length_ratio: float) -> bool:
    """Whether a plane homography (pixels relative to the principal point) under focal length f
    has orthogonal axes (|cos| <= max_cos) of equal length (to max_length_ratio)."""
    r1x, r1y, r1z = h[0, 0] / f, h[1, 0] / f, h[2, 0]
    r2x, r2y, r2z = h[0, 1] / f, h[1, 1] / f, h[2, 1]
    n1 = np.sqrt(r1x * r1x + r1y * r1y + r1z * r1z)
    n2 = np.sqrt(r2x * r2x + r2y * r2y + r2z * r2z)
    if n1 == 0.0 or n2 == 0.0:
        return False
    if abs((r1x * r2x + r1y * r2y + r1z * r2z) / (n1 * n2)) > max_cos:
        return False
    return abs(n1 / n2 - 1.0) <= max_length_ratio


@numba.njit(cache=True, inline="always")
def _focal_of_plane_homography(h: np.ndarray, focal_min: float, focal_max: float) -> float:
    """Focal length (px) of the homography `h` of a model plane (plane (a, b, 1) -> image pixels
    relative to the principal point, a and b orthogonal metric axes) under square pixels, or -1
    if it is not that of a rotation. How the camera is held is left to the caller: which axis is
    down differs between the floor and a wall.

    With K = diag(f, f, 1), K^-1 h = s [r1 r2 t]. Two conditions on r1, r2 are linear in
    u = 1 / f^2: the floor axes are orthogonal (cos = e1 / (n1 n2)) and equally long
    ((n1^2 - n2^2) / (n1^2 + n2^2) = e2 / N); with n1 ~ n2, n1 n2 ~ N / 2, so weights 2 and 1
    make them comparable. Either may be degenerate on its own (the first when the court's
    across lines are parallel in the image), not both for a camera that sees the plane at an
    angle.
    """
    b1x, b1y, c1 = h[0, 0], h[1, 0], h[2, 0]
    b2x, b2y, c2 = h[0, 1], h[1, 1], h[2, 1]
    e1a = 2.0 * (b1x * b2x + b1y * b2y)
    e1b = 2.0 * c1 * c2
    e2a = b1x * b1x + b1y * b1y - b2x * b2x - b2y * b2y
    e2b = c1 * c1 - c2 * c2
    denom = e1a * e1a + e2a * e2a
    if denom <= 0.0:
        return -1.0
    u = -(e1a * e1b + e2a * e2b) / denom
    if u <= 0.0:
        return -1.0
    f = 1.0 / np.sqrt(u)
    if f < focal_min or f > focal_max:
        return -1.0
    if not _axes_consistent(h, f, MAX_AXES_COS, MAX_AXES_LENGTH_RATIO):
        return -1.0
    return f


@numba.njit(cache=True, inline="always")
def _focal_of_floor_homography(h: np.ndarray, focal_min: float, focal_max: float) -> float:
    """Focal length (px) of a floor homography `h` (court floor (x, y, 1) -> image pixels relative
    to the principal point) under square pixels, or -1 if it is not that of a rotation or of a
    camera held as people film."""
    f = _focal_of_plane_homography(h, focal_min, focal_max)
    if f <= 0.0:
        return -1.0
    r1x, r1y, r1z = h[0, 0] / f, h[1, 0] / f, h[2, 0]
    r2x, r2y, r2z = h[0, 1] / f, h[1, 1] / f, h[2, 1]
    n1 = np.sqrt(r1x * r1x + r1y * r1y + r1z * r1z)
    n2 = np.sqrt(r2x * r2x + r2y * r2y + r2z * r2z)
    # how the camera is held (either sign of the homography's scale): r1, r2 are the court's x
    # and y axes in camera coordinates, so the court's down axis is their cross product
    ux, uy, uz = r1x / n1, r1y / n1, r1z / n1
    vx, vy, vz = r2x / n2, r2y / n2, r2z / n2
    dx = uy * vz - uz * vy
    dy = uz * vx - ux * vz
    dz = ux * vy - uy * vx
    if not held_upright(dx, dy, dz) and not held_upright(-dx, -dy, -dz):
        return -1.0
    return f


@numba.njit(cache=True, inline="always")
def _orthonormal_axes(
    m: np.ndarray,
) -> tuple[float, float, float, float, float, float, float, float, float]:
    """The nearest pair of orthonormal axes (u, v) to the first two columns of a normalised plane
    homography m = K^-1 H (plane (a, b, 1) -> normalised camera coordinates, up to scale), and
    the translation t = m's third column over the scale: (ux, uy, uz, vx, vy, vz, tx, ty, tz).

    Polar decomposition: the mismatch of a homography from slightly misplaced lines is shared
    by both axes, not all put on one. Q = M (M^T M)^(-1/2), with the square root of the 2 x 2
    Gram matrix in closed form; the scale is the mean singular value (half its trace)."""
    ax, ay, az = m[0, 0], m[1, 0], m[2, 0]
    bx, by, bz = m[0, 1], m[1, 1], m[2, 1]
    g11 = ax * ax + ay * ay + az * az
    g12 = ax * bx + ay * by + az * bz
    g22 = bx * bx + by * by + bz * bz
    root_det = np.sqrt(max(g11 * g22 - g12 * g12, 1e-300))
    norm = np.sqrt(g11 + g22 + 2.0 * root_det)
    s11, s12, s22 = (g11 + root_det) / norm, g12 / norm, (g22 + root_det) / norm  # G^(1/2)
    det_s = s11 * s22 - s12 * s12
    i11, i12, i22 = s22 / det_s, -s12 / det_s, s11 / det_s  # G^(-1/2)
    ux, uy, uz = ax * i11 + bx * i12, ay * i11 + by * i12, az * i11 + bz * i12
    vx, vy, vz = ax * i12 + bx * i22, ay * i12 + by * i22, az * i12 + bz * i22
    scale = 0.5 * (s11 + s22)
    return ux, uy, uz, vx, vy, vz, m[0, 2] / scale, m[1, 2] / scale, m[2, 2] / scale


@numba.njit(cache=True)
def _pose_from_normalised(
    m: np.ndarray,
    height_min: float,
    height_max: float,
    max_distance: float,
    court_centre: np.ndarray,
    court_size: np.ndarray,
    anchor: np.ndarray,
    out_r: np.ndarray,
    out_t: np.ndarray,
) -> bool:
    """Pose (R, t written to out_r, out_t) of a normalised floor homography m = K^-1 H (court floor
    (x, y, 1) -> normalised camera coordinates, up to scale); False if the camera is not upright
    or implausibly placed. `anchor` (2,) is a floor point that must be in front of the camera."""
    ux, uy, uz, vx, vy, vz, tx, ty, tz = _orthonormal_axes(m)
    # the sign of the scale: the anchor must be in front of the camera
    if uz * anchor[0] + vz * anchor[1] + tz < 0.0:
        ux, uy, uz = -ux, -uy, -uz
        vx, vy, vz = -vx, -vy, -vz
        tx, ty, tz = -tx, -ty, -tz
    # the court's x and y axes in camera coordinates; down (z) is their cross product
    wx = uy * vz - uz * vy
    wy = uz * vx - ux * vz
    wz = ux * vy - uy * vx
    if not held_upright(wx, wy, wz):
        return False
    out_r[0, 0], out_r[1, 0], out_r[2, 0] = ux, uy, uz
    out_r[0, 1], out_r[1, 1], out_r[2, 1] = vx, vy, vz
    out_r[0, 2], out_r[1, 2], out_r[2, 2] = wx, wy, wz
    out_t[0], out_t[1], out_t[2] = tx, ty, tz
    return placed_plausibly(
        out_r, out_t, height_min, height_max, max_distance, court_centre, court_size
    )


@numba.njit(cache=True)
def _pose_from_front_wall(
    m: np.ndarray,
    height_min: float,
    height_max: float,
    max_distance: float,
    court_centre: np.ndarray,
    court_size: np.ndarray,
    out_r: np.ndarray,
    out_t: np.ndarray,
) -> bool:
    """Pose of a normalised front-wall homography m = K^-1 H (front wall (x, z, 1) -> normalised
    camera coordinates, up to scale), as `_pose_from_normalised`; the camera must look at the
    wall's painted (court) side."""
    ux, uy, uz, vx, vy, vz, tx, ty, tz = _orthonormal_axes(m)
    # the wall's centre (x = width / 2, 1 m up) must be in front of the camera
    if uz * 0.5 * court_size[0] - vz + tz < 0.0:
        ux, uy, uz = -ux, -uy, -uz
        vx, vy, vz = -vx, -vy, -vz
        tx, ty, tz = -tx, -ty, -tz
    # u, v are the court's x and z (down) axes in camera coordinates; y = z cross x
    if not held_upright(vx, vy, vz):
        return False
    wx = vy * uz - vz * uy
    wy = vz * ux - vx * uz
    wz = vx * uy - vy * ux
    out_r[0, 0], out_r[1, 0], out_r[2, 0] = ux, uy, uz
    out_r[0, 1], out_r[1, 1], out_r[2, 1] = wx, wy, wz
    out_r[0, 2], out_r[1, 2], out_r[2, 2] = vx, vy, vz
    out_t[0], out_t[1], out_t[2] = tx, ty, tz
    # the camera is on the court's side of the front wall (y > 0)
    if -(wx * tx + wy * ty + wz * tz) <= 0.0:
        return False
    return placed_plausibly(
        out_r, out_t, height_min, height_max, max_distance, court_centre, court_size
    )


@numba.njit(cache=True, inline="always")
def _conic_row(p: np.ndarray, q: np.ndarray, row: np.ndarray, square: bool) -> None:
    """Coefficients of p^T w q in the image-of-the-absolute-conic unknowns: w = [[a, 0, d],
    [0, b, e], [d, e, g]] (zero skew); with `square`, a = b is one unknown (row: a, d, e, g),
    else the principal point is the origin, d = e = 0 (row: a, b, g)."""
    if square:
        row[0] = p[0] * q[0] + p[1] * q[1]
        row[1] = p[0] * q[2] + p[2] * q[0]
        row[2] = p[1] * q[2] + p[2] * q[1]
        row[3] = p[2] * q[2]
    else:
        row[0] = p[0] * q[0]
        row[1] = p[1] * q[1]
        row[2] = p[2] * q[2]


@numba.njit(cache=True)
def _intrinsics_with_vertical(
    hu1: np.ndarray,
    hu2: np.ndarray,
    ratio2: float,
    vertical: np.ndarray,
    square: bool,
    unit_px: float,
    out: np.ndarray,
) -> bool:
    """Intrinsics (fx, fy, cx, cy relative to the image centre) written to `out` of the camera
    whose floor's x and y directions image as `hu1` / dx and `hu2` / dy (a floor homography's
    first two columns, pixels relative to the image centre; ratio2 = (dx / dy)^2) and whose
    vertical images as `vertical`, when the principal point is unknown (`square`: square
    pixels) or the pixels are not square (principal point at the centre). False if none.

    The court's x, y and z axes are orthogonal and x, y equally long on the floor: with w the
    image of the absolute conic, h1' w h2 = 0, h1' w h1 = h2' w h2, v' w h1 = 0, v' w h2 = 0:
    four linear equations in w's unknowns (zero skew), solved in the least-squares sense
    (smallest singular vector) and refused when they disagree. Pixels are measured in `unit_px`
    (about a focal length) so w's entries are comparable, and each equation is weighted by the
    size of its vectors, not by its own coefficients: an equation that nearly holds for every w
    (x orthogonal to y for a camera looking straight down the court) stays small instead of
    being blown up into a constraint.
    """
    n = 4 if square else 3
    p1 = hu1.copy()
    p2 = hu2.copy()
    v = vertical.copy()
    for vec in (p1, p2, v):
        vec[0] /= unit_px
        vec[1] /= unit_px
    # one scale for h1 and h2 (their relative size is what equal length is about)
    size = max(np.sqrt(np.sum(p1 * p1)), np.sqrt(np.sum(p2 * p2)))
    p1 /= size
    p2 /= size
    v /= np.sqrt(np.sum(v * v))
    a = np.zeros((4, n))
    row = np.empty(n)
    tmp = np.empty(n)
    _conic_row(p1, p2, row, square)
    a[0] = row
    _conic_row(p1, p1, row, square)
    _conic_row(p2, p2, tmp, square)
    a[1] = (row - ratio2 * tmp) / (1.0 + ratio2)
    _conic_row(v, p1, row, square)
    a[2] = row
    _conic_row(v, p2, row, square)
    a[3] = row
    _, sv, vt = np.linalg.svd(a)
    w = vt[-1]
    if sv[-1] > ALTERNATIVE_MAX_DISAGREEMENT * sv[0]:
        return False  # the four conditions disagree: not a consistent camera
    if w[0] < 0.0:
        w = -w
    if square:
        # back from unit_px units: a / unit^2, d / unit, e / unit, g
        wa, wd, we, wg = w[0] / unit_px**2, w[1] / unit_px, w[2] / unit_px, w[3]
        if wa <= 0.0:
            return False
        lam = wg - (wd * wd + we * we) / wa
        if lam <= 0.0:
            return False
        out[0] = out[1] = np.sqrt(lam / wa)
        out[2] = -wd / wa
        out[3] = -we / wa
    else:
        wa, wb, wg = w[0] / unit_px**2, w[1] / unit_px**2, w[2]
        if wa <= 0.0 or wb <= 0.0 or wg <= 0.0:
            return False
        out[0] = np.sqrt(wg / wa)
        out[1] = np.sqrt(wg / wb)
        out[2] = 0.0
        out[3] = 0.0
    return True


@numba.njit(cache=True, inline="always")
def _unit_square_homography(
    a1: np.ndarray,
    a2: np.ndarray,
    b1: np.ndarray,
    b2: np.ndarray,
    centre: np.ndarray,
    limit: float,
    min_area: float,
    quad: np.ndarray,
) -> np.ndarray:
    """Homography (3, 3) from the unit square (X' from line b1 to b2, Y' from a1 to a2) to the
    quadrangle where the lines meet (pixels relative to `centre`), or zeros when a corner is
    missing or beyond `limit` px or the quadrangle is smaller than `min_area` (it pins nothing).
    `quad` (4, 2) is scratch space."""
    corners = ((a1, b1), (a1, b2), (a2, b1), (a2, b2))
    for m in range(4):
        la, lb = corners[m]
        x, y, good = _intersect(la, lb)
        if not good or abs(x - centre[0]) > limit or abs(y - centre[1]) > limit:
            return np.zeros((3, 3))
        quad[m, 0] = x - centre[0]
        quad[m, 1] = y - centre[1]
    # shoelace over corners 0, 1, 3, 2
    area = 0.5 * abs(
        (quad[0, 0] * quad[1, 1] - quad[1, 0] * quad[0, 1])
        + (quad[1, 0] * quad[3, 1] - quad[3, 0] * quad[1, 1])
        + (quad[3, 0] * quad[2, 1] - quad[2, 0] * quad[3, 1])
        + (quad[2, 0] * quad[0, 1] - quad[0, 0] * quad[2, 1])
    )
    if area < min_area:
        return np.zeros((3, 3))
    return _square_to_quad(quad)


@numba.njit(cache=True, inline="always")
def _rectangle_homography(
    hu: np.ndarray, a0: float, da: float, b0: float, db: float, out: np.ndarray
) -> None:
    """The homography of a model rectangle (a0 .. a0 + da, b0 .. b0 + db) into `out`, from that of
    the unit square `hu`: H = hu A with A: (a, b) -> ((a - a0) / da, (b - b0) / db)."""
    for row in range(3):
        out[row, 0] = hu[row, 0] / da
        out[row, 1] = hu[row, 1] / db
        out[row, 2] = hu[row, 2] - a0 * out[row, 0] - b0 * out[row, 1]


@numba.njit(cache=True)
def _alternative_intrinsics(
    hu: np.ndarray,
    ratios2: np.ndarray,
    orthogonal_vp: np.ndarray,
    width: float,
    height: float,
    focal_min: float,
    focal_max: float,
    alt_k: np.ndarray,
    alt_ratio2: np.ndarray,
) -> int:
    """Intrinsics other than square pixels at the centre for the plane rectangle whose unit
    square images as `hu` (pixels relative to the centre) and whose normal's vanishing point is
    `orthogonal_vp`, under every span ratio in `ratios2`: a free principal point (a cropped
    photo; kept when it is off the centre by ALTERNATIVE_MIN_OFFSET_SHARE of the width) and
    non-square pixels (an anamorphic frame; kept when the aspect differs from 1 by
    ALTERNATIVE_MIN_ASPECT_CHANGE). Written to alt_k, alt_ratio2; returns the count."""
    k = np.empty(4)
    n_alt = 0
    for u in range(ratios2.shape[0]):
        for square in (True, False):
            if not _intrinsics_with_vertical(
                hu[:, 0].copy(), hu[:, 1].copy(), ratios2[u], orthogonal_vp, square, width, k
            ):
                continue
            if not (focal_min <= k[0] <= focal_max):
                continue
            if square:
                shift = np.sqrt(k[2] * k[2] + k[3] * k[3])
                if shift < ALTERNATIVE_MIN_OFFSET_SHARE * width:
                    continue
                if abs(k[2]) > 0.5 * width or abs(k[3]) > 0.5 * height:
                    continue
            else:
                aspect = k[1] / k[0]
                if abs(aspect - 1.0) < ALTERNATIVE_MIN_ASPECT_CHANGE or not (
                    ASPECT_RANGE[0] <= aspect <= ASPECT_RANGE[1]
                ):
                    continue
            alt_k[n_alt] = k
            alt_ratio2[n_alt] = ratios2[u]
            n_alt += 1
    return n_alt


@numba.njit(cache=True, nogil=True)
def _hypotheses_njit(
    across_lines: np.ndarray,
    along_lines: np.ndarray,
    across_values: np.ndarray,
    along_values: np.ndarray,
    centre: np.ndarray,
    width: float,
    height: float,
    focal_min: float,
    focal_max: float,
    min_area: float,
    vertical: np.ndarray,
    n_alt_lines: int,
    ratios2: np.ndarray,
    square_centred: bool,
    out_h: np.ndarray,
    out_k: np.ndarray,
) -> int:
    """Every quadruple of two `across_lines` and two `along_lines` (homogeneous, (n, 3)) under
    every assignment of floor line values: floor homographies (court floor -> pixels relative
    to the image centre) consistent with a camera held as people film are written to out_h with
    their intrinsics (fx, fy, cx, cy relative to the centre) in out_k; returns the count.

    Square pixels with the principal point at the centre are tried for every homography; when a
    `vertical` vanishing point is given (homogeneous, relative to the centre; zeros for none),
    also a free principal point (a cropped photo) and non-square pixels (an anamorphic frame),
    kept when they differ from the first by more than ALTERNATIVE_MIN_OFFSET_SHARE of the width
    or ALTERNATIVE_MIN_ASPECT_CHANGE.
    """
    n_a = across_lines.shape[0]
    n_b = along_lines.shape[0]
    n_out = 0
    cap = out_h.shape[0]
    limit = 3.0 * max(width, height)
    quad = np.empty((4, 2))
    hm = np.empty((3, 3))
    alt_k = np.empty((2 * ratios2.shape[0], 4))
    alt_ratio2 = np.empty(2 * ratios2.shape[0])
    with_vertical = vertical[0] != 0.0 or vertical[1] != 0.0 or vertical[2] != 0.0
    for i in range(n_a):
        for j in range(i + 1, n_a):
            for kk in range(n_b):
                for ll in range(kk + 1, n_b):
                    # unit square (X' along the `along` pair kk->ll, Y' across i->j) -> image
                    hu = _unit_square_homography(
                        across_lines[i],
                        across_lines[j],
                        along_lines[kk],
                        along_lines[ll],
                        centre,
                        limit,
                        min_area,
                        quad,
                    )
                    if hu[2, 2] == 0.0:
                        continue
                    # intrinsics other than square pixels at the centre, from the vertical, for
                    # the quadrangles of the strongest lines; they depend on the quadrangle and
                    # the ratio of the assignment's x and y spans only
                    n_alt = 0
                    if with_vertical and max(i, j, kk, ll) < n_alt_lines:
                        n_alt = _alternative_intrinsics(
                            hu,
                            ratios2,
                            vertical,
                            width,
                            height,
                            focal_min,
                            focal_max,
                            alt_k,
                            alt_ratio2,
                        )
                    for p in range(across_values.shape[0]):
                        for q in range(across_values.shape[0]):
                            if p == q:
                                continue
                            dy = across_values[q] - across_values[p]
                            yp = across_values[p]
                            for r in range(along_values.shape[0]):
                                for s in range(along_values.shape[0]):
                                    if r == s:
                                        continue
                                    dx = along_values[s] - along_values[r]
                                    xr = along_values[r]
                                    _rectangle_homography(hu, xr, dx, yp, dy, hm)
                                    f = -1.0
                                    if square_centred:
                                        f = _focal_of_floor_homography(hm, focal_min, focal_max)
                                    if f > 0.0:
                                        if n_out >= cap:
                                            return n_out
                                        out_h[n_out] = hm
                                        out_k[n_out, 0] = f
                                        out_k[n_out, 1] = f
                                        out_k[n_out, 2] = 0.0
                                        out_k[n_out, 3] = 0.0
                                        n_out += 1
                                    for alt in range(n_alt):
                                        if (
                                            abs((dx * dx) / (dy * dy) / alt_ratio2[alt] - 1.0)
                                            > 1e-9
                                        ):
                                            continue
                                        if n_out >= cap:
                                            return n_out
                                        out_h[n_out] = hm
                                        out_k[n_out] = alt_k[alt]
                                        n_out += 1
    return n_out


@numba.njit(cache=True, nogil=True)
def _poses_njit(
    homographies: np.ndarray,
    intrinsics: np.ndarray,
    height_min: float,
    height_max: float,
    max_distance: float,
    court_centre: np.ndarray,
    court_size: np.ndarray,
    out_r: np.ndarray,
    out_t: np.ndarray,
) -> np.ndarray:
    """Poses of floor homographies (N, 3, 3) (pixels relative to the image centre) under their
    intrinsics (N, 4) (fx, fy, cx, cy relative to the centre); returns which are plausible."""
    ok = np.zeros(homographies.shape[0], dtype=np.bool_)
    m = np.empty((3, 3))
    for i in range(homographies.shape[0]):
        fx, fy, cx, cy = intrinsics[i, 0], intrinsics[i, 1], intrinsics[i, 2], intrinsics[i, 3]
        h = homographies[i]
        for c in range(3):
            m[0, c] = (h[0, c] - cx * h[2, c]) / fx
            m[1, c] = (h[1, c] - cy * h[2, c]) / fy
            m[2, c] = h[2, c]
        ok[i] = _pose_from_normalised(
            m,
            height_min,
            height_max,
            max_distance,
            court_centre,
            court_size,
            court_centre,
            out_r[i],
            out_t[i],
        )
    return ok


MAX_HYPOTHESES = 400_000
DISTINCT_HOMOGRAPHY_SHARE = 0.008
# Alternative intrinsics from a vertical vanishing point (see `_hypotheses_njit`): how far they
# must differ from square pixels at the centre to be worth a hypothesis, and the aspect ratios
# (f_v / f_u) a frame may have (anamorphic broadcast: 0.75).
ALTERNATIVE_MIN_OFFSET_SHARE = 0.04
ALTERNATIVE_MIN_ASPECT_CHANGE = 0.05
ASPECT_RANGE = (0.65, 1.5)
# They are tried on the quadrangles of this many strongest lines per group, and refused when the
# four conditions disagree (smallest over largest singular value).
ALTERNATIVE_LINES_PER_GROUP = 7
ALTERNATIVE_MAX_DISAGREEMENT = 0.05


def genomes_from_poses(
    intrinsics: np.ndarray,
    rotations: np.ndarray,
    translations: np.ndarray,
    image_size: tuple[int, int],
    undistortion: Undistortion | None,
) -> np.ndarray:
    """Genomes (N, 15) of cameras with intrinsics (N, 4) (fx, fy, cx, cy relative to the image
    centre; or (N,) focal lengths: square pixels at the centre), court-frame pose
    (X_cam = R X + t), and the radial terms the division model amounts to."""
    k = np.asarray(intrinsics, dtype=np.float64)
    if k.ndim == 1:
        k = np.column_stack([k, k, np.zeros_like(k), np.zeros_like(k)])
    n = len(k)
    genomes = np.zeros((n, camera.N_GENES))
    genomes[:, 0], genomes[:, 1] = k[:, 0], k[:, 1]
    centre = camera.picture_centre(image_size)
    genomes[:, 2] = centre[0] + k[:, 2]
    genomes[:, 3] = centre[1] + k[:, 3]
    genomes[:, 7:10] = camera.angles_from_rotations(rotations @ camera.PAPER_FROM_COURT_R.T)
    genomes[:, 4:7] = translations + rotations @ camera.PAPER_ORIGIN_COURT_M
    if undistortion is not None and undistortion.lam != 0.0:
        # division model r_u = r_d / (1 + lam r_d^2) inverted to second order:
        # r_d = r_u (1 + lam r_u^2 + 2 lam^2 r_u^4), radii in units of R; in focal units:
        ratio2 = (k[:, 0] / undistortion.radius_px) ** 2
        genomes[:, camera.GENE["k1"]] = undistortion.lam * ratio2
        genomes[:, camera.GENE["k2"]] = 2.0 * undistortion.lam**2 * ratio2**2
    return genomes


# Anamorphic frames (f_v / f_u != 1). A camera facing down the court images the floor as a
# near-symmetric trapezoid, which a square-pixel camera fits as well as the true one (stretching
# the picture sideways is matched by another height, tilt and focal length): the floor lines
# propose the camera with square pixels, and its walls miss. So the floor hypotheses are also
# tried under the aspects of the two anamorphic formats, and the walls decide: a 4:3 picture
# stretched to 16:9 (f_v / f_u = 3/4) and a 16:9 picture squeezed into 4:3 storage, as HDV's
# 1440 x 1080 (4/3). Aspects near these are reached by the fit, which frees the aspect of a
# camera hypothesised with one. (A 10% grid over 0.68-1.46 gave the wrong cameras of zoomed
# views more aspects to choose from: on bench.synthetic one of them was accepted 7 m off.)
ANAMORPHIC_ASPECTS = (0.75, 4.0 / 3.0)


@numba.njit(cache=True, nogil=True)
def _aspect_focals_njit(
    homographies: np.ndarray, aspects: np.ndarray, focal_min: float, focal_max: float
) -> np.ndarray:
    """focal_u (N, A) of each floor homography (pixels relative to the principal point) under
    each pixel aspect f_v / f_u, or -1 where no camera held as people film has it."""
    out = np.full((homographies.shape[0], aspects.shape[0]), -1.0)
    h = np.empty((3, 3))
    for i in range(homographies.shape[0]):
        for a in range(aspects.shape[0]):
            for c in range(3):
                h[0, c] = homographies[i, 0, c]
                h[1, c] = homographies[i, 1, c] / aspects[a]
                h[2, c] = homographies[i, 2, c]
            out[i, a] = _focal_of_floor_homography(h, focal_min, focal_max)
    return out


def aspect_variants(
    genomes: np.ndarray, model: CourtModel, image_size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """The cameras (M, 15) that image the floor as the square-pixel, centred cameras among
    `genomes` do, under each of ANAMORPHIC_ASPECTS, and for each the row of `genomes` it came
    from (M,). The radial terms keep their effect along the picture's width."""
    pop = camera.as_population(genomes)
    width = image_size[0]
    centre = camera.picture_centre(image_size)
    square = (
        (np.abs(pop[:, 1] / pop[:, 0] - 1.0) < 1e-9)
        & (np.abs(pop[:, 2] - centre[0]) < 1e-6)
        & (np.abs(pop[:, 3] - centre[1]) < 1e-6)
    )
    rows = np.flatnonzero(square)
    if not len(rows):
        return np.zeros((0, camera.N_GENES)), np.zeros(0, dtype=np.int64)
    base = pop[rows]
    r, t = camera.court_extrinsics(base)
    homographies = np.stack([r[:, :, 0], r[:, :, 1], t], axis=2)
    homographies[:, :2, :] *= base[:, :2, None]
    aspects = np.array(ANAMORPHIC_ASPECTS)
    focals = _aspect_focals_njit(
        np.ascontiguousarray(homographies),
        aspects,
        FOCAL_RANGE_OF_WIDTH[0] * width,
        FOCAL_RANGE_OF_WIDTH[1] * width,
    )
    which, a = np.nonzero(focals > 0.0)
    if not len(which):
        return np.zeros((0, camera.N_GENES)), np.zeros(0, dtype=np.int64)
    f_u = focals[which, a]
    intrinsics = np.column_stack([f_u, aspects[a] * f_u, np.zeros_like(f_u), np.zeros_like(f_u)])
    out_r = np.empty((len(which), 3, 3))
    out_t = np.empty((len(which), 3))
    ok = _poses_njit(
        np.ascontiguousarray(homographies[which]),
        intrinsics,
        HEIGHT_RANGE_M[0],
        HEIGHT_RANGE_M[1],
        MAX_DISTANCE_FROM_COURT_M,
        np.array([model.spec.width_m / 2.0, model.spec.length_m / 2.0]),
        np.array([model.spec.width_m, model.spec.length_m]),
        out_r,
        out_t,
    )
    variants = genomes_from_poses(intrinsics[ok], out_r[ok], out_t[ok], image_size, None)
    source = base[which[ok]]
    scale2 = (variants[:, 0] / source[:, 0]) ** 2
    for gene, power in (("k1", 1), ("k2", 2), ("k3", 3)):
        variants[:, camera.GENE[gene]] = source[:, camera.GENE[gene]] * scale2**power
    return variants, rows[which[ok]]


def could_be_orthogonal(
    vp_a: np.ndarray,
    vp_b: np.ndarray,
    centre: np.ndarray,
    width: float,
    max_cos: float = ORTHOGONAL_VP_MAX_COS,
) -> bool:
    """Whether two vanishing points (homogeneous) can be the images of two orthogonal directions
    for a square-pixel camera whose principal point is near `centre`: (v_a - c).(v_b - c) =
    -f^2 w_a w_b, so the vectors from c towards them must make an angle of at least ~90 degrees
    (exactly 90 when one is at infinity), with a margin for a principal point off centre."""

    def toward(vp: np.ndarray) -> tuple[np.ndarray, bool]:
        if abs(vp[2]) < 1e-9 * np.linalg.norm(vp[:2]):
            return vp[:2] / np.linalg.norm(vp[:2]), True
        d = vp[:2] / vp[2] - centre
        n = np.linalg.norm(d)
        return (d / n if n > 0 else d), False

    da, inf_a = toward(vp_a)
    db, inf_b = toward(vp_b)
    if inf_a and inf_b:
        return True  # a camera looking straight down
    cos = float(da @ db)
    if inf_a or inf_b:
        return abs(cos) <= max_cos
    return cos <= max_cos


def strongest(members: np.ndarray, strength: np.ndarray, count: int) -> np.ndarray:
    """The `count` members with the greatest strength, strongest first."""
    order = np.argsort(-strength[members], kind="stable")
    return members[order[:count]]


def floor_hypotheses(
    lines: ImageLines,
    groups: list[VanishingGroup],
    model: CourtModel,
    image_size: tuple[int, int],
    undistortion: Undistortion | None,
    triads: list[tuple[VanishingGroup, VanishingGroup, VanishingGroup]] | None = None,
    lines_per_group: int = QUADRUPLE_LINES_PER_GROUP,
) -> np.ndarray:
    """Plausible cameras (N, 15) from every pair of groups taken as (across, along) floor
    lines (see the module doc), the `lines_per_group` strongest of each group taken into
    quadruples; a third group that can be the vertical adds cameras with a free principal point
    and with non-square pixels. The two floor directions of each of the `triads`
    (`vanishing_triads`) are tried as well, for square pixels at the centre, where they are not
    already a pair of `groups`."""
    width, height = image_size
    across_values, along_values = floor_line_values(model)
    homog = lines.homogeneous()
    strength = lines.strength()
    centre = camera.picture_centre(image_size)
    to_centred = np.array([[1.0, 0.0, -centre[0]], [0.0, 1.0, -centre[1]], [0.0, 0.0, 1.0]])
    court_centre = np.array([model.spec.width_m / 2.0, model.spec.length_m / 2.0])
    calls = []
    # every (dx / dy)^2 an assignment of floor lines can have
    dxs = (along_values[:, None] - along_values[None, :])[~np.eye(len(along_values), dtype=bool)]
    dys = (across_values[:, None] - across_values[None, :])[~np.eye(len(across_values), dtype=bool)]
    ratios2 = np.unique((dxs[:, None] ** 2 / dys[None, :] ** 2).ravel())

    def add_calls(ga: VanishingGroup, gb: VanishingGroup, verticals: list[np.ndarray]) -> None:
        square_centred = could_be_orthogonal(ga.point, gb.point, centre, width)
        if not square_centred and not (
            verticals
            and could_be_orthogonal(ga.point, gb.point, centre, width, OFF_CENTRE_VP_MAX_COS)
        ):
            return
        a = homog[strongest(ga.lines, strength, lines_per_group)]
        b = homog[strongest(gb.lines, strength, lines_per_group)]
        if len(a) < 2 or len(b) < 2:
            return
        for vertical in verticals or [np.zeros(3)]:
            unit_vertical = vertical / max(np.linalg.norm(vertical), 1e-300)
            calls.append((a, b, unit_vertical, square_centred))

    def can_be_vertical(gz: VanishingGroup, ga: VanishingGroup, gb: VanishingGroup) -> bool:
        return could_be_vertical(gz.point, centre) and beyond_horizon(
            gz.point, ga.point, gb.point, centre
        )

    for ga in groups:
        for gb in groups:
            if ga is gb:
                continue
            # the best-supported other group that can be the vertical, if any
            verticals = [
                to_centred @ gz.point
                for gz in sorted(groups, key=lambda g: -g.support_px)
                if gz is not ga and gz is not gb and can_be_vertical(gz, ga, gb)
            ][:1]
            add_calls(ga, gb, verticals)
    member_masks = [np.isin(np.arange(len(lines)), g.lines) for g in groups]

    def is_a_group(g: VanishingGroup) -> bool:
        mask = np.isin(np.arange(len(lines)), g.lines)
        return any(np.array_equal(mask, other) for other in member_masks)

    # A triad's points are orthogonal directions for a square-pixel camera at the centre by
    # construction: its floor pairs are tried for that camera only (the other intrinsics, from
    # a vertical, cost twenty times as much and come from the groups' pairs).
    for triad in triads or []:
        upright = [
            can_be_vertical(triad[z], *(triad[i] for i in range(3) if i != z)) for z in range(3)
        ]
        for z in range(3):
            if any(upright) and not upright[z]:
                continue  # another of the triad's points is the vertical
            ga, gb = (triad[i] for i in range(3) if i != z)
            if is_a_group(ga) and is_a_group(gb):
                continue
            add_calls(ga, gb, [])
            add_calls(gb, ga, [])

    def hypotheses_of(
        call: tuple[np.ndarray, np.ndarray, np.ndarray, bool],
    ) -> tuple[np.ndarray, np.ndarray]:
        a, b, unit_vertical, square_centred = call
        out_h = np.empty((MAX_HYPOTHESES, 3, 3))
        out_k = np.empty((MAX_HYPOTHESES, 4))
        n = _hypotheses_njit(
            np.ascontiguousarray(a),
            np.ascontiguousarray(b),
            across_values,
            along_values,
            centre,
            float(width),
            float(height),
            FOCAL_RANGE_OF_WIDTH[0] * width,
            FOCAL_RANGE_OF_WIDTH[1] * width,
            MIN_QUAD_AREA_SHARE * width * height,
            np.ascontiguousarray(unit_vertical),
            ALTERNATIVE_LINES_PER_GROUP,
            ratios2,
            square_centred,
            out_h,
            out_k,
        )
        return out_h[:n].copy(), out_k[:n].copy()

    found = parallel.ordered_map(hypotheses_of, calls)
    if not found:
        return np.zeros((0, camera.N_GENES))
    all_h = np.concatenate([h for h, _ in found])
    all_k = np.concatenate([k for _, k in found])
    keep = distinct_homographies(all_h, all_k, model, width)
    all_h = np.ascontiguousarray(all_h[keep])
    all_k = np.ascontiguousarray(all_k[keep])
    n = len(all_h)
    out_r = np.empty((n, 3, 3))
    out_t = np.empty((n, 3))
    ok = _poses_njit(
        all_h,
        all_k,
        HEIGHT_RANGE_M[0],
        HEIGHT_RANGE_M[1],
        MAX_DISTANCE_FROM_COURT_M,
        court_centre,
        np.array([model.spec.width_m, model.spec.length_m]),
        out_r,
        out_t,
    )
    return genomes_from_poses(all_k[ok], out_r[ok], out_t[ok], image_size, undistortion)


# Front-wall hypotheses (`front_wall_hypotheses`): lines per group taken into quadruples, and
# focal lengths tried (a geometric grid over FOCAL_RANGE_OF_WIDTH) when the wall is seen nearly
# face-on: its homography then says little about the focal length, which the floor decides in
# the verification.
WALL_LINES_PER_GROUP = 8
WALL_FOCAL_STEPS = 16
# A grid focal length is tried when the wall's axes under it are this close to orthogonal and
# equally long: looser than for a solved focal length, as the grid steps by 27% and the corners
# may come from the ends of lines.
WALL_MAX_AXES_COS = 0.15
WALL_MAX_AXES_LENGTH_RATIO = 0.25
MAX_WALL_HYPOTHESES = 200_000


def front_wall_values(model: CourtModel) -> tuple[np.ndarray, np.ndarray]:
    """(z values (m, down) of the front wall's lines across it: floor junction, tin, service line,
    out line; x values of its two corners)."""
    heights = sorted(
        {float(model.node(name)[2]) for name in model.node_names if model.node(name)[1] == 0.0}
    )
    return np.array(heights), np.array([0.0, model.spec.width_m])


def could_be_across(vp: np.ndarray, centre: np.ndarray) -> bool:
    """Whether a vanishing point can be that of the court's x axis (the front wall's lines and
    the floor lines across the court) for a level camera: towards the left or right of the
    picture rather than above or below it."""
    d = vp[:2] if abs(vp[2]) < 1e-12 * np.linalg.norm(vp[:2]) else vp[:2] / vp[2] - centre
    return bool(abs(d[0]) >= abs(d[1]))


def could_be_upright(vp: np.ndarray, centre: np.ndarray) -> bool:
    """Whether a vanishing point can be the world's vertical for a level camera: straight above
    or below the picture (`could_be_vertical`), or at infinity along the picture's vertical
    (vertical lines parallel in the image)."""
    if abs(vp[2]) < 1e-12 * np.linalg.norm(vp[:2]):
        return bool(abs(np.arctan2(vp[0], abs(vp[1]))) <= MAX_ROLL_RAD + np.deg2rad(10.0))
    return could_be_vertical(vp, centre)


@numba.njit(cache=True, nogil=True)
def _wall_hypotheses_njit(
    across_lines: np.ndarray,
    upright_lines: np.ndarray,
    z_values: np.ndarray,
    x_values: np.ndarray,
    centre: np.ndarray,
    width: float,
    height: float,
    focal_grid: np.ndarray,
    min_area: float,
    height_min: float,
    height_max: float,
    max_distance: float,
    court_centre: np.ndarray,
    court_size: np.ndarray,
    along_vp: np.ndarray,
    n_alt_lines: int,
    ratios2: np.ndarray,
    out_r: np.ndarray,
    out_t: np.ndarray,
    out_k: np.ndarray,
) -> int:
    """Every quadruple of two `across_lines` and two `upright_lines` under every assignment of
    front-wall line heights and corners: the cameras whose front wall they are, written to
    out_r, out_t and out_k (fx, fy, cx, cy relative to the centre); returns the count.

    Square pixels at the centre: the focal length comes from the wall homography when it pins
    one (the wall seen at an angle); every grid focal length the homography is consistent with
    is tried as well (a wall seen face-on is consistent with all of them). With the vanishing
    point of the lines along the court `along_vp` (homogeneous, relative to the centre; zeros
    for none), the quadrangles of the `n_alt_lines` strongest lines also give a free principal
    point and non-square pixels, as on the floor with the vertical (`_alternative_intrinsics`;
    `ratios2`: every (dx / dz)^2 of an assignment)."""
    n_a = across_lines.shape[0]
    n_b = upright_lines.shape[0]
    cap = out_r.shape[0]
    n_out = 0
    limit = 3.0 * max(width, height)
    quad = np.empty((4, 2))
    hm = np.empty((3, 3))
    m = np.empty((3, 3))
    focal_min, focal_max = focal_grid[0], focal_grid[focal_grid.shape[0] - 1]
    with_along = along_vp[0] != 0.0 or along_vp[1] != 0.0 or along_vp[2] != 0.0
    alt_k = np.empty((2 * ratios2.shape[0], 4))
    alt_ratio2 = np.empty(2 * ratios2.shape[0])
    for i in range(n_a):
        for j in range(i + 1, n_a):
            for kk in range(n_b):
                for ll in range(kk + 1, n_b):
                    # unit square (X' along the upright pair kk->ll, Y' across i->j) -> image
                    hu = _unit_square_homography(
                        across_lines[i],
                        across_lines[j],
                        upright_lines[kk],
                        upright_lines[ll],
                        centre,
                        limit,
                        min_area,
                        quad,
                    )
                    if hu[2, 2] == 0.0:
                        continue
                    n_alt = 0
                    if with_along and max(i, j, kk, ll) < n_alt_lines:
                        n_alt = _alternative_intrinsics(
                            hu,
                            ratios2,
                            along_vp,
                            width,
                            height,
                            focal_min,
                            focal_max,
                            alt_k,
                            alt_ratio2,
                        )
                    for p in range(z_values.shape[0]):
                        for q in range(z_values.shape[0]):
                            if p == q:
                                continue
                            dz = z_values[q] - z_values[p]
                            zp = z_values[p]
                            for r in range(2):
                                xr = x_values[r]
                                dx = x_values[1 - r] - xr
                                _rectangle_homography(hu, xr, dx, zp, dz, hm)
                                solved = _focal_of_plane_homography(hm, focal_min, focal_max)
                                for g in range(-1 - n_alt, focal_grid.shape[0]):
                                    if g < -1:
                                        alt = -2 - g
                                        if (
                                            abs((dx * dx) / (dz * dz) / alt_ratio2[alt] - 1.0)
                                            > 1e-9
                                        ):
                                            continue
                                        fx, fy = alt_k[alt, 0], alt_k[alt, 1]
                                        cx, cy = alt_k[alt, 2], alt_k[alt, 3]
                                    else:
                                        fx = solved if g < 0 else focal_grid[g]
                                        fy, cx, cy = fx, 0.0, 0.0
                                        if fx <= 0.0:
                                            continue
                                        if g >= 0 and not _axes_consistent(
                                            hm, fx, WALL_MAX_AXES_COS, WALL_MAX_AXES_LENGTH_RATIO
                                        ):
                                            continue
                                    if n_out >= cap:
                                        return n_out
                                    for c in range(3):
                                        m[0, c] = (hm[0, c] - cx * hm[2, c]) / fx
                                        m[1, c] = (hm[1, c] - cy * hm[2, c]) / fy
                                        m[2, c] = hm[2, c]
                                    if _pose_from_front_wall(
                                        m,
                                        height_min,
                                        height_max,
                                        max_distance,
                                        court_centre,
                                        court_size,
                                        out_r[n_out],
                                        out_t[n_out],
                                    ):
                                        out_k[n_out, 0] = fx
                                        out_k[n_out, 1] = fy
                                        out_k[n_out, 2] = cx
                                        out_k[n_out, 3] = cy
                                        n_out += 1
    return n_out


def front_wall_hypotheses(
    lines: ImageLines,
    groups: list[VanishingGroup],
    model: CourtModel,
    image_size: tuple[int, int],
    undistortion: Undistortion | None,
) -> np.ndarray:
    """Plausible cameras (N, 15) from two lines of a group that can run across the court taken
    as two of the front wall's lines (floor junction, tin, service line, out line) and two of a
    group that can be the vertical taken as its corners: a wall rectangle, hence a homography
    and a camera. Views from behind the back wall show the front wall best of all; its floor
    lines may be faint, short or hidden by players."""
    width, height = image_size
    centre = camera.picture_centre(image_size)
    z_values, x_values = front_wall_values(model)
    homog = lines.homogeneous()
    strength = lines.strength()
    focal_grid = width * np.geomspace(*FOCAL_RANGE_OF_WIDTH, WALL_FOCAL_STEPS)
    court_centre = np.array([model.spec.width_m / 2.0, model.spec.length_m / 2.0])
    court_size = np.array([model.spec.width_m, model.spec.length_m])
    out_r = np.empty((MAX_WALL_HYPOTHESES, 3, 3))
    out_t = np.empty((MAX_WALL_HYPOTHESES, 3))
    out_k = np.empty((MAX_WALL_HYPOTHESES, 4))
    to_centred = np.array([[1.0, 0.0, -centre[0]], [0.0, 1.0, -centre[1]], [0.0, 0.0, 1.0]])
    # every (dx / dz)^2 of an assignment of wall lines and corners
    dzs = np.abs(z_values[:, None] - z_values[None, :])[~np.eye(len(z_values), dtype=bool)]
    ratios2 = np.unique((x_values[1] - x_values[0]) ** 2 / dzs**2)
    upright_groups = [g for g in groups if could_be_upright(g.point, centre)]
    # the vertical's vanishing point: the best-supported group that can be it, else straight
    # down the picture at infinity (a level camera)
    vertical = upright_groups[0].point if upright_groups else np.array([0.0, 1.0, 0.0])
    quads: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for ga in groups:
        if not could_be_across(ga.point, centre):
            continue
        across = strongest(ga.lines, strength, WALL_LINES_PER_GROUP)
        if len(across) < 2:
            continue
        # the lines along the court (side walls' lines): the best-supported other group,
        # whose vanishing point is the wall's normal (zeros: none)
        along = [g.point for g in groups if g is not ga and not any(g is u for u in upright_groups)]
        along_vp = to_centred @ along[0] if along else np.zeros(3)
        along_vp = along_vp / max(float(np.linalg.norm(along_vp)), 1e-300)
        for gb in upright_groups:
            if gb is not ga and len(gb.lines) >= 2:
                quads.append(
                    (
                        homog[across],
                        homog[strongest(gb.lines, strength, WALL_LINES_PER_GROUP)],
                        along_vp,
                    )
                )
        # the wall's lines end at its corners, which may be too faint to be lines of their
        # own: corners through the ends of the lines across, towards the vertical
        ends = lines.extent[across].reshape(-1, 2)
        corners = np.cross(np.column_stack([ends, np.ones(len(ends))]), vertical)
        quads.append((homog[across], corners, along_vp))
    parts = []
    for a, b, along_vp in quads:
        n = _wall_hypotheses_njit(
            np.ascontiguousarray(a, dtype=np.float64),
            np.ascontiguousarray(b, dtype=np.float64),
            z_values,
            x_values,
            centre,
            float(width),
            float(height),
            focal_grid,
            MIN_QUAD_AREA_SHARE * width * height,
            HEIGHT_RANGE_M[0],
            HEIGHT_RANGE_M[1],
            MAX_DISTANCE_FROM_COURT_M,
            court_centre,
            court_size,
            np.ascontiguousarray(along_vp),
            ALTERNATIVE_LINES_PER_GROUP,
            ratios2,
            out_r,
            out_t,
            out_k,
        )
        parts.append(genomes_from_poses(out_k[:n], out_r[:n], out_t[:n], image_size, undistortion))
    if not parts:
        return np.zeros((0, camera.N_GENES))
    return np.concatenate(parts)


def distinct_homographies(
    homographies: np.ndarray, intrinsics: np.ndarray, model: CourtModel, image_width: int
) -> np.ndarray:
    """Indices of homographies (N, 3, 3) with intrinsics (N, 4) that put the floor's corners and T
    on different pixels (to DISTINCT_HOMOGRAPHY_SHARE of the image width) or have other
    intrinsics: many line quadruples and assignments give the same camera, which need not be
    scored twice (one floor homography with other intrinsics is another camera: other walls)."""
    if len(homographies) == 0:
        return np.zeros(0, np.int64)
    names = ("floor_front_left", "floor_front_right", "floor_back_left", "floor_back_right", "T")
    points = np.array([[*model.node(name)[:2], 1.0] for name in names])
    mapped = np.einsum("nij,kj->nki", homographies, points)
    with np.errstate(divide="ignore", invalid="ignore"):
        pixels = mapped[..., :2] / mapped[..., 2:3]
    cell = DISTINCT_HOMOGRAPHY_SHARE * image_width
    cells = np.clip(np.round(pixels / cell), -(2**20), 2**20)
    cells = (
        np.where(np.isfinite(cells), cells, 2**20).astype(np.int64).reshape(len(homographies), -1)
    )
    aspect = np.round(20.0 * intrinsics[:, 1] / intrinsics[:, 0]).astype(np.int64)
    shift = np.round(intrinsics[:, 2:4] / cell).astype(np.int64)
    cells = np.column_stack([cells, aspect, shift])
    # one 64-bit hash per row (a collision only drops a hypothesis)
    key = np.zeros(len(cells), np.uint64)
    for column in cells.T:
        key = key * np.uint64(1_000_003) + column.astype(np.uint64)
    _, first = np.unique(key, return_index=True)
    return np.sort(first)


def beyond_horizon(vp: np.ndarray, vp_a: np.ndarray, vp_b: np.ndarray, centre: np.ndarray) -> bool:
    """Whether `vp` can be the vertical's vanishing point of a camera whose floor directions
    vanish at `vp_a` and `vp_b` (homogeneous): the horizon is the line through them, and the
    picture's centre lies between the horizon and the vertical's point (tilted down by t, the
    horizon is f tan t above the principal point and the nadir f / tan t below it; tilted up,
    the other way round), so both lie on the same side of the horizon."""
    horizon = np.cross(vp_a, vp_b)
    if abs(vp[2]) < 1e-12 * np.linalg.norm(vp[:2]) or not np.any(horizon[:2]):
        return True  # no side to tell
    side_vp = (horizon @ vp) / vp[2]
    side_centre = horizon @ np.array([centre[0], centre[1], 1.0])
    return bool(side_vp * side_centre > 0.0)


def could_be_vertical(vp: np.ndarray, centre: np.ndarray) -> bool:
    """Whether a vanishing point can be the world's vertical for a camera held level: straight
    above or below the picture (within MAX_ROLL_RAD plus a margin for an off-centre principal
    point), well outside it."""
    if abs(vp[2]) < 1e-12 * np.linalg.norm(vp[:2]):
        return False  # vertical lines parallel in the image: a level camera, no principal point
    d = vp[:2] / vp[2] - centre
    return (
        abs(np.arctan2(d[0], abs(d[1]))) <= MAX_ROLL_RAD + np.deg2rad(10.0)
        and abs(d[1]) > centre[1]
    )


# ---------------------------------------------------------------------------------------------
# typical placements: one more source of hypotheses (and the default start of the paper's GA)


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
    genomes = np.zeros((len(centres_m), camera.N_GENES))
    genomes[:, 0] = genomes[:, 1] = focal_px
    genomes[:, 2], genomes[:, 3] = camera.picture_centre(image_size)
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


@functools.lru_cache(maxsize=16)
def _default_grid_starts(image_size: tuple[int, int], spec: str) -> np.ndarray:
    starts = _candidate_starts(image_size, court_model(spec), StartGrid())
    starts.setflags(write=False)
    return starts


def candidate_starts(
    image_size: tuple[int, int], model: CourtModel, grid: StartGrid | None = None
) -> np.ndarray:
    """Start cameras (N, 15) over the grid's placements (the default grid is cached per image
    size and court spec: it is the same for every image)."""
    if grid is None and COURT_SPECS.get(model.spec.name) == model.spec:
        return _default_grid_starts((int(image_size[0]), int(image_size[1])), model.spec.name)
    return _candidate_starts(image_size, model, grid or StartGrid())


def _candidate_starts(
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
# the search stage: hypotheses from every source, ranked, the best polished

# Search: distinct hypotheses polished (from the lines and the hint; from the placement grid),
# the polish's truncations (px at 1920 px wide) and budget, and how many go on to refinement.
FLOOR_PASS_HYPOTHESES = 15000
WALL_PASS_HYPOTHESES = 5000
VERIFIED_HYPOTHESES = 2000
# |lambda| (division model, radius in half-diagonals) above which other lenses are tried too,
# as these multiples of the estimate: a weaker one in every search, more in the second search
# (see `search_cameras`)
STRONG_LENS_LAMBDA = 0.08
STRONG_LENS_FACTORS = (0.5,)
STRONG_LENS_FACTORS_SECOND_SEARCH = (0.5, 0.75, 1.5)
POLISHED_FROM_LINES = 24
# ... and ranked at the tight tolerance (see `search_cameras`)
VERIFIED_AT_TIGHT_TOLERANCE = 500
POLISHED_AT_TIGHT_TOLERANCE = 12
POLISHED_FROM_GRID = 6
POLISH_TAUS_AT_1920 = (24.0, 8.0)
POLISH_EVALUATIONS = 120
REFINED_CANDIDATES = 8
# source indices of the hypotheses: from image lines, the placement grid, the start camera given
# as a hint, and the line hypotheses under other pixel aspects
LINES, GRID, HINT, ASPECT = 0, 1, 2, 3
SOURCE_LABELS = ("lines", "grid", "start", "aspect")
# The aspect variants are many near-copies of the line hypotheses' floors; they have budgets of
# their own so that they cannot crowd the square-pixel hypotheses out of verification or polish.
VERIFIED_ASPECT_VARIANTS = 300
POLISHED_ASPECT_VARIANTS = 6


@dataclass(frozen=True)
class SearchOutcome:
    candidates: np.ndarray  # (K, 15) distinct best cameras, best first
    sources: list[str]  # where each came from: "lines", "grid", "start"
    scores: np.ndarray  # (K,) verification scores (log-likelihood ratio against chance)
    info: dict[str, float]
    convergence: dict[str, Any]


def search_cameras(
    evidence: LineEvidence,
    maps: EvidenceMaps,
    model: CourtModel,
    image_size: tuple[int, int],
    start_genome: np.ndarray | None,
    verification: verify.VerifySamples,
    trace: Callable[[str, np.ndarray], None] | None = None,
    second_search: bool = False,
) -> SearchOutcome:
    """Hypotheses from the image's lines, typical placements and the start camera (and, in the
    `second_search` after a refusal, the line hypotheses under the anamorphic formats' pixel
    aspects, from lines straightened with more lenses and from more lines per vanishing group):
    ranked on
    the evidence with a wide tolerance, the best distinct ones polished (a pinhole + k1 fit from
    a wide to a narrower truncation), ranked again with a tight tolerance. `trace(stage,
    cameras)` sees the cameras kept after each stage (for diagnosis)."""

    def traced(stage: str, cameras: np.ndarray) -> None:
        if trace is not None:
            trace(stage, cameras)

    width, _ = image_size
    chains = segments.chains_of(evidence)
    lenses = segments.undistortion_candidates(chains, image_size)
    undistortion = lenses[0]
    min_length = max(10.0, 30.0 * width / 1920.0)
    # The plumb-line estimate leans on the long lines at the picture's edge, where a real lens
    # departs most from the one-term model, and overshoots the centre's distortion there: a
    # weaker lens is tried as well. It can also undershoot (a few long lines near the centre
    # outvote them): on bench.synthetic's wide_angle 5008 it said -0.16 for a lens nearest
    # -0.27, and no hypothesis came within 25 px of the court; from lines straightened with
    # -0.24 to -0.27, hypotheses 1.5-7 px off. The second search (after a refusal) tries a
    # stronger lens too. Not the first: more lenses there give more near-copies of the right
    # camera with other lenses, and on seeds 1000+ two wide-angle views found with the
    # estimate's lens ended with another's, their picture's corners 4-5 px off. A second lens
    # the chains agree on (`segments.undistortion_candidates`) is tried as it is.
    factors = STRONG_LENS_FACTORS_SECOND_SEARCH if second_search else STRONG_LENS_FACTORS
    lines_per_group = (
        QUADRUPLE_LINES_PER_GROUP_SECOND_SEARCH if second_search else QUADRUPLE_LINES_PER_GROUP
    )
    lens_candidates = [undistortion.lam]
    if abs(undistortion.lam) > STRONG_LENS_LAMBDA:
        lens_candidates += [factor * undistortion.lam for factor in factors]
    lens_candidates += [other.lam for other in lenses[1:]]
    line_parts = []
    n_lines = n_groups = 0
    for lam in lens_candidates:
        lens = segments.Undistortion(undistortion.centre, undistortion.radius_px, lam)
        image_lines = segments.merge_collinear(segments.segments_of(chains, lens, min_length))
        groups = vanishing_groups(image_lines)
        triads = vanishing_triads(image_lines, image_size)
        # the lines straightened with the plumb-line estimate only (the other lenses' lines are
        # near-copies of them, and each is as costly)
        line_parts.append(
            floor_hypotheses(
                image_lines,
                groups,
                model,
                image_size,
                lens,
                triads,
                lines_per_group if lam == undistortion.lam else QUADRUPLE_LINES_PER_GROUP,
            )
        )
        line_parts.append(front_wall_hypotheses(image_lines, groups, model, image_size, lens))
        n_lines, n_groups = max(n_lines, len(image_lines)), max(n_groups, len(groups))
    from_lines = np.concatenate(line_parts)
    grid = candidate_starts(image_size, model)
    parts = [from_lines, grid]
    if start_genome is not None:
        parts.append(start_genome[None, :])
    sources = np.concatenate([np.full(len(p), i) for i, p in enumerate(parts)])
    genomes = np.concatenate(parts)
    traced("hypotheses", genomes)
    # a cheap ranking of everything, then the verification proper of the best
    rank_tolerance = verify.rank_tolerance_px(width)
    if len(genomes) > FLOOR_PASS_HYPOTHESES + WALL_PASS_HYPOTHESES:
        # the best on the floor, and the best on the walls: a floor of planks or worn lines
        # says little (on bench.synthetic's wide_angle 7011, a corner view over planks, the
        # true camera ranked 40 000th of 85 000 on the floor, its walls' lines clear)
        by_floor, by_walls = (
            verify.coarse_scores(genomes, model, maps, (rank_tolerance,), part)[:, 0]
            for part in ("floor", "walls")
        )
        keep = np.union1d(
            _best_rows(by_floor, FLOOR_PASS_HYPOTHESES), _best_rows(by_walls, WALL_PASS_HYPOTHESES)
        )
        keep = np.union1d(keep, np.flatnonzero(sources == HINT))  # the hint always goes on
        genomes, sources = genomes[keep], sources[keep]
        traced("floor pass", genomes)
    if second_search:
        # the floor hypotheses again under other pixel aspects: their floors are the same, so
        # only the ranking with the walls below can tell them apart
        variants, _ = aspect_variants(genomes[sources == LINES], model, image_size)
        genomes = np.concatenate([genomes, variants])
        sources = np.concatenate([sources, np.full(len(variants), ASPECT, dtype=sources.dtype)])
        traced("aspect variants", genomes)
    # Ranked at two tolerances: the wide one keeps hypotheses a few pixels off (four lines
    # pin a homography only near them); the tight one keeps those that are right where a busy
    # picture puts some line within the wide tolerance of nearly every wrong camera.
    tight_tolerance = verify.verify_tolerance_px(width)
    coarse, coarse_tight = verify.coarse_scores(
        genomes, model, maps, (rank_tolerance, tight_tolerance)
    ).T
    implausible = placement.floor_shares(genomes, model, image_size) < placement.MIN_FLOOR_SHARE
    implausible |= placement.implausible_placement(genomes, model)
    coarse[implausible] = coarse_tight[implausible] = -np.inf
    variant = sources == ASPECT
    square = np.flatnonzero(~variant)
    if len(square) > VERIFIED_HYPOTHESES + VERIFIED_AT_TIGHT_TOLERANCE:
        keep = np.union1d(
            square[_best_rows(coarse[square], VERIFIED_HYPOTHESES)],
            square[_best_rows(coarse_tight[square], VERIFIED_AT_TIGHT_TOLERANCE)],
        )
    else:
        keep = square
    variants_kept = np.flatnonzero(variant & np.isfinite(coarse))
    keep = np.union1d(
        keep, variants_kept[_best_rows(coarse[variants_kept], VERIFIED_ASPECT_VARIANTS)]
    )
    keep = np.union1d(keep, np.flatnonzero(sources == HINT))  # the hint always goes on
    genomes, sources = genomes[keep], sources[keep]
    traced("coarse", genomes)
    _, _, scores = verify.edge_support(genomes, verification, maps, rank_tolerance)
    _, _, tight_scores = verify.edge_support(genomes, verification, maps, tight_tolerance)

    def best_of(rows: np.ndarray, values: np.ndarray, count: int) -> list[int]:
        masked = np.where(rows, values, -np.inf)
        return [int(i) for i in verify.distinct_best(genomes, masked, model, image_size, count)]

    # the line hypotheses (and the hint) at both tolerances, a few of the placements as a
    # fallback, and a few of the aspect variants if any
    from_lines = (sources == LINES) | (sources == HINT)
    chosen = best_of(from_lines, scores, POLISHED_FROM_LINES)
    for group, values, count in (
        (from_lines, tight_scores, POLISHED_AT_TIGHT_TOLERANCE),
        (sources == GRID, scores, POLISHED_FROM_GRID),
    ):
        chosen += [i for i in best_of(group, values, count) if i not in chosen]
    # (distinct_best fills up from outside the group when the group is small: the aspect
    # variants, absent from the first search, must not bring other hypotheses in)
    variant = sources == ASPECT
    chosen += [
        i
        for i in best_of(variant, scores, POLISHED_ASPECT_VARIANTS)
        if variant[i] and i not in chosen
    ]
    chosen = [i for i in chosen if np.isfinite(scores[i]) and np.isfinite(tight_scores[i])]
    # a start camera given by the user is always polished: it is a hint worth the look
    chosen += [int(i) for i in np.flatnonzero(sources == HINT) if int(i) not in chosen]
    traced("chosen for polishing", genomes[chosen])
    polish_samples = refine.fit_samples(model, 2.0 * refine.spacing_for_width(width))
    taus = tuple(max(2.0, tau * width / 1920.0) for tau in POLISH_TAUS_AT_1920)
    polished = np.array(
        parallel.ordered_map(
            lambda i: (
                refine.refine_coarse_to_fine(
                    genomes[i], polish_samples, maps, taus, refine.BASE, POLISH_EVALUATIONS
                ).genome
            ),
            chosen,
        )
    ).reshape(-1, camera.N_GENES)
    traced("polished", polished)
    _, _, polished_scores = verify.edge_support(polished, verification, maps, tight_tolerance)
    polished_scores[placement.implausible_placement(polished, model)] = -np.inf
    best = verify.distinct_best(polished, polished_scores, model, image_size, REFINED_CANDIDATES)
    best = np.array([i for i in best if np.isfinite(polished_scores[i])], dtype=np.int64)
    traced("candidates", polished[best])
    info = {
        "image_lines": float(n_lines),
        "vanishing_groups": float(n_groups),
        "line_hypotheses": float(len(from_lines)),
        "grid_hypotheses": float(len(grid)),
        "lens_lambda": float(undistortion.lam),
        "best_search_score": float(polished_scores[best[0]]) if len(best) else float("-inf"),
    }
    ranked = np.sort(scores[np.isfinite(scores)])[::-1][:200]
    convergence = {
        "stage": "search",
        "x_label": "hypotheses, best first",
        "x": list(range(1, len(ranked) + 1)),
        "best": [float(v) for v in ranked],
        "mean": [],
    }
    return SearchOutcome(
        candidates=polished[best],
        sources=[SOURCE_LABELS[int(sources[chosen[i]])] for i in best],
        scores=polished_scores[best],
        info=info,
        convergence=convergence,
    )


def _best_rows(values: np.ndarray, count: int) -> np.ndarray:
    """Indices of the `count` largest values (all of them if there are no more)."""
    if len(values) <= count:
        return np.arange(len(values))
    return np.argpartition(-values, count)[:count]
