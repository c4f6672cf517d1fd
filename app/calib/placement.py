"""Where a camera filming a squash court stands and how it is held, and how much of the picture
the court's floor fills: the plausibility rules that the search (hypotheses), the refinement (the
ranking of candidates) and the verdict share. They come from how courts are filmed, never from
an image: heights and distances of cameras, how far they roll and tilt, the volume where players
play (no fixed camera stands there) and the solid front wall (no camera sees the floor through
it).
"""

from __future__ import annotations

from collections.abc import Callable

import numba
import numpy as np

from app.calib import camera
from app.calib.camera import extrinsics_njit
from app.calib.court import CourtModel

# Plausible cameras, from how courts are filmed (not from any image): focal length (share of
# the image width: a 120-degree action camera to a long broadcast zoom), height above the floor
# (m), distance from the court (m), and how the camera is held: level (roll), looking at the
# court (between a little above the horizon and steeply down).
FOCAL_RANGE_OF_WIDTH = (0.25, 12.0)
HEIGHT_RANGE_M = (0.3, 25.0)
MAX_DISTANCE_FROM_COURT_M = 45.0
MAX_ROLL_RAD = np.deg2rad(15.0)
# Where players move and swing (`_in_play_volume`): no fixed camera stands there. Margins (m)
# from the front and side walls (a camera mounted in a corner or on a wall) and from the back
# wall (a tripod against it), and the height (m) above which a camera is out of a racket's reach.
PLAY_VOLUME_WALL_MARGIN_M = 1.0
PLAY_VOLUME_BACK_MARGIN_M = 2.0
PLAY_VOLUME_HEIGHT_M = 2.0
# The front wall is solid in every court (the ball is played against it; glass is only ever at
# the back and the sides): a camera behind it, within its width, sees the floor only over its
# top, which is at least the front-wall out line's height, and the farther behind the wall it
# stands the higher it must be for the line of sight over the top to reach the floor before the
# back wall. (Beyond a side wall's plane, it sees the floor through that wall.) Margin (m)
# behind the wall's plane for a camera mounted on it.
FRONT_WALL_MARGIN_M = 0.5
FRONT_WALL_MIN_TOP_M = 4.57
MAX_TILT_UP_RAD = np.deg2rad(15.0)
MAX_TILT_DOWN_RAD = np.deg2rad(75.0)


@numba.njit(cache=True, inline="always")
def held_upright(dx: float, dy: float, dz: float) -> bool:
    """Whether a camera sees the world's down direction (dx, dy, dz) (camera coordinates, unit)
    as people film: down in the picture within MAX_ROLL_RAD of the image's vertical, and the
    optical axis between MAX_TILT_UP_RAD above and MAX_TILT_DOWN_RAD below the horizon."""
    tilt_down = np.arcsin(min(max(dz, -1.0), 1.0))
    if tilt_down < -MAX_TILT_UP_RAD or tilt_down > MAX_TILT_DOWN_RAD:
        return False
    # the image's down is +y; the world's down projected on the image plane is (dx, dy)
    return dy > 0.0 and abs(np.arctan2(dx, dy)) <= MAX_ROLL_RAD


@numba.njit(cache=True, inline="always")
def placed_plausibly(
    r: np.ndarray,
    t: np.ndarray,
    height_min: float,
    height_max: float,
    max_distance: float,
    court_centre: np.ndarray,
    court_size: np.ndarray,
) -> bool:
    """Whether a camera (X_cam = r X + t) stands where courts are filmed from: at a plausible
    height and distance, not where players play and not behind the front wall (see
    `implausible_placement`)."""
    cx = -(r[0, 0] * t[0] + r[1, 0] * t[1] + r[2, 0] * t[2])
    cy = -(r[0, 1] * t[0] + r[1, 1] * t[1] + r[2, 1] * t[2])
    cz = -(r[0, 2] * t[0] + r[1, 2] * t[1] + r[2, 2] * t[2])
    if not (height_min <= -cz <= height_max):
        return False
    if abs(cx - court_centre[0]) > max_distance or abs(cy - court_centre[1]) > max_distance:
        return False
    return not (
        _in_play_volume(cx, cy, cz, court_size[0], court_size[1])
        or _behind_front_wall(cx, cy, cz, court_size[0], court_size[1])
    )


@numba.njit(cache=True, inline="always")
def _in_play_volume(x: float, y: float, z: float, width_m: float, length_m: float) -> bool:
    """Whether a point (court frame, z down) is where players move and swing: inside the court,
    more than PLAY_VOLUME_WALL_MARGIN_M from the side and front walls, in front of the back
    PLAY_VOLUME_BACK_MARGIN_M, below PLAY_VOLUME_HEIGHT_M. No fixed camera stands there (it
    would be hit); cameras inside the court are mounted on a wall, in a corner, high up, or on a
    tripod against the back wall."""
    return (
        PLAY_VOLUME_WALL_MARGIN_M < x < width_m - PLAY_VOLUME_WALL_MARGIN_M
        and PLAY_VOLUME_WALL_MARGIN_M < y < length_m - PLAY_VOLUME_BACK_MARGIN_M
        and z > -PLAY_VOLUME_HEIGHT_M
    )


@numba.njit(cache=True, inline="always")
def _behind_front_wall(x: float, y: float, z: float, width_m: float, length_m: float) -> bool:
    """Whether a camera at a point (court frame, z down) behind the front wall and within its
    width has the wall hide the whole floor: its line of sight over the wall's lowest possible
    top (FRONT_WALL_MIN_TOP_M) meets the floor beyond the back wall, or never. At the wall's
    plane that is a camera below the top; 13 m behind it, one below 10.6 m (bench.synthetic
    zoomed 2003 was taken for a camera 6 m high there, laying the court on a floor it could not
    see). Every line of sight from such a camera to the floor crosses the wall's plane within
    its width, so the top decides."""
    if y >= -FRONT_WALL_MARGIN_M or not 0.0 <= x <= width_m:
        return False
    return -z < FRONT_WALL_MIN_TOP_M * (length_m - y) / length_m


def _placement_rule(genomes: np.ndarray, rule: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(N,) bool: `rule` of the court-frame centres (K, 3) of the finite cameras among
    `genomes` (False for the others)."""
    pop = camera.as_population(genomes)
    finite = np.all(np.isfinite(pop), axis=1)
    r, t = camera.court_extrinsics(pop[finite])
    out = np.zeros(len(pop), dtype=bool)
    out[finite] = rule(-np.einsum("nji,nj->ni", r, t))
    return out


def in_play_volume(genomes: np.ndarray, model: CourtModel) -> np.ndarray:
    """(N,) bool: the camera centre is where players play (no fixed camera stands there)."""
    spec = model.spec
    return _placement_rule(genomes, lambda c: _in_play_volume_all(c, spec.width_m, spec.length_m))


def behind_front_wall(genomes: np.ndarray, model: CourtModel) -> np.ndarray:
    """(N,) bool: the camera stands behind the front wall, which hides the floor from it."""
    spec = model.spec
    return _placement_rule(
        genomes, lambda c: _behind_front_wall_all(c, spec.width_m, spec.length_m)
    )


def implausible_placement(genomes: np.ndarray, model: CourtModel) -> np.ndarray:
    """(N,) bool: no fixed camera filming the court stands there (where players play, or behind
    the front wall)."""
    spec = model.spec
    return _placement_rule(
        genomes,
        lambda c: (
            _in_play_volume_all(c, spec.width_m, spec.length_m)
            | _behind_front_wall_all(c, spec.width_m, spec.length_m)
        ),
    )


@numba.njit(cache=True, nogil=True)
def _behind_front_wall_all(centres: np.ndarray, width_m: float, length_m: float) -> np.ndarray:
    out = np.empty(centres.shape[0], dtype=np.bool_)
    for i in range(centres.shape[0]):
        c = centres[i]
        out[i] = _behind_front_wall(c[0], c[1], c[2], width_m, length_m)
    return out


@numba.njit(cache=True, nogil=True)
def _in_play_volume_all(centres: np.ndarray, width_m: float, length_m: float) -> np.ndarray:
    out = np.empty(centres.shape[0], dtype=np.bool_)
    for i in range(centres.shape[0]):
        out[i] = _in_play_volume(centres[i, 0], centres[i, 1], centres[i, 2], width_m, length_m)
    return out


# ---------------------------------------------------------------------------------------------
# how much of the picture the court's floor fills: users film the floor (that is where the
# players' feet are), so a camera that shows almost none of it is not the answer

MIN_FLOOR_SHARE = 0.05
_FLOOR_EDGE_PIECES = 8
_NEAR_DEPTH_M = 0.1


@numba.njit(cache=True)
def _clip_polygon(
    poly: np.ndarray, n: int, axis: int, limit: float, keep_above: bool, out: np.ndarray
) -> int:
    """Sutherland-Hodgman: the part of polygon poly[:n] with coordinate `axis` >= limit (or <=)."""
    m = 0
    for i in range(n):
        a = poly[i]
        b = poly[(i + 1) % n]
        a_in = a[axis] >= limit if keep_above else a[axis] <= limit
        b_in = b[axis] >= limit if keep_above else b[axis] <= limit
        if a_in:
            out[m] = a
            m += 1
        if a_in != b_in:
            s = (limit - a[axis]) / (b[axis] - a[axis])
            out[m] = a + s * (b - a)
            m += 1
    return m


@numba.njit(cache=True, nogil=True)
def _floor_share_njit(
    pop: np.ndarray,
    outline: np.ndarray,
    fold_radius: np.ndarray,
    width: float,
    height: float,
    out: np.ndarray,
) -> None:
    n0 = outline.shape[0]
    cam = np.empty((2 * n0 + 4, 3))
    clipped = np.empty((2 * n0 + 4, 3))
    px = np.empty((2 * n0 + 20, 2))
    tmp = np.empty((2 * n0 + 20, 2))
    tmp2 = np.empty((2 * n0 + 20, 2))
    r = np.empty((3, 3))
    t = np.empty(3)
    for i in range(pop.shape[0]):
        g = pop[i]
        extrinsics_njit(g, r, t)
        for k in range(n0):
            for a in range(3):
                cam[k, a] = (
                    r[a, 0] * outline[k, 0]
                    + r[a, 1] * outline[k, 1]
                    + r[a, 2] * outline[k, 2]
                    + t[a]
                )
        n = _clip_polygon(cam, n0, 2, _NEAR_DEPTH_M, True, clipped)
        if n < 3:
            out[i] = 0.0
            continue
        # on the undistorted normalised plane, keep what the lens maps faithfully: inside its
        # fold, and not far beyond the picture (the polynomial means nothing out there)
        bound = 3.0 * max(width, height) / min(g[0], g[1])
        if np.isfinite(fold_radius[i]):
            bound = min(bound, 0.95 * fold_radius[i] / np.sqrt(2.0))
        for k in range(n):
            tmp[k, 0] = clipped[k, 0] / clipped[k, 2]
            tmp[k, 1] = clipped[k, 1] / clipped[k, 2]
        n = _clip_polygon(tmp, n, 0, -bound, True, tmp2)
        n = _clip_polygon(tmp2, n, 0, bound, False, tmp)
        n = _clip_polygon(tmp, n, 1, -bound, True, tmp2)
        n = _clip_polygon(tmp2, n, 1, bound, False, px)
        for k in range(n):
            xn = px[k, 0]
            yn = px[k, 1]
            r2 = xn * xn + yn * yn
            radial = 1.0 + g[10] * r2 + g[11] * r2 * r2 + g[14] * r2 * r2 * r2
            a1 = 2.0 * xn * yn
            xd = xn * radial + g[12] * a1 + g[13] * (r2 + 2.0 * xn * xn)
            yd = yn * radial + g[12] * (r2 + 2.0 * yn * yn) + g[13] * a1
            tmp[k, 0] = min(max(g[0] * xd + g[2], -10.0 * width), 11.0 * width)
            tmp[k, 1] = min(max(g[1] * yd + g[3], -10.0 * height), 11.0 * height)
        m = _clip_polygon(tmp, n, 0, 0.0, True, tmp2)
        m = _clip_polygon(tmp2, m, 0, width, False, tmp)
        m = _clip_polygon(tmp, m, 1, 0.0, True, tmp2)
        m = _clip_polygon(tmp2, m, 1, height, False, tmp)
        area = 0.0
        for k in range(m):
            j = (k + 1) % m
            area += tmp[k, 0] * tmp[j, 1] - tmp[j, 0] * tmp[k, 1]
        out[i] = abs(0.5 * area) / (width * height)


def floor_outline(model: CourtModel) -> np.ndarray:
    """The floor's boundary (4 * _FLOOR_EDGE_PIECES, 3), corners and points between them, so a
    distorting lens bends its edges."""
    width, length = model.spec.width_m, model.spec.length_m
    corners = np.array(
        [[0.0, 0.0, 0.0], [width, 0.0, 0.0], [width, length, 0.0], [0.0, length, 0.0]]
    )
    s = np.linspace(0.0, 1.0, _FLOOR_EDGE_PIECES, endpoint=False)[:, None]
    return np.concatenate(
        [a + s * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True)]
    )


def floor_shares(genomes: np.ndarray, model: CourtModel, image_size: tuple[int, int]) -> np.ndarray:
    """Share of the picture the court's floor fills, per camera (N,)."""
    pop = np.ascontiguousarray(camera.as_population(genomes))
    out = np.empty(len(pop))
    _floor_share_njit(
        pop,
        floor_outline(model),
        camera.lens_fold_radii(pop),
        float(image_size[0]),
        float(image_size[1]),
        out,
    )
    return out
