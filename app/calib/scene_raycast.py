"""The compiled ray caster behind `scene.py`: scene arrays in, pixel colours out.

A scene is a handful of flat arrays (built by `scene.build_scene`), so one compiled kernel renders
every style: squash courts with plaster or glass walls, other sports' floors, rooms.

Geometry (court frame: metres, x right, y from the front wall to the back wall, z DOWN):
- the court box 0 <= x <= W, 0 <= y <= L: floor, front wall (opaque), side and back walls (plaster or
  glass, tops given per wall); glass is crossed by the ray: transmission with a tint and haze, a
  Fresnel reflection (one bounce, traced), painted lines, decals and metal fittings on it;
- glass fins outside the back wall (thin glass planes x = joint, y in [L, L + depth]);
- a hall box around everything: floor, four walls, a ceiling with light panels; tiered stands with a
  crowd beside the side walls; a gallery slab with a railing behind the back wall.

Surfaces carry a material (`surf` rows: base colour, light, material kind and its parameters),
painted segments (`segs`, sorted by surface, ranges in `seg_lo`/`seg_hi`), floor arcs, and adverts
(`ads`, textured rectangles in surface coordinates, ranges in `ad_lo`/`ad_hi`).

Per pixel the kernel averages s x s supersamples and also returns, for compositing players later,
what lies between the camera and the court interior: `front_acc` (the light it adds) and
`front_trans` (the fraction of light from inside the court that passes).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numba
import numpy as np

_F = TypeVar("_F", bound=Callable[..., Any])
# Compiled without numba's reference counting (`_nrt=False`): the kernels pass the 13 scene arrays
# along on every call, and counting references to them cost ~5x the shading itself. These functions
# allocate nothing; `visible_from`, which does, keeps the default.
_KERNEL_OPTIONS: dict[str, Any] = {"cache": True, "_nrt": False}


def _kernel(fn: _F) -> _F:
    return numba.njit(**_KERNEL_OPTIONS)(fn)


def _inline_kernel(fn: _F) -> _F:
    return numba.njit(inline="always", **_KERNEL_OPTIONS)(fn)


# ----------------------------------------------------------------------------------------------
# Surfaces
(
    S_FLOOR,
    S_FRONT,
    S_LEFT,
    S_RIGHT,
    S_BACK,
    S_HALL_FLOOR,
    S_HALL_LEFT,
    S_HALL_RIGHT,
    S_HALL_FRONT,
    S_HALL_BACK,
    S_CEILING,
    S_STAND_LEFT,
    S_STAND_RIGHT,
    S_GALLERY,
    S_RAILING,
    S_FIN,
    S_STAND_BACK,
    N_SURFACES,
) = range(18)

SURFACE_IDS: dict[str, int] = {
    "floor": S_FLOOR,
    "front": S_FRONT,
    "left": S_LEFT,
    "right": S_RIGHT,
    "back": S_BACK,
    "hall_floor": S_HALL_FLOOR,
    "hall_left": S_HALL_LEFT,
    "hall_right": S_HALL_RIGHT,
    "hall_front": S_HALL_FRONT,
    "hall_back": S_HALL_BACK,
    "ceiling": S_CEILING,
    "stand_left": S_STAND_LEFT,
    "stand_right": S_STAND_RIGHT,
    "gallery": S_GALLERY,
    "railing": S_RAILING,
    "fin": S_FIN,
    "stand_back": S_STAND_BACK,
}

# Materials (surf[:, SF_KIND]) and the meaning of their parameters surf[:, SF_P0 + k]
(
    M_PLASTER,  # p0 mottle, p1 scuff density, p2 scuff strength, p3 dirt towards the floor,
    # p4 light gradient with height, p5 light gradient along the wall
    M_PLANKS,  # p0 width, p1 length, p2 tone spread, p3 grain, p4 seam darkness, p5 axis, p6 pool
    M_FLAT,  # p0 mottle, p1 fine noise, p2 pool, p3 faint planks under paint (0..1)
    M_GLASS_FLOOR,  # p0 panel size, p1 joint darkness, p2 mottle
    M_CARPET,  # p0 strength, p1 scale (m)
    M_TILES,  # p0 tile size, p1 grout width, p2 grout darkness, p3 tone spread
    M_PANELS,  # p0 panel width, p1 joint darkness, p2 dado height, p3 dado multiplier, p4 mottle
    M_CEILING,  # p0/p1 light spacing x/y, p2/p3 light size x/y, p4 light level, p5 beam spacing, p6 beam dark
    M_CROWD,  # p0 density, p1 row depth, p2 seat width, p3 crowd light, p4 seed
    M_METAL,  # p0 sheen
) = range(10)

SF_B, SF_G, SF_R, SF_LIGHT, SF_KIND, SF_P0 = range(6)
SURF_COLUMNS = 16

# Scalar parameters (the `p` vector)
(
    P_HAS_COURT,
    P_W,
    P_L,
    P_FRONT_TOP,
    P_SIDE_TOP_FRONT,
    P_SIDE_TOP_BACK,
    P_BACK_TOP,
    P_TIN_TOP,
    P_HALF_LINE,
    P_AREA_X0,
    P_AREA_Y0,
    P_AREA_X1,
    P_AREA_Y1,
    P_SIDE_GLASS,
    P_BACK_GLASS,
    P_GLASS_T,
    P_TINT_B,
    P_TINT_G,
    P_TINT_R,
    P_R0_SIDE,
    P_R0_BACK,
    P_HAZE,
    P_SIDE_JOINT_SPACING,
    P_FIN_DEPTH,
    P_CLAMP_W,
    P_CLAMP_H,
    P_CLAMP_Z0,
    P_CLAMP_Z1,
    P_CLAMP_Z2,
    P_DOOR_X0,
    P_DOOR_X1,
    P_DOOR_POST_W,
    P_TOP_RAIL_H,
    P_CORNER_POST_W,
    P_METAL_B,
    P_METAL_G,
    P_METAL_R,
    P_TIN_B,
    P_TIN_G,
    P_TIN_R,
    P_HALL_X0,
    P_HALL_X1,
    P_HALL_Y0,
    P_HALL_Y1,
    P_HALL_Z,
    P_STAND_LEFT,
    P_STAND_RIGHT,
    P_STAND_OFFSET,
    P_STAND_TAN,
    P_STAND_Y0,
    P_STAND_Y1,
    P_GALLERY,
    P_GALLERY_Y,
    P_GALLERY_Z,
    P_RAILING,
    P_RAIL_Y,
    P_RAIL_TOP,
    P_RAIL_N_MID,
    P_RAIL_POST_SPACING,
    P_RAIL_BAR,
    P_RAIL_X0,
    P_RAIL_X1,
    P_LINE_ALPHA,
    P_LINE_WEAR,
    P_GLOW,
    P_GLOW_W,
    P_FLOOR_GLOSS,
    P_AO,
    P_SEED,
    P_PLAYER_BOX_TOP,
    P_N_JOINTS,
    P_CROWD_DENSITY,
    P_ROW_DEPTH,
    P_SEAT_W,
    P_CROWD_SEED,
    P_STAND_BACK,
    N_PARAMS,
) = range(77)

MAX_JOINTS = 8


# ----------------------------------------------------------------------------------------------
# Small helpers


@_kernel
def _noise(tex: np.ndarray, u: float, v: float) -> float:
    """Bilinear, wrapping lookup in a square noise texture at texel coordinates (u, v); [-1, 1]."""
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


@_kernel
def _hash01(i: int, j: int, seed: int) -> float:
    h = (i * 374761393 + j * 668265263 + seed * 982451653) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return h / 4294967296.0


@_inline_kernel
def _surface_ab(surface: int, x: float, y: float, z: float) -> tuple[float, float]:
    """2D coordinates on a surface, metres: the frame adverts are placed in."""
    if (
        surface == S_FLOOR
        or surface == S_HALL_FLOOR
        or surface == S_GALLERY
        or surface == S_CEILING
    ):
        return x, y
    if (
        surface == S_LEFT
        or surface == S_RIGHT
        or surface == S_HALL_LEFT
        or surface == S_HALL_RIGHT
        or surface == S_FIN
    ):
        return y, -z
    if surface == S_STAND_LEFT or surface == S_STAND_RIGHT or surface == S_STAND_BACK:
        return y, -z
    return x, -z


@_inline_kernel
def _sample_texture(
    texs: np.ndarray, t: int, u: float, v: float
) -> tuple[float, float, float, float]:
    """Bilinear BGRA lookup in texture t (uint8, 4 bytes a texel: small enough to stay in cache) at
    normalised (u, v) in [0, 1] (v down); alpha comes back in 0..1."""
    th, tw = texs.shape[1], texs.shape[2]
    x = min(max(u * tw - 0.5, 0.0), tw - 1.001)
    y = min(max(v * th - 0.5, 0.0), th - 1.001)
    j0 = int(x)
    i0 = int(y)
    a = x - j0
    b = y - i0
    w00 = (1.0 - a) * (1.0 - b)
    w01 = a * (1.0 - b)
    w10 = (1.0 - a) * b
    w11 = a * b
    t00 = texs[t, i0, j0]
    t01 = texs[t, i0, j0 + 1]
    t10 = texs[t, i0 + 1, j0]
    t11 = texs[t, i0 + 1, j0 + 1]
    return (
        w00 * t00[0] + w01 * t01[0] + w10 * t10[0] + w11 * t11[0],
        w00 * t00[1] + w01 * t01[1] + w10 * t10[1] + w11 * t11[1],
        w00 * t00[2] + w01 * t01[2] + w10 * t10[2] + w11 * t11[2],
        (w00 * t00[3] + w01 * t01[3] + w10 * t10[3] + w11 * t11[3]) / 255.0,
    )


@_inline_kernel
def _nearest_line(
    segs: np.ndarray, lo: int, hi: int, x: float, y: float, z: float
) -> tuple[float, int]:
    """Distance (m) from a point to the nearest painted segment in segs[lo:hi], and its index."""
    best = 1e30
    kb = -1
    for k in range(lo, hi):
        ax, ay, az = segs[k, 0], segs[k, 1], segs[k, 2]
        ex = segs[k, 3] - ax
        ey = segs[k, 4] - ay
        ez = segs[k, 5] - az
        qx = x - ax
        qy = y - ay
        qz = z - az
        t = (qx * ex + qy * ey + qz * ez) / (ex * ex + ey * ey + ez * ez)
        t = min(max(t, 0.0), 1.0)
        rx = qx - t * ex
        ry = qy - t * ey
        rz = qz - t * ez
        d2 = rx * rx + ry * ry + rz * rz
        if d2 < best:
            best = d2
            kb = k
    return np.sqrt(best), kb


@_inline_kernel
def _nearest_arc(arcs: np.ndarray, x: float, y: float) -> tuple[float, int]:
    """Distance (m) from a floor point to the nearest painted arc (cx, cy, r, a0, a1, colour)."""
    best = 1e30
    kb = -1
    for k in range(arcs.shape[0]):
        qx = x - arcs[k, 0]
        qy = y - arcs[k, 1]
        rho = np.sqrt(qx * qx + qy * qy)
        d = abs(rho - arcs[k, 2])
        if d >= best:
            continue
        a0, a1 = arcs[k, 3], arcs[k, 4]
        if a1 - a0 < 6.283:
            ang = np.arctan2(qy, qx)
            while ang < a0:
                ang += 2.0 * np.pi
            while ang > a0 + 2.0 * np.pi:
                ang -= 2.0 * np.pi
            if ang > a1:
                continue
        best = d
        kb = k
    return best, kb


# ----------------------------------------------------------------------------------------------
# Intersections


@_inline_kernel
def _side_top(p: np.ndarray, y: float) -> float:
    return p[P_SIDE_TOP_FRONT] + (p[P_SIDE_TOP_BACK] - p[P_SIDE_TOP_FRONT]) * y / p[P_L]


@_inline_kernel
def _on_railing(p: np.ndarray, x: float, z: float) -> bool:
    if not (p[P_RAIL_X0] <= x <= p[P_RAIL_X1]):
        return False
    top = p[P_RAIL_TOP]
    bottom = p[P_GALLERY_Z] if p[P_GALLERY] > 0.0 else 0.0
    if z < top - 0.5 * p[P_RAIL_BAR] or z > bottom:
        return False
    half = 0.5 * p[P_RAIL_BAR]
    if abs(z - top) <= half * 1.4:
        return True
    n_mid = int(p[P_RAIL_N_MID])
    for k in range(1, n_mid + 1):
        zk = top + k * (bottom - top) / (n_mid + 1)
        if abs(z - zk) <= half * 0.7:
            return True
    spacing = p[P_RAIL_POST_SPACING]
    offset = (x - p[P_RAIL_X0]) % spacing
    return offset <= p[P_RAIL_BAR]


@_inline_kernel
def _person_part(
    p: np.ndarray, row: int, y: float, a: float, side: int
) -> tuple[int, float, float]:
    """Which part of a seated spectator (row `row`, seat from y) is at height `a` above the row's
    tread: 0 none, 1 hair, 2 face, 3 clothes; with two hashes for the colours."""
    sw = p[P_SEAT_W]
    yy = y / sw + 0.5 * (row % 2)
    seat = int(np.floor(yy))
    seed = int(p[P_CROWD_SEED]) + 101 * side
    if _hash01(row, seat, seed) >= p[P_CROWD_DENSITY]:
        return 0, 0.0, 0.0
    dxm = (yy - seat - 0.5 - 0.3 * (_hash01(seat, row, seed + 3) - 0.5)) * sw
    size = 0.88 + 0.24 * _hash01(row, seat, seed + 4)
    h2 = _hash01(row, seat, seed + 6)
    h3 = _hash01(row, seat, seed + 7)
    head = 1.1 * size
    rh = 0.105 * size
    if dxm * dxm + (a - head) * (a - head) < rh * rh:
        if a > head + 0.02 and _hash01(row, seat, seed + 5) < 0.8:
            return 1, h2, h3
        return 2, h2, h3
    half = (0.14 + 0.09 * min(max((a - 0.45) / 0.4, 0.0), 1.0)) * size
    if abs(dxm) < half and 0.3 < a < 0.96 * size:
        return 3, h2, h3
    return 0, h2, h3


@_inline_kernel
def _crowd_people(
    p: np.ndarray,
    side: int,
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
    best: float,
) -> float:
    """Distance to the nearest spectator cut-out on a stand (one vertical plane per row), or -1.
    Stands: 0 beyond the left wall, 1 beyond the right wall (rows along y), 2 behind the back wall
    (rows along x)."""
    rd = p[P_ROW_DEPTH]
    tn = p[P_STAND_TAN]
    if side == 0:
        ou = -p[P_STAND_OFFSET] - ox
        du = -dx
    elif side == 1:
        ou = ox - p[P_W] - p[P_STAND_OFFSET]
        du = dx
    else:
        ou = oy - p[P_L] - p[P_STAND_OFFSET]
        du = dy
    if du <= 0.0 or rd <= 0.0:
        return -1.0
    r = max(0, int(np.ceil(ou / rd - 0.5)))
    for _ in range(60):
        s = ((r + 0.5) * rd - ou) / du
        if s >= best:
            return -1.0
        if s > 1e-7:
            if side < 2:
                along = oy + s * dy
                inside = p[P_STAND_Y0] <= along <= p[P_STAND_Y1]
            else:
                along = ox + s * dx
                inside = p[P_HALL_X0] <= along <= p[P_HALL_X1]
            if inside:
                base = -tn * (r + 0.5) * rd
                a = base - (oz + s * dz)
                if 0.0 < a < 1.4 and base - 1.4 > p[P_HALL_Z]:
                    part, _, _ = _person_part(p, r, along, a, side)
                    if part > 0:
                        return s
        r += 1
    return -1.0


@_kernel
def _nearest_opaque(
    p: np.ndarray,
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
    people: bool = True,
) -> tuple[float, int]:
    """Distance along the ray and surface of the nearest opaque hit (glass is not opaque).
    `people=False` leaves the spectators out (cheaper, for reflections)."""
    eps = 1e-7
    best = 1e30
    surface = -1
    w, length = p[P_W], p[P_L]
    court = p[P_HAS_COURT] > 0.0
    # floors (court / sport area and the hall floor): z = 0 seen from above
    if dz > 0.0 and oz < 0.0:
        s = -oz / dz
        if s < best:
            x = ox + s * dx
            y = oy + s * dy
            best = s
            if p[P_AREA_X0] <= x <= p[P_AREA_X1] and p[P_AREA_Y0] <= y <= p[P_AREA_Y1]:
                surface = S_FLOOR
            else:
                surface = S_HALL_FLOOR
    # ceiling
    if dz < 0.0:
        s = (p[P_HALL_Z] - oz) / dz
        if eps < s < best:
            best = s
            surface = S_CEILING
    # hall walls
    if dx < 0.0:
        s = (p[P_HALL_X0] - ox) / dx
        if eps < s < best:
            best = s
            surface = S_HALL_LEFT
    elif dx > 0.0:
        s = (p[P_HALL_X1] - ox) / dx
        if eps < s < best:
            best = s
            surface = S_HALL_RIGHT
    if dy < 0.0:
        s = (p[P_HALL_Y0] - oy) / dy
        if eps < s < best:
            best = s
            surface = S_HALL_FRONT
    elif dy > 0.0:
        s = (p[P_HALL_Y1] - oy) / dy
        if eps < s < best:
            best = s
            surface = S_HALL_BACK
    # gallery slab top (z = gallery z, y >= gallery y), seen from above
    if p[P_GALLERY] > 0.0 and dz > 0.0 and oz < p[P_GALLERY_Z]:
        s = (p[P_GALLERY_Z] - oz) / dz
        if eps < s < best and oy + s * dy >= p[P_GALLERY_Y]:
            best = s
            surface = S_GALLERY
    # railing (bars on the plane y = rail y)
    if p[P_RAILING] > 0.0 and dy != 0.0:
        s = (p[P_RAIL_Y] - oy) / dy
        if eps < s < best and _on_railing(p, ox + s * dx, oz + s * dz):
            best = s
            surface = S_RAILING
    # stands: planes rising away from the side walls, z = tan * (x + offset) on the left
    if p[P_STAND_LEFT] > 0.0:
        tn = p[P_STAND_TAN]
        den = dz - tn * dx
        if den != 0.0:
            s = (tn * (ox + p[P_STAND_OFFSET]) - oz) / den
            if eps < s < best:
                x = ox + s * dx
                y = oy + s * dy
                if x <= -p[P_STAND_OFFSET] and p[P_STAND_Y0] <= y <= p[P_STAND_Y1]:
                    best = s
                    surface = S_STAND_LEFT
    if p[P_STAND_RIGHT] > 0.0:
        tn = p[P_STAND_TAN]
        den = dz + tn * dx
        if den != 0.0:
            s = (tn * (w + p[P_STAND_OFFSET] - ox) - oz) / den
            if eps < s < best:
                x = ox + s * dx
                y = oy + s * dy
                if x >= w + p[P_STAND_OFFSET] and p[P_STAND_Y0] <= y <= p[P_STAND_Y1]:
                    best = s
                    surface = S_STAND_RIGHT
    if p[P_STAND_BACK] > 0.0:
        tn = p[P_STAND_TAN]
        den = dz + tn * dy
        if den != 0.0:
            s = (tn * (p[P_L] + p[P_STAND_OFFSET] - oy) - oz) / den
            if eps < s < best and oy + s * dy >= p[P_L] + p[P_STAND_OFFSET]:
                best = s
                surface = S_STAND_BACK
    for side in range(3 if people else 0):
        on = (
            (side == 0 and p[P_STAND_LEFT] > 0.0)
            or (side == 1 and p[P_STAND_RIGHT] > 0.0)
            or (side == 2 and p[P_STAND_BACK] > 0.0)
        )
        if on:
            s = _crowd_people(p, side, ox, oy, oz, dx, dy, dz, best)
            if s > 0.0:
                best = s
                surface = (
                    S_STAND_LEFT if side == 0 else (S_STAND_RIGHT if side == 1 else S_STAND_BACK)
                )
    if not court:
        return best, surface
    # front wall (always opaque)
    if dy != 0.0:
        s = -oy / dy
        if eps < s < best:
            x = ox + s * dx
            z = oz + s * dz
            if 0.0 <= x <= w and p[P_FRONT_TOP] <= z <= 0.0:
                best = s
                surface = S_FRONT
    # plaster side walls
    if p[P_SIDE_GLASS] <= 0.0 and dx != 0.0:
        for side in range(2):
            wall_x = 0.0 if side == 0 else w
            s = (wall_x - ox) / dx
            if eps < s < best:
                y = oy + s * dy
                z = oz + s * dz
                if 0.0 <= y <= length and _side_top(p, y) <= z <= 0.0:
                    best = s
                    surface = S_LEFT if side == 0 else S_RIGHT
    # plaster back wall
    if p[P_BACK_GLASS] <= 0.0 and dy != 0.0:
        s = (length - oy) / dy
        if eps < s < best:
            x = ox + s * dx
            z = oz + s * dz
            if 0.0 <= x <= w and p[P_BACK_TOP] <= z <= 0.0:
                best = s
                surface = S_BACK
    return best, surface


@_inline_kernel
def _glass_crossing(
    p: np.ndarray,
    joints: np.ndarray,
    k: int,
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
) -> float:
    """Distance to glass pane k (0 back, 1 left, 2 right, 3 + j fin j) or -1 when missed."""
    if p[P_HAS_COURT] <= 0.0:
        return -1.0
    w, length = p[P_W], p[P_L]
    if k == 0:
        if p[P_BACK_GLASS] <= 0.0 or dy == 0.0:
            return -1.0
        s = (length - oy) / dy
        if s <= 1e-7:
            return -1.0
        x = ox + s * dx
        z = oz + s * dz
        if 0.0 <= x <= w and p[P_BACK_TOP] <= z <= 0.0:
            return s
        return -1.0
    if k <= 2:
        if p[P_SIDE_GLASS] <= 0.0 or dx == 0.0:
            return -1.0
        wall_x = 0.0 if k == 1 else w
        s = (wall_x - ox) / dx
        if s <= 1e-7:
            return -1.0
        y = oy + s * dy
        z = oz + s * dz
        if 0.0 <= y <= length and _side_top(p, y) <= z <= 0.0:
            return s
        return -1.0
    j = k - 3
    if p[P_BACK_GLASS] <= 0.0 or p[P_FIN_DEPTH] <= 0.0 or dx == 0.0 or j >= int(p[P_N_JOINTS]):
        return -1.0
    s = (joints[j] - ox) / dx
    if s <= 1e-7:
        return -1.0
    y = oy + s * dy
    z = oz + s * dz
    if length <= y <= length + p[P_FIN_DEPTH] and p[P_BACK_TOP] <= z <= 0.0:
        return s
    return -1.0


# ----------------------------------------------------------------------------------------------
# Shading


@_inline_kernel
def _surface_normal(surface: int) -> tuple[float, float, float]:
    if (
        surface == S_FLOOR
        or surface == S_HALL_FLOOR
        or surface == S_CEILING
        or surface == S_GALLERY
    ):
        return 0.0, 0.0, 1.0
    if surface == S_FRONT or surface == S_BACK or surface == S_HALL_FRONT or surface == S_HALL_BACK:
        return 0.0, 1.0, 0.0
    return 1.0, 0.0, 0.0


@_kernel
def _paint(
    p: np.ndarray,
    segs: np.ndarray,
    seg_lo: np.ndarray,
    seg_hi: np.ndarray,
    arcs: np.ndarray,
    line_cols: np.ndarray,
    tex: np.ndarray,
    surface: int,
    x: float,
    y: float,
    z: float,
    b: float,
    g: float,
    r: float,
    light: float,
    footprint_scale: float,
    dx: float,
    dy: float,
    dz: float,
) -> tuple[float, float, float, bool, float]:
    """Painted lines (and their LED glow) over a surface colour; also says whether it was paint and
    how far (m) the point is from the nearest line's edge (negative inside the line).

    Lines are anti-aliased analytically: the sample stands for a footprint of `footprint_scale`
    (depth / focal length) metres across the ray, stretched by the angle between the ray (dx, dy,
    dz) and the direction across the line; the paint covers the part of that footprint inside the
    line's width. So even one sample per pixel puts a thin line's weight at its true position."""
    lo, hi = seg_lo[surface], seg_hi[surface]
    if lo >= hi and (surface != S_FLOOR or arcs.shape[0] == 0):
        return b, g, r, False, 1e30
    d, k = _nearest_line(segs, lo, hi, x, y, z)
    colour = int(segs[k, 7]) if k >= 0 else 0
    # the direction across the nearest line, in the surface
    nx, ny, nz = _surface_normal(surface)
    ax = ay = az = 0.0
    if k >= 0:
        tx = segs[k, 3] - segs[k, 0]
        ty = segs[k, 4] - segs[k, 1]
        tz = segs[k, 5] - segs[k, 2]
        ax = ty * nz - tz * ny
        ay = tz * nx - tx * nz
        az = tx * ny - ty * nx
    if surface == S_FLOOR and arcs.shape[0] > 0:
        da, ka = _nearest_arc(arcs, x, y)
        if da < d:
            d = da
            colour = int(arcs[ka, 5])
            ax = x - arcs[ka, 0]
            ay = y - arcs[ka, 1]
            az = 0.0
    half = p[P_HALF_LINE]
    lb, lg, lr = line_cols[colour, 0], line_cols[colour, 1], line_cols[colour, 2]
    glow = p[P_GLOW]
    norm_a = np.sqrt(ax * ax + ay * ay + az * az)
    norm_d = np.sqrt(dx * dx + dy * dy + dz * dz)
    cos_ad = (ax * dx + ay * dy + az * dz) / max(norm_a * norm_d, 1e-12)
    fp = footprint_scale / np.sqrt(max(1.0 - cos_ad * cos_ad, 0.0025))
    # overlap of the footprint [d - fp/2, d + fp/2] with the paint [-half, half]
    cover = (min(d + 0.5 * fp, half) - max(d - 0.5 * fp, -half)) / fp
    if cover > 0.0:
        cover = min(cover, 1.0)
        alpha = p[P_LINE_ALPHA] * cover
        if p[P_LINE_WEAR] > 0.0:
            wear = 0.5 + 0.5 * _noise(tex, x / 0.03 + 11.0 * surface, y / 0.03 + z / 0.03)
            alpha *= 1.0 - p[P_LINE_WEAR] * wear
        lit = light if glow <= 0.0 else 1.0 + glow
        b = b * (1.0 - alpha) + alpha * lb * lit
        g = g * (1.0 - alpha) + alpha * lg * lit
        r = r * (1.0 - alpha) + alpha * lr * lit
    if glow > 0.0 and d > half:
        e = (d - half) / p[P_GLOW_W]
        if e < 3.0:
            f = glow * np.exp(-e * e)
            b += f * lb
            g += f * lg
            r += f * lr
    return b, g, r, cover > 0.5, d - half


@_kernel
def _adverts(
    ads: np.ndarray,
    ad_lo: np.ndarray,
    ad_hi: np.ndarray,
    texs: np.ndarray,
    surface: int,
    a: float,
    bb: float,
    b: float,
    g: float,
    r: float,
    light: float,
) -> tuple[float, float, float, float]:
    """Adverts/decals over a surface colour; returns the colour and the total opacity added."""
    cover = 0.0
    for k in range(ad_lo[surface], ad_hi[surface]):
        a0, a1, b0, b1 = ads[k, 1], ads[k, 2], ads[k, 3], ads[k, 4]
        if a0 <= a <= a1 and b0 <= bb <= b1:
            u = (a - a0) / (a1 - a0)
            if ads[k, 7] > 0.0:
                u = 1.0 - u
            if surface == S_FLOOR or surface == S_HALL_FLOOR or surface == S_CEILING:
                v = (bb - b0) / (b1 - b0)
            else:
                v = (b1 - bb) / (b1 - b0)
            tb, tg, tr, ta = _sample_texture(texs, int(ads[k, 5]), u, v)
            alpha = ta * ads[k, 6]
            emissive = ads[k, 8]
            lit = light * (1.0 - emissive) + emissive
            b = b * (1.0 - alpha) + alpha * tb * lit
            g = g * (1.0 - alpha) + alpha * tg * lit
            r = r * (1.0 - alpha) + alpha * tr * lit
            cover = cover + (1.0 - cover) * alpha
    return b, g, r, cover


@_inline_kernel
def _pool(p: np.ndarray, strength: float, x: float, y: float) -> float:
    """Light pooled over the middle of the floor area, falling off towards its edges."""
    cx = 0.5 * (p[P_AREA_X0] + p[P_AREA_X1])
    cy = 0.5 * (p[P_AREA_Y0] + p[P_AREA_Y1])
    hx = max(0.5 * (p[P_AREA_X1] - p[P_AREA_X0]), 1.0)
    hy = max(0.5 * (p[P_AREA_Y1] - p[P_AREA_Y0]), 1.0)
    e = ((x - cx) / hx) ** 2 + ((y - cy) / hy) ** 2
    return max(1.0 - strength * 0.5 * e, 0.5)


@_inline_kernel
def _lod(scale_m: float, footprint_m: float) -> float:
    """How much of a texture detail of size `scale_m` survives in a sample of footprint
    `footprint_m` (1 = all of it): details smaller than a sample are averaged away, not aliased."""
    return min(1.0, scale_m / max(footprint_m, 1e-9))


@_kernel
def _material(
    p: np.ndarray,
    surf: np.ndarray,
    tex: np.ndarray,
    surface: int,
    x: float,
    y: float,
    z: float,
    fp: float,
) -> tuple[float, float, float]:
    """Base colour of a surface point before paint and adverts; `fp` is the sample's footprint (m),
    details finer than it fade to their average."""
    kind = int(surf[surface, SF_KIND])
    cb, cg, cr = surf[surface, SF_B], surf[surface, SF_G], surf[surface, SF_R]
    light = surf[surface, SF_LIGHT]
    seed = int(p[P_SEED]) + 7919 * surface
    a, bb = _surface_ab(surface, x, y, z)
    n = light
    if kind == M_PLANKS:
        width, plank_len = surf[surface, 5], surf[surface, 6]
        across, along = (a, bb) if surf[surface, 10] < 0.5 else (bb, a)
        plank = int(np.floor(across / width))
        offset = _hash01(plank, 0, seed) * plank_len
        piece = int(np.floor((along + offset) / plank_len))
        tone = 1.0 + surf[surface, 7] * np.sqrt(_lod(width, fp)) * (
            _hash01(plank, piece + 1, seed) - 0.5
        )
        grain = (
            surf[surface, 8]
            * _lod(0.012, fp)
            * _noise(tex, across / 0.004 + 37.0 * plank, along / 0.08)
        )
        fa = across / width - plank
        fl = (along + offset) / plank_len - piece
        seam = 1.0
        if fp < 0.0024:
            if min(fa, 1.0 - fa) * width < 0.0012 or min(fl, 1.0 - fl) * plank_len < 0.0012:
                seam = 1.0 - surf[surface, 9]
        else:
            seam = 1.0 - surf[surface, 9] * 0.0024 / width
        pool = _pool(p, surf[surface, 11], x, y)
        n = light * pool * (tone + grain) * seam
    elif kind == M_FLAT:
        mottle = surf[surface, 5] * _noise(tex, a / 0.9 + 5.0, bb / 0.9 + 9.0) + surf[
            surface, 6
        ] * _lod(0.02, fp) * _noise(tex, a / 0.01, bb / 0.01)
        pool = _pool(p, surf[surface, 7], x, y)
        under = 0.0
        if surf[surface, 8] > 0.0:
            plank = int(np.floor(a / 0.07))
            under = (
                surf[surface, 8]
                * 0.04
                * np.sqrt(_lod(0.07, fp))
                * (_hash01(plank, int(np.floor(bb / 1.8)), seed) - 0.5)
            )
        n = light * pool * (1.0 + mottle + under)
    elif kind == M_GLASS_FLOOR:
        size = surf[surface, 5]
        fa = a / size - np.floor(a / size)
        fb = bb / size - np.floor(bb / size)
        joint = 1.0
        if fp < 0.008:
            if min(fa, 1.0 - fa) * size < 0.004 or min(fb, 1.0 - fb) * size < 0.004:
                joint = 1.0 - surf[surface, 6]
        else:
            joint = 1.0 - surf[surface, 6] * 0.016 / size
        n = light * joint * (1.0 + surf[surface, 7] * _noise(tex, a / 0.5, bb / 0.5))
    elif kind == M_CARPET:
        n = light * (
            1.0
            + surf[surface, 5] * _noise(tex, a / surf[surface, 6], bb / surf[surface, 6])
            + 0.5 * surf[surface, 5] * _lod(0.01, fp) * _noise(tex, a / 0.004 + 3.0, bb / 0.004)
        )
    elif kind == M_TILES:
        size = surf[surface, 5]
        ia = int(np.floor(a / size))
        ib = int(np.floor(bb / size))
        fa = a / size - ia
        fb = bb / size - ib
        grout = surf[surface, 6] / size
        tone = 1.0 + surf[surface, 8] * np.sqrt(_lod(size, fp)) * (_hash01(ia, ib, seed) - 0.5)
        if fp < 2.0 * surf[surface, 6]:
            if min(fa, 1.0 - fa) < grout or min(fb, 1.0 - fb) < grout:
                tone = 1.0 - surf[surface, 7]
        else:
            tone *= 1.0 - surf[surface, 7] * 4.0 * grout
        n = light * tone * (1.0 + 0.03 * _noise(tex, a / 0.05, bb / 0.05))
    elif kind == M_PANELS:
        fa = a / surf[surface, 5] - np.floor(a / surf[surface, 5])
        if fp < 0.02:
            joint = 1.0 - surf[surface, 6] if min(fa, 1.0 - fa) * surf[surface, 5] < 0.01 else 1.0
        else:
            joint = 1.0 - surf[surface, 6] * 0.02 / surf[surface, 5]
        dado = surf[surface, 8] if bb < surf[surface, 7] else 1.0
        n = light * joint * dado * (1.0 + surf[surface, 9] * _noise(tex, a / 0.3, bb / 0.3))
    elif kind == M_CEILING:
        n = light * (1.0 + 0.05 * _noise(tex, a / 0.4, bb / 0.4))
        if surf[surface, 10] > 0.0:
            fb = a / surf[surface, 10] - np.floor(a / surf[surface, 10])
            if fb < 0.06:
                n *= 1.0 - surf[surface, 11]
        fx = (a + 0.5 * surf[surface, 7]) / surf[surface, 5] - np.floor(
            (a + 0.5 * surf[surface, 7]) / surf[surface, 5]
        )
        fy = (bb + 0.5 * surf[surface, 8]) / surf[surface, 6] - np.floor(
            (bb + 0.5 * surf[surface, 8]) / surf[surface, 6]
        )
        if fx * surf[surface, 5] < surf[surface, 7] and fy * surf[surface, 6] < surf[surface, 8]:
            return surf[surface, 9], surf[surface, 9], surf[surface, 9] * 0.97
    elif kind == M_CROWD:
        return _crowd(p, surf, tex, surface, x, y, z)
    elif kind == M_METAL:
        n = light * (1.0 + surf[surface, 5] * _noise(tex, a / 0.2, bb / 0.02))
    else:  # plaster
        mottle = surf[surface, 5] * (
            0.4 * _lod(0.04, fp) * _noise(tex, a / 0.02, bb / 0.02)
            + 0.6 * _noise(tex, a / 0.3 + 97.0, bb / 0.3)
        )
        n = light * (1.0 + mottle)
        if surf[surface, 6] > 0.0:
            # ball marks: dark specks, densest at mid height
            band = np.exp(-((bb - 1.6) ** 2) / 1.2)
            if fp < 0.012:
                spot = _noise(tex, a / 0.012 + 41.0, bb / 0.012 + 13.0)
                if spot > 1.0 - surf[surface, 6] * band:
                    n *= 1.0 - surf[surface, 7]
            else:
                n *= 1.0 - surf[surface, 7] * 0.15 * surf[surface, 6] * band
        if surf[surface, 8] > 0.0:
            n *= 1.0 - surf[surface, 8] * np.exp(-bb / 0.35)
        # uneven lighting: brighter or darker with height and along the wall
        extent = p[P_W] if surface == S_FRONT or surface == S_BACK else p[P_L]
        n *= max(
            1.0
            + surf[surface, 9] * (bb - 2.5) / 2.5
            + surf[surface, 10] * (2.0 * a / extent - 1.0),
            0.3,
        )
    return cb * n, cg * n, cr * n


@_kernel
def _crowd(
    p: np.ndarray,
    surf: np.ndarray,
    tex: np.ndarray,
    surface: int,
    x: float,
    y: float,
    z: float,
) -> tuple[float, float, float]:
    """A stand: seated spectators (cut-outs on each row's plane) over the stepped seating."""
    light = surf[surface, SF_LIGHT]
    if surface == S_STAND_LEFT:
        side, u, y = 0, -p[P_STAND_OFFSET] - x, y
    elif surface == S_STAND_RIGHT:
        side, u, y = 1, x - p[P_W] - p[P_STAND_OFFSET], y
    else:
        side, u, y = 2, y - p[P_L] - p[P_STAND_OFFSET], x  # rows along x: x is the seat direction
    rd = p[P_ROW_DEPTH]
    row = int(np.floor(u / rd))
    fr = u / rd - row
    if abs(fr - 0.5) < 1e-6 * max(1.0, u):
        a = -p[P_STAND_TAN] * (row + 0.5) * rd - z
        part, h2, h3 = _person_part(p, row, y, a, side)
        lit = light * surf[surface, 8]
        if part == 1:
            return 22.0 * lit, 26.0 * lit, 30.0 * lit
        if part == 2:
            skin = 0.3 + 0.7 * h3
            return 100.0 * skin * lit, 135.0 * skin * lit, 185.0 * skin * lit
        if part == 3:
            shade = 0.75 + 0.25 * min(max((a - 0.3) / 0.6, 0.0), 1.0)
            if h2 < 0.55:
                grey = (18.0 + 40.0 * h3) * shade
                return grey * lit, grey * lit, grey * lit
            if h2 < 0.78:
                grey = (80.0 + 110.0 * h3) * shade
                return grey * lit, grey * lit, grey * lit
            k = int(h3 * 7.0)
            if k == 0:
                b, g, r = 40.0, 40.0, 170.0
            elif k == 1:
                b, g, r = 150.0, 80.0, 30.0
            elif k == 2:
                b, g, r = 50.0, 120.0, 50.0
            elif k == 3:
                b, g, r = 40.0, 170.0, 200.0
            elif k == 4:
                b, g, r = 120.0, 50.0, 110.0
            elif k == 5:
                b, g, r = 130.0, 120.0, 40.0
            else:
                b, g, r = 150.0, 110.0, 200.0
            grey = (b + g + r) / 3.0
            return (
                (0.6 * b + 0.4 * grey) * lit * shade,
                (0.6 * g + 0.4 * grey) * lit * shade,
                (0.6 * r + 0.4 * grey) * lit * shade,
            )
    # the stepped seating behind: seat backs in the stand's colour, dark gaps between rows
    shade = 0.35 + 0.65 * min(fr * 1.6, 1.0)
    seat = y / p[P_SEAT_W] + 0.5 * (row % 2)
    fs = seat - np.floor(seat)
    if fs < 0.08 or fs > 0.92:
        shade *= 0.6
    return (
        surf[surface, SF_B] * shade * light,
        surf[surface, SF_G] * shade * light,
        surf[surface, SF_R] * shade * light,
    )


@_inline_kernel
def _shade_opaque(
    sc: tuple,
    surface: int,
    x: float,
    y: float,
    z: float,
    fp: float,
    footprint_scale: float,
    dx: float,
    dy: float,
    dz: float,
) -> tuple[float, float, float, float, float]:
    """Colour of an opaque surface point (material, tin, adverts, paint, corner shading), the
    distance (m) to the nearest painted line's edge and the adverts' cover there."""
    p, surf, segs, seg_lo, seg_hi, arcs, line_cols, ads, ad_lo, ad_hi, texs, tex, _ = sc
    if surface < 0:
        return 0.0, 0.0, 0.0, 1e30, 0.0
    light = surf[surface, SF_LIGHT]
    if surface == S_RAILING:
        b, g, r = (
            surf[surface, SF_B] * light,
            surf[surface, SF_G] * light,
            surf[surface, SF_R] * light,
        )
        return b, g, r, 1e30, 0.0
    if surface == S_FRONT and z >= p[P_TIN_TOP]:
        # the tin (board) below the tin line
        wob = 1.0 + 0.03 * _noise(tex, x / 0.05, z / 0.05)
        b, g, r = p[P_TIN_B] * light * wob, p[P_TIN_G] * light * wob, p[P_TIN_R] * light * wob
    else:
        b, g, r = _material(p, surf, tex, surface, x, y, z, fp)
    a, bb = _surface_ab(surface, x, y, z)
    cover = 0.0
    if ad_hi[surface] > ad_lo[surface]:
        b, g, r, cover = _adverts(ads, ad_lo, ad_hi, texs, surface, a, bb, b, g, r, light)
    b, g, r, _, edge = _paint(
        p,
        segs,
        seg_lo,
        seg_hi,
        arcs,
        line_cols,
        tex,
        surface,
        x,
        y,
        z,
        b,
        g,
        r,
        light,
        footprint_scale,
        dx,
        dy,
        dz,
    )
    if p[P_HAS_COURT] > 0.0 and p[P_AO] > 0.0 and surface <= S_BACK:
        # soft darkening into the corners and along the floor junctions
        w, length = p[P_W], p[P_L]
        if surface == S_FLOOR:
            dist = min(min(x, w - x), min(y, length - y))
        elif surface == S_FRONT or surface == S_BACK:
            dist = min(min(x, w - x), -z)
        else:
            dist = min(min(y, length - y), -z)
        occl = 1.0 - p[P_AO] * np.exp(-max(dist, 0.0) / 0.2)
        b *= occl
        g *= occl
        r *= occl
    return b, g, r, edge, cover


@_inline_kernel
def _trace_simple(
    sc: tuple,
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
    depth0: float,
    inv_f: float,
    sample_inv_f: float,
    lod: float,
    through_glass: bool,
) -> tuple[float, float, float, float]:
    """A secondary ray (a reflection) from a point `depth0` (camera depth) along the camera ray:
    nearest opaque colour, dimmed by the glass it crosses; a painted line on crossed glass shows as
    paint (`through_glass=False` skips the panes: cheaper, for faint floor reflections). No further
    reflections. Also returns how many pixel footprints the nearest painted line's edge is away in
    the reflection, so thin mirrored lines get supersampled too; textures are filtered `lod` times
    coarser than the pixel."""
    p, surf, segs, seg_lo, seg_hi, arcs, line_cols, _, _, _, _, tex, joints = sc
    s_hit, surface = _nearest_opaque(p, ox, oy, oz, dx, dy, dz, False)
    x = ox + s_hit * dx
    y = oy + s_hit * dy
    z = oz + s_hit * dz
    if surface < 0:
        return 0.0, 0.0, 0.0, 1e30
    fp = _footprint(surface, depth0 + s_hit, dx, dy, dz, inv_f)
    b, g, r, edge, _ = _shade_opaque(
        sc, surface, x, y, z, lod * fp, (depth0 + s_hit) * sample_inv_f, dx, dy, dz
    )
    near = edge / fp if edge < 1e29 else 1e30
    nearest_paint = 1e30
    pb = 0.0
    pg = 0.0
    pr = 0.0
    for k in range(3 if through_glass else 0):
        s = _glass_crossing(p, joints, k, ox, oy, oz, dx, dy, dz)
        if s < 0.0 or s >= s_hit:
            continue
        t = p[P_GLASS_T]
        b = b * t * p[P_TINT_B]
        g = g * t * p[P_TINT_G]
        r = r * t * p[P_TINT_R]
        if s < nearest_paint:
            gs = S_BACK if k == 0 else (S_LEFT if k == 1 else S_RIGHT)
            gx = ox + s * dx
            gy = oy + s * dy
            gz = oz + s * dz
            light = surf[gs, SF_LIGHT]
            qb, qg, qr, painted, edge = _paint(
                p,
                segs,
                seg_lo,
                seg_hi,
                arcs,
                line_cols,
                tex,
                gs,
                gx,
                gy,
                gz,
                0.0,
                0.0,
                0.0,
                light,
                (depth0 + s) * sample_inv_f,
                dx,
                dy,
                dz,
            )
            if edge < 1e29:
                near = min(near, edge / _footprint(gs, depth0 + s, dx, dy, dz, inv_f))
            if painted:
                nearest_paint = s
                pb, pg, pr = qb, qg, qr
    if nearest_paint < 1e29:
        return pb, pg, pr, near
    return b, g, r, near


@_inline_kernel
def _slab(
    lo: float, hi: float, o: float, d: float, s_lo: float, s_hi: float
) -> tuple[float, float]:
    """Clip the ray's parameter interval [s_lo, s_hi] to the slab lo <= o + s d <= hi."""
    if d == 0.0:
        if o < lo or o > hi:
            return 1.0, 0.0
        return s_lo, s_hi
    s0 = (lo - o) / d
    s1 = (hi - o) / d
    if s0 > s1:
        s0, s1 = s1, s0
    return max(s_lo, s0), min(s_hi, s1)


@_inline_kernel
def _box_entry(
    p: np.ndarray, ox: float, oy: float, oz: float, dx: float, dy: float, dz: float
) -> float:
    """Distance at which the ray enters the court volume where players stand (-1: never)."""
    lo, hi = _slab(0.0, p[P_W], ox, dx, 0.0, 1e30)
    lo, hi = _slab(0.0, p[P_L], oy, dy, lo, hi)
    lo, hi = _slab(p[P_PLAYER_BOX_TOP], 0.0, oz, dz, lo, hi)
    if lo > hi:
        return -1.0
    return lo


@_inline_kernel
def _back_glass_fitting(
    p: np.ndarray, joints: np.ndarray, x: float, z: float
) -> tuple[float, float]:
    """What covers the back glass at (x, z): (opacity, brightness) of metal or joints; 0 = clear."""
    h = -z
    w = p[P_W]
    # top rail and corner posts
    if p[P_TOP_RAIL_H] > 0.0 and z <= p[P_BACK_TOP] + p[P_TOP_RAIL_H]:
        return 1.0, 0.9 + 0.2 * (z - p[P_BACK_TOP]) / p[P_TOP_RAIL_H]
    if p[P_CORNER_POST_W] > 0.0 and (x < p[P_CORNER_POST_W] or x > w - p[P_CORNER_POST_W]):
        return 1.0, 0.8
    # door posts and the door's gaps and handle
    d0, d1 = p[P_DOOR_X0], p[P_DOOR_X1]
    if d1 > d0:
        pw = p[P_DOOR_POST_W]
        if pw > 0.0 and (abs(x - d0) < 0.5 * pw or abs(x - d1) < 0.5 * pw):
            return 1.0, 0.85
        if abs(x - d0) < 0.006 or abs(x - d1) < 0.006:
            return 0.7, 0.35
        hx = d1 - 0.09 if d1 - d0 > 0.3 else d0 + 0.05
        if abs(x - hx) < 0.018 and 0.85 < h < 1.25:
            return 1.0, 1.1
        if abs(x - d0) < 0.05 and (abs(h - 0.35) < 0.06 or abs(h - 1.85) < 0.06):
            return 1.0, 1.0  # hinges
    n = int(p[P_N_JOINTS])
    for j in range(n):
        dxj = abs(x - joints[j])
        if dxj < 0.5 * p[P_CLAMP_W]:
            for zc in (p[P_CLAMP_Z0], p[P_CLAMP_Z1], p[P_CLAMP_Z2]):
                if zc > 0.0 and abs(h - zc) < 0.5 * p[P_CLAMP_H]:
                    return 1.0, 1.15
        if dxj < 0.004:
            return 0.5, 0.6
    return 0.0, 1.0


@_inline_kernel
def _footprint(surface: int, s: float, dx: float, dy: float, dz: float, inv_f: float) -> float:
    """Size (m) of a pixel's footprint on a surface hit at ray parameter s (the ray's camera-z
    component is 1, so s is the depth), stretched by the grazing angle."""
    norm = np.sqrt(dx * dx + dy * dy + dz * dz)
    if (
        surface == S_FLOOR
        or surface == S_HALL_FLOOR
        or surface == S_CEILING
        or surface == S_GALLERY
    ):
        c = abs(dz) / norm
    elif (
        surface == S_FRONT or surface == S_BACK or surface == S_HALL_FRONT or surface == S_HALL_BACK
    ):
        c = abs(dy) / norm
    else:
        c = abs(dx) / norm
    return s * inv_f / max(c, 0.15)


@_kernel
def _trace_primary(
    sc: tuple,
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
    inv_f: float,
    sample_inv_f: float,
    lod_inv_f: float,
) -> tuple[float, float, float, float, float, float, float, float, float]:
    """Colour of a camera ray; (acc b, g, r, transmission) of what lies before the court volume;
    a region code (what the ray met: for finding edges between pixels) and how many pixel
    footprints (`inv_f`: 1 / focal length) the nearest painted line's edge is away (small: the
    pixel needs supersampling). Painted lines are anti-aliased over the sample's footprint
    (`sample_inv_f`), textures filtered to `lod_inv_f`."""
    p, surf, segs, seg_lo, seg_hi, arcs, line_cols, ads, ad_lo, ad_hi, texs, tex, joints = sc
    s_hit, surface = _nearest_opaque(p, ox, oy, oz, dx, dy, dz)
    s_enter = _box_entry(p, ox, oy, oz, dx, dy, dz) if p[P_HAS_COURT] > 0.0 else -1.0
    if s_enter > s_hit:
        s_enter = -1.0
    acc_b = 0.0
    acc_g = 0.0
    acc_r = 0.0
    tr_b = 1.0
    tr_g = 1.0
    tr_r = 1.0
    front_b = 0.0
    front_g = 0.0
    front_r = 0.0
    front_t = 0.0
    front_done = False
    if s_enter == 0.0:
        front_t = 1.0
        front_done = True
    last = 0.0
    stopped = False
    region = float(surface)
    first_pane = -1
    near = 1e30
    s_back = _glass_crossing(p, joints, 0, ox, oy, oz, dx, dy, dz)
    s_left = _glass_crossing(p, joints, 1, ox, oy, oz, dx, dy, dz)
    s_right = _glass_crossing(p, joints, 2, ox, oy, oz, dx, dy, dz)
    n_fins = int(p[P_N_JOINTS]) if oy > p[P_L] and p[P_FIN_DEPTH] > 0.0 else 0
    for _ in range(8):
        # the next glass pane along the ray
        best = s_hit
        kb = -1
        if last < s_back < best:
            best = s_back
            kb = 0
        if last < s_left < best:
            best = s_left
            kb = 1
        if last < s_right < best:
            best = s_right
            kb = 2
        for k in range(3, 3 + n_fins):
            s = _glass_crossing(p, joints, k, ox, oy, oz, dx, dy, dz)
            if last < s < best:
                best = s
                kb = k
        if kb < 0:
            break
        if first_pane < 0:
            first_pane = kb
        if not front_done and s_enter >= 0.0 and best > s_enter + 1e-6:
            front_b, front_g, front_r = acc_b, acc_g, acc_r
            front_t = (tr_b + tr_g + tr_r) / 3.0
            front_done = True
        last = best
        x = ox + best * dx
        y = oy + best * dy
        z = oz + best * dz
        if kb >= 3:
            # a glass fin seen almost edge-on: darker and greener, a dark polished front edge
            t = 0.86
            if y > p[P_L] + p[P_FIN_DEPTH] - 0.012:
                t = 0.45
            elif y < p[P_L] + 0.12:
                h = -z
                for zc in (p[P_CLAMP_Z0], p[P_CLAMP_Z1], p[P_CLAMP_Z2]):
                    if zc > 0.0 and abs(h - zc) < 0.5 * p[P_CLAMP_H]:
                        t = 0.0
            if t == 0.0:
                light = surf[S_BACK, SF_LIGHT] * 1.1
                acc_b += tr_b * p[P_METAL_B] * light
                acc_g += tr_g * p[P_METAL_G] * light
                acc_r += tr_r * p[P_METAL_R] * light
                tr_b = tr_g = tr_r = 0.0
                stopped = True
                break
            fin_light = surf[S_BACK, SF_LIGHT] * (1.0 - t)
            acc_b += tr_b * 95.0 * fin_light
            acc_g += tr_g * 120.0 * fin_light
            acc_r += tr_r * 90.0 * fin_light
            tr_b *= t * 0.95
            tr_g *= t
            tr_r *= t * 0.92
            continue
        gs = S_BACK if kb == 0 else (S_LEFT if kb == 1 else S_RIGHT)
        light = surf[gs, SF_LIGHT]
        # paint on the glass (out lines): opaque
        qb, qg, qr, painted, edge = _paint(
            p,
            segs,
            seg_lo,
            seg_hi,
            arcs,
            line_cols,
            tex,
            gs,
            x,
            y,
            z,
            0.0,
            0.0,
            0.0,
            light,
            best * sample_inv_f,
            dx,
            dy,
            dz,
        )
        if edge < 1e29:
            near = min(near, edge / _footprint(gs, best, dx, dy, dz, inv_f))
        if painted:
            acc_b += tr_b * qb
            acc_g += tr_g * qg
            acc_r += tr_r * qr
            tr_b = tr_g = tr_r = 0.0
            stopped = True
            break
        # glow of LED lines on the glass adds light
        acc_b += tr_b * qb
        acc_g += tr_g * qg
        acc_r += tr_r * qr
        # metal fittings (back wall) and panel joints (side walls)
        if kb == 0:
            opacity, bright = _back_glass_fitting(p, joints, x, z)
        else:
            opacity, bright = 0.0, 1.0
            spacing = p[P_SIDE_JOINT_SPACING]
            if spacing > 0.0:
                f = y / spacing - np.floor(y / spacing)
                if min(f, 1.0 - f) * spacing < 0.004:
                    opacity, bright = 0.45, 0.7
        if opacity > 0.0:
            metal = light * bright
            acc_b += tr_b * opacity * p[P_METAL_B] * metal
            acc_g += tr_g * opacity * p[P_METAL_G] * metal
            acc_r += tr_r * opacity * p[P_METAL_R] * metal
            tr_b *= 1.0 - opacity
            tr_g *= 1.0 - opacity
            tr_r *= 1.0 - opacity
            if opacity >= 1.0:
                stopped = True
                break
        # decals and adverts printed on the glass
        if ad_hi[gs] > ad_lo[gs]:
            a, bb = _surface_ab(gs, x, y, z)
            db, dg, dr, cover = _adverts(ads, ad_lo, ad_hi, texs, gs, a, bb, 0.0, 0.0, 0.0, light)
            if cover > 0.0:
                acc_b += tr_b * db
                acc_g += tr_g * dg
                acc_r += tr_r * dr
                tr_b *= 1.0 - cover
                tr_g *= 1.0 - cover
                tr_r *= 1.0 - cover
        # the glass: Fresnel reflection (traced once) and tinted transmission with haze
        nx = 1.0 if kb > 0 else 0.0
        ny = 1.0 if kb == 0 else 0.0
        cos_i = abs(dx * nx + dy * ny) / np.sqrt(dx * dx + dy * dy + dz * dz)
        r0 = p[P_R0_BACK] if kb == 0 else p[P_R0_SIDE]
        refl = 0.0
        if r0 > 0.0:
            m = 1.0 - cos_i
            refl = min(r0 * (1.0 + 24.0 * m * m * m * m * m), 0.9)
        if refl * (tr_b + tr_g + tr_r) > 0.12:
            rdx = dx - 2.0 * nx * dx * nx
            rdy = dy - 2.0 * ny * dy * ny
            rb, rg, rr, rnear = _trace_simple(
                sc, x, y, z, rdx, rdy, dz, best, inv_f, sample_inv_f, 2.0 * lod_inv_f / inv_f, True
            )
            near = min(near, rnear)
            acc_b += tr_b * refl * rb
            acc_g += tr_g * refl * rg
            acc_r += tr_r * refl * rr
        # smudged glass: the haze varies over the pane
        ga, gb = _surface_ab(gs, x, y, z)
        smudge = 1.0 + 0.7 * _noise(tex, ga / 0.35 + 17.0 * kb, gb / 0.35)
        haze = p[P_HAZE] * light * (1.0 + 0.5 * (1.0 - cos_i)) * smudge
        t = p[P_GLASS_T] * (1.0 - refl)
        # scattered light: mostly the hall's (neutral), partly the glass's own colour
        acc_b += tr_b * haze * 100.0 * (1.0 + p[P_TINT_B])
        acc_g += tr_g * haze * 100.0 * (1.0 + p[P_TINT_G])
        acc_r += tr_r * haze * 100.0 * (1.0 + p[P_TINT_R])
        tr_b *= t * p[P_TINT_B]
        tr_g *= t * p[P_TINT_G]
        tr_r *= t * p[P_TINT_R]
    region += 32.0 * (first_pane + 1)
    if stopped:
        # an opaque fitting or paint: players inside the court show only if it lies beyond them
        region += 512.0
        if front_done:
            return acc_b, acc_g, acc_r, front_b, front_g, front_r, front_t, region, near
        return acc_b, acc_g, acc_r, acc_b, acc_g, acc_r, 0.0, region, near
    if not front_done and s_enter >= 0.0:
        front_b, front_g, front_r = acc_b, acc_g, acc_r
        front_t = (tr_b + tr_g + tr_r) / 3.0
        front_done = True
    x = ox + s_hit * dx
    y = oy + s_hit * dy
    z = oz + s_hit * dz
    fp = _footprint(surface, s_hit, dx, dy, dz, lod_inv_f) if surface >= 0 else 1.0
    b, g, r, edge, cover = _shade_opaque(sc, surface, x, y, z, fp, s_hit * sample_inv_f, dx, dy, dz)
    if edge < 1e29:
        near = min(near, edge / _footprint(surface, s_hit, dx, dy, dz, inv_f))
        if edge < 0.0:
            region += 1024.0
    if cover > 0.5:
        region += 2048.0
    gloss = p[P_FLOOR_GLOSS]
    if gloss > 0.0 and (surface == S_FLOOR or surface == S_HALL_FLOOR):
        norm = np.sqrt(dx * dx + dy * dy + dz * dz)
        m = 1.0 - abs(dz) / norm
        weight = gloss * (0.35 + 0.65 * m * m * m)
        if weight > 0.03:  # fainter reflections are not worth a ray
            rb, rg, rr, rnear = _trace_simple(
                sc,
                x,
                y,
                z - 1e-6,
                dx,
                dy,
                -dz,
                s_hit,
                inv_f,
                sample_inv_f,
                2.0 * lod_inv_f / inv_f,
                gloss > 0.2,
            )
            if weight > 0.15:
                near = min(near, rnear)
            b = b * (1.0 - weight) + weight * rb
            g = g * (1.0 - weight) + weight * rg
            r = r * (1.0 - weight) + weight * rr
    fin_b = acc_b + tr_b * b
    fin_g = acc_g + tr_g * g
    fin_r = acc_r + tr_r * r
    if not front_done:
        # the ray never reaches the court volume: a player cannot show here
        return fin_b, fin_g, fin_r, fin_b, fin_g, fin_r, 0.0, region, near
    return fin_b, fin_g, fin_r, front_b, front_g, front_r, front_t, region, near


@_inline_kernel
def _camera_ray(
    ray_x: np.ndarray,
    ray_y: np.ndarray,
    ray_ok: np.ndarray,
    grid_origin_px: float,
    grid_step_px: float,
    m: np.ndarray,
    u: float,
    v: float,
) -> tuple[bool, float, float, float]:
    """World direction of the ray through pixel position (u, v), bilinear on the undistortion grid."""
    grid_rows, grid_cols = ray_x.shape
    gv = (v - grid_origin_px) / grid_step_px
    r0 = min(max(int(np.floor(gv)), 0), grid_rows - 2)
    b = gv - r0
    gu = (u - grid_origin_px) / grid_step_px
    c0 = min(max(int(np.floor(gu)), 0), grid_cols - 2)
    a = gu - c0
    if not (
        ray_ok[r0, c0] and ray_ok[r0, c0 + 1] and ray_ok[r0 + 1, c0] and ray_ok[r0 + 1, c0 + 1]
    ):
        return False, 0.0, 0.0, 0.0
    xn = (ray_x[r0, c0] * (1 - a) + ray_x[r0, c0 + 1] * a) * (1 - b) + (
        ray_x[r0 + 1, c0] * (1 - a) + ray_x[r0 + 1, c0 + 1] * a
    ) * b
    yn = (ray_y[r0, c0] * (1 - a) + ray_y[r0, c0 + 1] * a) * (1 - b) + (
        ray_y[r0 + 1, c0] * (1 - a) + ray_y[r0 + 1, c0 + 1] * a
    ) * b
    dx = m[0, 0] * xn + m[0, 1] * yn + m[0, 2]
    dy = m[1, 0] * xn + m[1, 1] * yn + m[1, 2]
    dz = m[2, 0] * xn + m[2, 1] * yn + m[2, 2]
    return True, dx, dy, dz


# a pixel is supersampled when a painted line's edge lies within this many footprints of its centre
# sample, when its region code differs from a neighbour's, or when its colour differs from a
# neighbour's by more than EDGE_CONTRAST grey levels in some channel
LINE_REACH_PX = 1.6
EDGE_CONTRAST = 40.0


@_kernel
def render_kernel(
    ray_x: np.ndarray,
    ray_y: np.ndarray,
    ray_ok: np.ndarray,
    grid_origin_px: float,
    grid_step_px: float,
    samples_per_px: int,
    r_world_from_cam: np.ndarray,
    centre: np.ndarray,
    sc: tuple,
    inv_f: float,
    supersample_all: bool,
    out: np.ndarray,
    front_acc: np.ndarray,
    front_trans: np.ndarray,
    region: np.ndarray,
    near: np.ndarray,
    first: np.ndarray,
) -> int:
    """Render into out (H, W, 3); front_acc (H, W, 3) and front_trans (H, W) for players.

    `ray_x`, `ray_y`, `ray_ok`: undistorted normalised coordinates on a coarse pixel grid (rows v,
    columns u) starting at `grid_origin_px` with `grid_step_px` spacing; rays are bilinear between.
    Pass 1 traces every pixel's centre; pass 2 replaces pixels on edges (see LINE_REACH_PX), or all
    pixels with `supersample_all`, by the mean of s x s supersamples. `region` (H, W), `near` (H, W) and `first` (H, W, 3) are scratch.
    Returns the number of supersampled pixels.
    """
    rows, cols = out.shape[0], out.shape[1]
    m = r_world_from_cam
    cx, cy, cz = centre[0], centre[1], centre[2]
    for i in range(rows):
        if supersample_all and samples_per_px > 1:
            break  # pass 2 traces every pixel anyway
        for j in range(cols):
            ok, dx, dy, dz = _camera_ray(
                ray_x, ray_y, ray_ok, grid_origin_px, grid_step_px, m, j, i
            )
            if not ok:
                for c in range(3):
                    first[i, j, c] = 0.0
                    front_acc[i, j, c] = 0.0
                front_trans[i, j] = 0.0
                region[i, j] = -1.0
                near[i, j] = 1e30
                continue
            cb, cg, cr, ab, ag, ar, at, reg, nr = _trace_primary(
                sc, cx, cy, cz, dx, dy, dz, inv_f, inv_f, inv_f
            )
            first[i, j, 0] = cb
            first[i, j, 1] = cg
            first[i, j, 2] = cr
            front_acc[i, j, 0] = ab
            front_acc[i, j, 1] = ag
            front_acc[i, j, 2] = ar
            front_trans[i, j] = at
            region[i, j] = reg
            near[i, j] = nr
    ss = samples_per_px
    inv = 1.0 / (ss * ss)
    count = 0
    # textures are filtered to the pixel (adaptive: every pixel looks alike) or to the supersample
    lod_inv_f = inv_f / ss if supersample_all else inv_f
    for i in range(rows):
        for j in range(cols):
            need = ss > 1 and (supersample_all or near[i, j] < LINE_REACH_PX)
            if ss > 1 and not need:
                for di in range(-1, 2):
                    for dj in range(-1, 2):
                        ii = i + di
                        jj = j + dj
                        if (di == 0 and dj == 0) or ii < 0 or jj < 0 or ii >= rows or jj >= cols:
                            continue
                        if region[ii, jj] != region[i, j]:
                            need = True
                        elif di == 0 or dj == 0:
                            for c in range(3):
                                if abs(first[ii, jj, c] - first[i, j, c]) > EDGE_CONTRAST:
                                    need = True
            if not need:
                for c in range(3):
                    out[i, j, c] = first[i, j, c]
                continue
            count += 1
            sb = 0.0
            sg = 0.0
            sr = 0.0
            fb = 0.0
            fg = 0.0
            fr = 0.0
            ft = 0.0
            for si in range(ss):
                v = i + (si + 0.5) / ss - 0.5
                for sj in range(ss):
                    u = j + (sj + 0.5) / ss - 0.5
                    ok, dx, dy, dz = _camera_ray(
                        ray_x, ray_y, ray_ok, grid_origin_px, grid_step_px, m, u, v
                    )
                    if not ok:
                        continue
                    cb, cg, cr, ab, ag, ar, at, _, _ = _trace_primary(
                        sc, cx, cy, cz, dx, dy, dz, inv_f, inv_f / ss, lod_inv_f
                    )
                    sb += cb
                    sg += cg
                    sr += cr
                    fb += ab
                    fg += ag
                    fr += ar
                    ft += at
            out[i, j, 0] = sb * inv
            out[i, j, 1] = sg * inv
            out[i, j, 2] = sr * inv
            front_acc[i, j, 0] = fb * inv
            front_acc[i, j, 1] = fg * inv
            front_acc[i, j, 2] = fr * inv
            front_trans[i, j] = ft * inv
    return count


@numba.njit(cache=True)
def visible_from(
    p: np.ndarray,
    joints: np.ndarray,
    centre: np.ndarray,
    points: np.ndarray,
    tolerance_m: float,
) -> np.ndarray:
    """For court points (M, 3): True where nothing opaque lies between the camera centre and the
    point (glass panes are see-through; metal fittings, railings and walls are not)."""
    out = np.zeros(points.shape[0], dtype=np.bool_)
    ox, oy, oz = centre[0], centre[1], centre[2]
    for k in range(points.shape[0]):
        dx = points[k, 0] - ox
        dy = points[k, 1] - oy
        dz = points[k, 2] - oz
        s_hit, _ = _nearest_opaque(p, ox, oy, oz, dx, dy, dz)
        if s_hit < 1.0 - tolerance_m / np.sqrt(dx * dx + dy * dy + dz * dz):
            continue
        ok = True
        s = _glass_crossing(p, joints, 0, ox, oy, oz, dx, dy, dz)
        if 0.0 < s < 1.0:
            x = ox + s * dx
            z = oz + s * dz
            opacity, _ = _back_glass_fitting(p, joints, x, z)
            if opacity >= 1.0:
                ok = False
        out[k] = ok
    return out
