"""The 15-parameter camera of paper section III, its OpenCV form, and pixel <-> floor mapping.

Genome order: [f_u, f_v, c_u, c_v, t_x, t_y, t_z, alpha, beta, gamma, k1, k2, p1, p2, k3], with
R = Rz(gamma) Ry(beta) Rx(alpha). The genome is a search parametrisation expressed in the paper's
frame: origin at the centre of the (WSF singles) back wall's floor line, x across (to the right),
y down, z towards the front wall; t is that origin in camera coordinates. This is the frame Tables 1
and 3 are sized for. Every other input and output uses the court frame (see `court.py`); the one
rigid transform between the two lives here (`PAPER_FROM_COURT_R`, `PAPER_ORIGIN_COURT_M`).

Distortion is Brown's model exactly as OpenCV applies it (k1, k2, p1, p2, k3; no thin prism or
rational terms), so `cv2.projectPoints` with `to_opencv()` reproduces `project_points`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numba
import numpy as np

GENOME_NAMES: tuple[str, ...] = (
    "f_u",
    "f_v",
    "c_u",
    "c_v",
    "t_x",
    "t_y",
    "t_z",
    "alpha",
    "beta",
    "gamma",
    "k1",
    "k2",
    "p1",
    "p2",
    "k3",
)
N_GENES = len(GENOME_NAMES)
GENE = {name: i for i, name in enumerate(GENOME_NAMES)}
INTRINSIC_GENES = slice(0, 4)
DISTORTION_GENES = slice(10, 15)

# x_paper = PAPER_FROM_COURT_R @ (x_court - PAPER_ORIGIN_COURT_M): x stays, y_paper = z_court (down),
# z_paper = -y_court (towards the front wall). A proper rotation (det = +1).
PAPER_FROM_COURT_R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
PAPER_ORIGIN_COURT_M = np.array([3.2, 9.75, 0.0])

# Pixel -> floor outcomes (`pixel_to_floor` status codes).
RAY_OK = 0
RAY_UNDISTORT_FAILED = 1  # pixel outside the region where the lens model is invertible
RAY_MISSES_FLOOR = 2  # ray parallel to the floor or meeting it behind the camera


def as_population(genomes: np.ndarray) -> np.ndarray:
    """(15,) or (N, 15) -> (N, 15) float64, checked."""
    pop = np.asarray(genomes, dtype=np.float64)
    if pop.ndim == 1:
        pop = pop[None, :]
    if pop.ndim != 2 or pop.shape[1] != N_GENES:
        raise ValueError(f"genomes must have shape (15,) or (N, 15), got {np.shape(genomes)}")
    return pop


def angles_from_rotation(r: np.ndarray) -> tuple[float, float, float]:
    """Angles of one R = Rz(gamma) Ry(beta) Rx(alpha): (alpha, beta, gamma), beta in [-pi/2, pi/2]."""
    alpha, beta, gamma = angles_from_rotations(np.asarray(r)[None])[0]
    return float(alpha), float(beta), float(gamma)


def angles_from_rotations(r: np.ndarray) -> np.ndarray:
    """`angles_from_rotation` of many rotations (N, 3, 3) -> (N, 3)."""
    beta = np.arcsin(np.clip(-r[:, 2, 0], -1.0, 1.0))
    alpha = np.arctan2(r[:, 2, 1], r[:, 2, 2])
    gamma = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    return np.column_stack([alpha, beta, gamma])


_PAPER_R = np.ascontiguousarray(PAPER_FROM_COURT_R)
_PAPER_O = np.ascontiguousarray(PAPER_ORIGIN_COURT_M)


@numba.njit(cache=True, inline="always")
def extrinsics_njit(g: np.ndarray, r: np.ndarray, t: np.ndarray) -> None:
    """Court-frame extrinsics of one genome, written into r (3, 3) and t (3,): X_cam = r X + t.

    R_paper = Rz(gamma) Ry(beta) Rx(alpha); r = R_paper @ PAPER_FROM_COURT_R and
    t = t_genome - r @ PAPER_ORIGIN_COURT_M. The one implementation, shared by compiled code
    (the GA) and `court_extrinsics`.
    """
    ca, sa = np.cos(g[7]), np.sin(g[7])
    cb, sb = np.cos(g[8]), np.sin(g[8])
    cg, sg = np.cos(g[9]), np.sin(g[9])
    rp00 = cg * cb
    rp01 = cg * sb * sa - sg * ca
    rp02 = cg * sb * ca + sg * sa
    rp10 = sg * cb
    rp11 = sg * sb * sa + cg * ca
    rp12 = sg * sb * ca - cg * sa
    rp20 = -sb
    rp21 = cb * sa
    rp22 = cb * ca
    for j in range(3):
        r[0, j] = rp00 * _PAPER_R[0, j] + rp01 * _PAPER_R[1, j] + rp02 * _PAPER_R[2, j]
        r[1, j] = rp10 * _PAPER_R[0, j] + rp11 * _PAPER_R[1, j] + rp12 * _PAPER_R[2, j]
        r[2, j] = rp20 * _PAPER_R[0, j] + rp21 * _PAPER_R[1, j] + rp22 * _PAPER_R[2, j]
    for i in range(3):
        t[i] = g[4 + i] - (r[i, 0] * _PAPER_O[0] + r[i, 1] * _PAPER_O[1] + r[i, 2] * _PAPER_O[2])


@numba.njit(cache=True, nogil=True)
def _extrinsics_all(pop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = pop.shape[0]
    r = np.empty((n, 3, 3))
    t = np.empty((n, 3))
    for i in range(n):
        extrinsics_njit(pop[i], r[i], t[i])
    return r, t


def court_extrinsics(genomes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World(court)-to-camera rotation (N, 3, 3) and translation (N, 3): X_cam = R X_court + t."""
    return _extrinsics_all(np.ascontiguousarray(as_population(genomes)))


@numba.njit(cache=True, inline="always")
def project_point_njit(
    r: np.ndarray, t: np.ndarray, g: np.ndarray, x: float, y: float, z: float
) -> tuple[float, float, float]:
    """One court point through one camera: (u, v, depth). The single projection kernel.

    `r`, `t` from `court_extrinsics`, `g` the genome (intrinsics and distortion are read from it).
    Mirrors OpenCV's projectPoints for k1, k2, p1, p2, k3. Depth <= 0 means behind the camera; the
    pixel is then meaningless and callers must treat it as not visible.
    """
    xc = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + t[0]
    yc = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + t[1]
    zc = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + t[2]
    inv_z = 1.0 / zc if zc != 0.0 else 1.0
    xn = xc * inv_z
    yn = yc * inv_z
    r2 = xn * xn + yn * yn
    r4 = r2 * r2
    radial = 1.0 + g[10] * r2 + g[11] * r4 + g[14] * r4 * r2
    a1 = 2.0 * xn * yn
    xd = xn * radial + g[12] * a1 + g[13] * (r2 + 2.0 * xn * xn)
    yd = yn * radial + g[12] * (r2 + 2.0 * yn * yn) + g[13] * a1
    return g[0] * xd + g[2], g[1] * yd + g[3], zc


# A court sample this close to the camera's centre (m, along the optical axis) or behind it is
# not seen (its pixel is meaningless or the line grazes the lens).
MIN_SAMPLE_DEPTH_M = 0.05


@numba.njit(cache=True, inline="always")
def seen_pixel_njit(
    r: np.ndarray,
    t: np.ndarray,
    g: np.ndarray,
    x: float,
    y: float,
    z: float,
    fold_tan2: float,
    ignore: np.ndarray,
) -> tuple[float, float, int, int, bool]:
    """Where one court point lands and whether it is seen there: (u, v, iu, iv, seen), seen when
    it is in front of the camera (MIN_SAMPLE_DEPTH_M), inside the lens fold (tan^2 of the fold's
    angle; beyond it the polynomial maps points back into the picture as ghosts), inside the
    picture and not on an `ignore`d pixel (iu, iv: the nearest pixel)."""
    u, v, depth = project_point_njit(r, t, g, x, y, z)
    if depth <= MIN_SAMPLE_DEPTH_M:
        return u, v, 0, 0, False
    xc = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + t[0]
    yc = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + t[1]
    if xc * xc + yc * yc > fold_tan2 * depth * depth:
        return u, v, 0, 0, False
    h, w = ignore.shape
    if not (0.0 <= u <= w - 1.0 and 0.0 <= v <= h - 1.0):
        return u, v, 0, 0, False
    iu = int(u + 0.5)
    iv = int(v + 0.5)
    return u, v, iu, iv, not ignore[iv, iu]


@numba.njit(cache=True, nogil=True)
def _project_all(
    r: np.ndarray, t: np.ndarray, pop: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    n, m = pop.shape[0], points.shape[0]
    pixels = np.empty((n, m, 2))
    depth = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            u, v, zc = project_point_njit(
                r[i], t[i], pop[i], points[j, 0], points[j, 1], points[j, 2]
            )
            pixels[i, j, 0] = u
            pixels[i, j, 1] = v
            depth[i, j] = zc
    return pixels, depth


def project_points(genomes: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project court points (M, 3) through one genome (15,) or a population (N, 15).

    Returns pixels (M, 2) / (N, M, 2) and camera depth (M,) / (N, M). Points with depth <= 0 are
    behind the camera.
    """
    single = np.ndim(genomes) == 1
    pop = as_population(genomes)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (M, 3), got {np.shape(points)}")
    r, t = court_extrinsics(pop)
    pixels, depth = _project_all(r, t, pop, pts)
    return (pixels[0], depth[0]) if single else (pixels, depth)


def project_visible(genome: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixels (M, 2) of court points through one camera, NaN for points behind it."""
    pixels, depth = project_points(genome, points)
    pixels = pixels.copy()
    pixels[depth <= 0] = np.nan
    return pixels


@numba.njit(cache=True, inline="always")
def _distort_with_jacobian(
    x: float, y: float, d: np.ndarray
) -> tuple[float, float, float, float, float, float]:
    """Distorted normalised (xd, yd) and the Jacobian entries of the map, for Newton steps."""
    k1, k2, p1, p2, k3 = d[0], d[1], d[2], d[3], d[4]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    dxd_dx = radial + 2.0 * x * x * dradial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x
    dxd_dy = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dy = radial + 2.0 * y * y * dradial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x
    return xd, yd, dxd_dx, dxd_dy, dxd_dy, dyd_dy


@numba.njit(cache=True, inline="always")
def _undistort_one(
    tx: float, ty: float, dist: np.ndarray, iterations: int
) -> tuple[float, float, bool]:
    """Newton's inversion of the distortion for one distorted normalised point: (x, y, ok)."""
    x, y = tx, ty
    for _ in range(iterations):
        fx, fy, a, b, c, e = _distort_with_jacobian(x, y, dist)
        rx, ry = fx - tx, fy - ty
        if abs(rx) < 1e-13 and abs(ry) < 1e-13:
            break
        det = a * e - b * c
        if abs(det) < 1e-12:
            det = 1e-12
        x -= (e * rx - b * ry) / det
        y -= (-c * rx + a * ry) / det
    fx, fy, a, b, c, e = _distort_with_jacobian(x, y, dist)
    residual = np.hypot(fx - tx, fy - ty)
    # a root on the folded part of the lens model (det <= 0) is not a physical preimage
    ok = np.isfinite(x) and np.isfinite(y) and residual < 1e-10 and a * e - b * c > 0.0
    return x, y, ok


@numba.njit(cache=True, nogil=True)
def _undistort_njit(
    xd: np.ndarray, yd: np.ndarray, dist: np.ndarray, iterations: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = xd.shape[0]
    xs = np.empty(n)
    ys = np.empty(n)
    ok = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        xs[i], ys[i], ok[i] = _undistort_one(xd[i], yd[i], dist, iterations)
    return xs, ys, ok


# Up to 85 degrees off the axis: a nearly pinhole lens (k1 = -0.0075) folds at 81 degrees, and
# a camera in a corner sees the wall beside it there; past its fold the polynomial puts that
# wall back into the middle of the picture.
_FOLD_SEARCH_RADII = np.linspace(0.0, 12.0, 721)


@numba.njit(cache=True, nogil=True)
def _fold_radii_njit(pop: np.ndarray, radii: np.ndarray, out: np.ndarray) -> None:
    for i in range(pop.shape[0]):
        k1, k2, k3 = pop[i, 10], pop[i, 11], pop[i, 14]
        out[i] = np.inf
        for r in radii:
            r2 = r * r
            if 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + 7.0 * k3 * r2)) <= 0.0:
                out[i] = r
                break


def lens_fold_radii(genomes: np.ndarray) -> np.ndarray:
    """Undistorted normalised radius (N,) where each lens's radial distortion first turns back
    (d r_d / d r <= 0), +inf where it does not within 85 degrees of the axis.

    Past that radius the model maps two directions onto one pixel: nothing beyond it is a real
    image of the court, so fits and drawings must ignore it.
    """
    pop = np.ascontiguousarray(as_population(genomes))
    out = np.empty(len(pop))
    _fold_radii_njit(pop, _FOLD_SEARCH_RADII, out)
    return out


def lens_fold_tan2(genomes: np.ndarray) -> np.ndarray:
    """Squared `lens_fold_radii` (N,), as `seen_pixel_njit` takes them: a large finite number
    where a lens does not fold (the kernels compare squares and want no infinities)."""
    fold = lens_fold_radii(genomes)
    return np.where(np.isfinite(fold), fold**2, 1e12)


def lens_fold_radius(genome: np.ndarray) -> float:
    """`lens_fold_radii` of one camera."""
    return float(lens_fold_radii(genome)[0])


def undistort_normalized(
    xd: np.ndarray, yd: np.ndarray, dist: np.ndarray, iterations: int = 30
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Invert the distortion by Newton's method: (x, y, ok) for distorted normalised (xd, yd).

    `ok` is False where Newton did not converge or converged onto the folded part of the lens
    model (Jacobian determinant <= 0), i.e. where no physical undistorted point exists.
    """
    shape = np.shape(xd)
    x, y, ok = _undistort_njit(
        np.ascontiguousarray(xd, dtype=np.float64).ravel(),
        np.ascontiguousarray(yd, dtype=np.float64).ravel(),
        np.ascontiguousarray(dist, dtype=np.float64),
        iterations,
    )
    return x.reshape(shape), y.reshape(shape), ok.reshape(shape)


UNDISTORT_ITERATIONS = 30


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pixels_to_plane_njit(
    pixels: np.ndarray,
    g: np.ndarray,
    r: np.ndarray,
    centre: np.ndarray,
    plane_z_m: float,
    iterations: int,
    out: np.ndarray,
    status: np.ndarray,
) -> None:
    """Pixels (M, 2) -> plane points (M, 2) and status (M,), in one pass without the GIL."""
    for i in range(pixels.shape[0]):
        xd = (pixels[i, 0] - g[2]) / g[0]
        yd = (pixels[i, 1] - g[3]) / g[1]
        x, y, ok = _undistort_one(xd, yd, g[10:15], iterations)
        out[i, 0] = np.nan
        out[i, 1] = np.nan
        if not ok:
            status[i] = RAY_UNDISTORT_FAILED
            continue
        # the ray's direction in the court frame: R^T (x, y, 1)
        dx = r[0, 0] * x + r[1, 0] * y + r[2, 0]
        dy = r[0, 1] * x + r[1, 1] * y + r[2, 1]
        dz = r[0, 2] * x + r[1, 2] * y + r[2, 2]
        s = (plane_z_m - centre[2]) / dz
        if not (np.isfinite(s) and s > 0.0):
            status[i] = RAY_MISSES_FLOOR
            continue
        status[i] = RAY_OK
        out[i, 0] = centre[0] + s * dx
        out[i, 1] = centre[1] + s * dy


class PreparedCamera:
    """One camera with what every mapping needs computed once: the API keeps these per
    calibration (calibrations never change), so a request pays for its points only.

    Arrays are read-only; the object is immutable by convention (share it between threads).
    """

    __slots__ = ("centre", "genome", "r", "t")

    def __init__(self, genome: np.ndarray) -> None:
        g = np.array(as_population(genome)[0], dtype=np.float64)  # a private copy
        r, t = court_extrinsics(g)
        r, t = np.ascontiguousarray(r[0]), np.ascontiguousarray(t[0])
        centre = np.ascontiguousarray(-r.T @ t)
        for a in (g, r, t, centre):
            a.setflags(write=False)
        self.genome, self.r, self.t, self.centre = g, r, t, centre

    def pixel_to_floor(
        self, pixels: np.ndarray, plane_z_m: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """`pixel_to_floor` through this camera."""
        px = np.ascontiguousarray(np.asarray(pixels, dtype=np.float64).reshape(-1, 2))
        out = np.empty((px.shape[0], 2))
        status = np.empty(px.shape[0], dtype=np.int8)
        _pixels_to_plane_njit(
            px,
            self.genome,
            self.r,
            self.centre,
            float(plane_z_m),
            UNDISTORT_ITERATIONS,
            out,
            status,
        )
        return out, status


def pixel_to_floor(
    genome: np.ndarray, pixels: np.ndarray, plane_z_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (M, 2) -> court (x, y) metres (M, 2) on the plane z = plane_z_m, and status (M,).

    Undistorts, casts the ray from the camera centre and intersects it with the plane. Status is
    RAY_OK, RAY_UNDISTORT_FAILED or RAY_MISSES_FLOOR; points are NaN where status != RAY_OK.
    Many calls through one camera: `PreparedCamera(genome).pixel_to_floor`.
    """
    return PreparedCamera(genome).pixel_to_floor(pixels, plane_z_m)


def floor_to_pixel(
    genome: np.ndarray, floor_xy_m: np.ndarray, plane_z_m: float = 0.0
) -> np.ndarray:
    """Court floor (x, y) metres (M, 2) -> pixels (M, 2); NaN where the point is behind the camera."""
    xy = np.asarray(floor_xy_m, dtype=np.float64).reshape(-1, 2)
    points = np.column_stack([xy, np.full(len(xy), plane_z_m)])
    return project_visible(genome, points)


def in_lens_field(genome: np.ndarray, points: np.ndarray) -> np.ndarray:
    """bool (M,): court points (M, 3) in front of the camera and inside its lens fold.

    Past the fold (`lens_fold_radius`) the distortion polynomial turns back and maps the point to
    a pixel on the other side of the picture: that pixel is a ghost, not where the point appears.
    """
    g = as_population(genome)[0]
    r, t = court_extrinsics(g)
    cam = np.asarray(points, dtype=np.float64).reshape(-1, 3) @ r[0].T + t[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        radius2 = (cam[:, 0] ** 2 + cam[:, 1] ** 2) / cam[:, 2] ** 2
    fold = lens_fold_radius(g)
    return (cam[:, 2] > 1e-9) & (radius2 < fold * fold)


def floor_to_image_pixel(
    genome: np.ndarray, floor_xy_m: np.ndarray, plane_z_m: float = 0.0
) -> np.ndarray:
    """Like `floor_to_pixel`, but NaN also where the point lies beyond the lens fold."""
    xy = np.asarray(floor_xy_m, dtype=np.float64).reshape(-1, 2)
    points = np.column_stack([xy, np.full(len(xy), plane_z_m)])
    pixels = project_visible(genome, points)
    pixels[~in_lens_field(genome, points)] = np.nan
    return pixels


def pixels_in_image(pixels: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """bool (M,): finite pixels (M, 2) inside the image, which spans -0.5 .. size - 0.5 (pixel
    centres at integers)."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    width, height = image_size
    with np.errstate(invalid="ignore"):
        return (
            np.isfinite(px).all(axis=1)
            & (px[:, 0] >= -0.5)
            & (px[:, 0] <= width - 0.5)
            & (px[:, 1] >= -0.5)
            & (px[:, 1] <= height - 0.5)
        )


def to_opencv(genome: np.ndarray, image_size: tuple[int, int] | None = None) -> dict[str, Any]:
    """The OpenCV JSON form of the design brief, in the court frame."""
    g = as_population(genome)[0]
    r, t = court_extrinsics(g)
    rvec, _ = cv2.Rodrigues(r[0])
    out: dict[str, Any] = {
        "K": [[float(g[0]), 0.0, float(g[2])], [0.0, float(g[1]), float(g[3])], [0.0, 0.0, 1.0]],
        "dist": [float(v) for v in (g[10], g[11], g[12], g[13], g[14])],
        "rvec": [float(v) for v in rvec.ravel()],
        "tvec": [float(v) for v in t[0]],
    }
    if image_size is not None:
        out["image_size"] = [int(image_size[0]), int(image_size[1])]
    return out


def _float_array(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers with shape {list(shape)}") from None
    if arr.shape != shape:
        raise ValueError(f"{what} must have shape {list(shape)}, got {list(arr.shape)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite numbers")
    return arr


def from_opencv(camera: Mapping[str, Any]) -> np.ndarray:
    """Genome from the OpenCV form (K, dist, rvec, tvec in the court frame)."""
    for key in ("K", "dist", "rvec", "tvec"):
        if key not in camera:
            raise ValueError(f"camera is missing {key!r} (expected K, dist, rvec, tvec)")
    k = _float_array(camera["K"], (3, 3), "K")
    if k[0, 1] != 0 or k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1:
        raise ValueError("K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)")
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise ValueError("K focal lengths fx, fy must be positive")
    raw_dist = camera["dist"] if camera["dist"] is not None else []
    try:
        dist = np.asarray(raw_dist, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError("dist must be numbers k1, k2, p1, p2[, k3]") from None
    if len(dist) not in (4, 5, 8, 12, 14):
        raise ValueError("dist must hold k1, k2, p1, p2[, k3]")
    if len(dist) > 5 and np.any(dist[5:] != 0):
        raise ValueError("only k1, k2, p1, p2, k3 distortion is supported; higher terms must be 0")
    dist5 = _float_array(np.pad(dist[:5], (0, 5 - min(len(dist), 5))), (5,), "dist")
    rvec = _float_array(camera["rvec"], (3,), "rvec")
    tvec = _float_array(camera["tvec"], (3,), "tvec")
    r_court, _ = cv2.Rodrigues(rvec)
    r_paper = r_court @ PAPER_FROM_COURT_R.T
    alpha, beta, gamma = angles_from_rotation(r_paper)
    t_paper = tvec + r_court @ PAPER_ORIGIN_COURT_M
    k1, k2, p1, p2, k3 = dist5
    return np.array(
        [k[0, 0], k[1, 1], k[0, 2], k[1, 2], *t_paper, alpha, beta, gamma, k1, k2, p1, p2, k3]
    )


def picture_centre(image_size: Sequence[int]) -> np.ndarray:
    """(u, v) of the picture's centre: pixel centres are at integer coordinates (pixel (0, 0)
    spans -0.5 .. 0.5), so a W x H picture's centre is ((W - 1) / 2, (H - 1) / 2). A principal
    point there is what "centred" means throughout."""
    return np.array([(image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0])


def check_image_size(image_size: Sequence[int]) -> tuple[int, int]:
    """(width, height) as ints, at least 2 x 2; ValueError otherwise."""
    if len(image_size) != 2:
        raise ValueError(f"image_size must be (width, height), got {image_size}")
    width, height = int(image_size[0]), int(image_size[1])
    if width < 2 or height < 2:
        raise ValueError(f"image_size must be at least 2 x 2, got {image_size}")
    return width, height


def parse_image_size(value: Any) -> tuple[int, int]:
    size = _float_array(value, (2,), "image_size")
    if np.any(size < 1) or np.any(size != np.round(size)):
        raise ValueError("image_size must be two positive whole numbers [width, height]")
    return int(size[0]), int(size[1])


def camera_from_json(obj: Any) -> tuple[np.ndarray, tuple[int, int] | None]:
    """Accept a genome (list of 15), {"genome": [...]} or the OpenCV form; -> (genome, image_size).

    Raises ValueError with a message meant for an API user.
    """
    if isinstance(obj, Mapping) and "opencv" in obj and isinstance(obj["opencv"], Mapping):
        obj = obj["opencv"]  # a whole calibration result is accepted too
    if isinstance(obj, Mapping) and "K" in obj:
        size = parse_image_size(obj["image_size"]) if obj.get("image_size") is not None else None
        return from_opencv(obj), size
    if isinstance(obj, Mapping) and "genome" in obj:
        size = parse_image_size(obj["image_size"]) if obj.get("image_size") is not None else None
        return _float_array(obj["genome"], (N_GENES,), "genome"), size
    if isinstance(obj, list | tuple):
        return _float_array(obj, (N_GENES,), "genome"), None
    raise ValueError(
        'a camera must be a genome (15 numbers), {"genome": [...]} or the OpenCV form '
        '{"K", "dist", "rvec", "tvec", "image_size"}'
    )
