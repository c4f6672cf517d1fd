"""Seeded benchmark cases: a camera placed the way each class of user films, a random court, a render.

`make_case(class_name, seed)` -> `SyntheticCase` (image, true genome, spec, style, ...) for the
classes users upload (issue 6): broadcast glass courts, club cameras, tripod phones, wide-angle
lenses, corner and side views, zoomed half-court views, anamorphic or cropped frames, and clips with
moving players (some with camera cuts). Camera ranges follow real filming (the dev set's fitted
cameras: broadcast 2-15 m behind the back wall at 2.5-8 m, f about 0.5-1.2 image widths, small roll;
club cameras 3-6 m high with barrel lenses; phones 1-1.6 m high behind the glass).

Every case shows a calibratable court: placements are resampled until at least `MIN_FLOOR_LINES`
painted floor lines, in both directions, are visible over `MIN_LINE_PX` pixels each (inside the
picture, not hidden by walls, railings, glass fittings or burned-in graphics) and the court floor
covers at least `MIN_FLOOR_FRACTION` of the picture.

`make_negative(kind, seed)` -> `NegativeCase`: images with no squash court (other sports' halls
rendered by the same ray caster, rooms, textures, text pages, checkerboards, procedural photos).

Same (class, seed) gives the same case, bit for bit.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import cv2
import numpy as np

from app.calib import scene, scene_art, scene_styles
from app.calib.camera import (
    DISTORTION_GENES,
    as_population,
    court_extrinsics,
    from_opencv,
    lens_fold_radius,
    picture_centre,
    pixel_to_floor,
    project_points,
    undistort_normalized,
)
from app.calib.court import court_model, get_spec
from app.calib.scene import Overlay, Person, SceneStyle

CASE_CLASSES: tuple[str, ...] = (
    "broadcast_glass",
    "club",
    "tripod_phone",
    "wide_angle",
    "corner_side",
    "zoomed",
    "anamorphic_cropped",
    "clip",
)
NEGATIVE_KINDS: tuple[str, ...] = (
    "badminton",
    "tennis",
    "basketball",
    "volleyball",
    "futsal",
    "multisport",
    "room",
    "corridor",
    "texture",
    "text_page",
    "checkerboard",
    "photo",
)

_T = TypeVar("_T")

MIN_FLOOR_LINES = 3
MIN_LINE_PX = 30.0
MIN_FLOOR_FRACTION = 0.08
MAX_PLACEMENT_ATTEMPTS = 60
# Share of club courts' glass back walls rendered without painted lines: many clubs mark the
# back wall's out line on the glass faintly or not at all (a reasoned guess, not a measurement).
CLUB_GLASS_BACK_WITHOUT_LINES = 0.5

# floor lines of the court for the visibility rule: name -> (model edges, direction)
FLOOR_LINES: dict[str, tuple[tuple[str, ...], str]] = {
    "short": (
        ("short_left_outer", "short_left_inner", "short_right_inner", "short_right_outer"),
        "across",
    ),
    "half_court": (("half_court",), "along"),
    "box_left_side": (("box_left_side",), "along"),
    "box_right_side": (("box_right_side",), "along"),
    "box_left_back": (("box_left_back",), "across"),
    "box_right_back": (("box_right_back",), "across"),
}


@dataclass(frozen=True, eq=False)
class SyntheticCase:
    """One benchmark case. `image` is what a user uploads as a picture (for a clip: the first frame
    of the main shot); clips also carry all `frames`, `fps`, the frame range [start, stop) of the
    longest run filmed by `genome` and the `cut_frames` filmed by another camera (a cut-away).
    Each rendered frame lasts `frame_hold` video frames: users upload clips of seconds, rendered
    here at a few frames per second."""

    image: np.ndarray
    genome: np.ndarray
    spec: str
    class_name: str
    seed: int
    style: SceneStyle
    size: tuple[int, int]
    frames: tuple[np.ndarray, ...] | None = None
    fps: float | None = None
    main_shot: tuple[int, int] | None = None
    cut_frames: tuple[int, ...] = ()
    visible_lines: tuple[str, ...] = ()
    floor_fraction: float = 0.0
    frame_hold: int = 1

    def video_frames(self) -> list[np.ndarray]:
        """The clip's frames as a video at `fps` has them (each held `frame_hold` frames)."""
        return [frame for frame in self.frames or () for _ in range(self.frame_hold)]


@dataclass(frozen=True, eq=False)
class NegativeCase:
    """An image with no squash court; `style` is the rendered scene's (None for flat pictures)."""

    image: np.ndarray
    kind: str
    seed: int
    style: SceneStyle | None = None


def _rng(name: str, seed: int) -> np.random.Generator:
    return np.random.default_rng([zlib.crc32(name.encode()), int(seed)])


# ----------------------------------------------------------------------------------------------
# Cameras


def look_at_rotation(centre: np.ndarray, target: np.ndarray, roll_rad: float) -> np.ndarray:
    """World-to-camera rotation (3, 3) looking from centre at target, image x to the right of the
    view, image y down (court z is down), rolled about the optical axis."""
    forward = np.asarray(target, float) - np.asarray(centre, float)
    forward /= np.linalg.norm(forward)
    down = np.array([0.0, 0.0, 1.0])
    right = np.cross(down, forward)
    if np.linalg.norm(right) < 1e-6:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    image_down = np.cross(forward, right)
    r = np.stack([right, image_down, forward])
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    roll = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return roll @ r


def make_genome(
    centre: np.ndarray,
    rotation: np.ndarray,
    f_u: float,
    f_v: float,
    principal: Sequence[float],
    dist: tuple[float, float, float, float, float],
) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(rotation)
    tvec = -rotation @ np.asarray(centre, float)
    return from_opencv(
        {
            "K": [[f_u, 0.0, principal[0]], [0.0, f_v, principal[1]], [0.0, 0.0, 1.0]],
            "dist": list(dist),
            "rvec": rvec.ravel().tolist(),
            "tvec": tvec.tolist(),
        }
    )


def _distorted_normalised(
    rotation: np.ndarray, centre: np.ndarray, points: np.ndarray, dist: tuple[float, ...]
) -> np.ndarray:
    cam = (np.asarray(points, float) - centre) @ rotation.T
    xn = cam[:, :2] / np.maximum(cam[:, 2:3], 1e-6)
    r2 = (xn**2).sum(axis=1, keepdims=True)
    k1, k2 = dist[0], dist[1]
    return xn * (1.0 + k1 * r2 + k2 * r2 * r2)


def _centre_on(
    centre: np.ndarray, points: np.ndarray, roll: float, dist: tuple[float, ...]
) -> np.ndarray:
    """A rotation whose optical axis passes through the middle of the points' angular extent."""
    directions = points - centre
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    forward = directions.mean(axis=0)
    rotation = look_at_rotation(centre, centre + forward, roll)
    for _ in range(4):
        xy = _distorted_normalised(rotation, centre, points, dist)
        mid = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
        axis = rotation[2] + mid[0] * rotation[0] + mid[1] * rotation[1]
        rotation = look_at_rotation(centre, centre + axis, roll)
    return rotation


def frame_camera(
    centre: np.ndarray,
    points: np.ndarray,
    size: tuple[int, int],
    fill: float,
    roll: float,
    dist: tuple[float, float, float, float, float],
    aspect: float = 1.0,
    principal: tuple[float, float] | None = None,
    shift: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """A camera at `centre` framing the points: their extent spans `fill` of the picture along its
    tighter axis (fill > 1 crops them). `aspect` = f_v / f_u; `principal` defaults to the centre;
    `shift` moves the framed points by fractions of the picture."""
    width, height = size
    cu, cv = principal if principal is not None else picture_centre(size)
    rotation = _centre_on(centre, points, roll, dist)
    xy = _distorted_normalised(rotation, centre, points, dist)
    span = xy.max(axis=0) - xy.min(axis=0)
    f_u = fill * min(width / max(span[0], 1e-6), height / max(span[1] * aspect, 1e-6))
    mid = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
    # the points' middle lands at the picture centre (+ shift), whatever the principal point
    middle_u, middle_v = picture_centre(size)
    target_u = middle_u + shift[0] * width
    target_v = middle_v + shift[1] * height
    du = (target_u - cu) / f_u - mid[0]
    dv = (target_v - cv) / (f_u * aspect) - mid[1]
    axis = rotation[2] - du * rotation[0] - dv * rotation[1]
    rotation = look_at_rotation(centre, centre + axis, roll)
    return make_genome(centre, rotation, f_u, f_u * aspect, (cu, cv), dist)


def _fold_safe_dist(
    rng: np.random.Generator, k1: float, k2: float = 0.0
) -> tuple[float, float, float, float, float]:
    return (
        float(k1),
        float(k2),
        float(rng.normal(0.0, 0.0008)),
        float(rng.normal(0.0, 0.0008)),
        0.0,
    )


def lens_is_physical(genome: np.ndarray, max_radius: float) -> bool:
    """True when the radial polynomial compresses no ray out to `max_radius` (undistorted,
    normalised) more than an orthographic lens would: slope d r_d / d r >= cos^3 of the ray's
    angle. Orthographic (image height f sin(angle)) is the strongest compression of the standard
    projections (equidistant fisheye: cos^2); a polynomial that dips below it inside the picture
    is nearly folded there, squeezes a band of angles into a few pixels and widens again beyond,
    which no real lens does (seeds 7300+: the wide-angle, club and corner cases whose floor was
    right but whose periphery lines were 3-17 px off had slopes of 0.001-0.12 there)."""
    g = as_population(genome)[0]
    k1, k2, k3 = g[DISTORTION_GENES][[0, 1, 4]]
    r2 = np.linspace(0.0, max_radius, 400) ** 2
    slope = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2**2 + 7.0 * k3 * r2**3
    return bool(np.all(slope >= (1.0 + r2) ** -1.5))


def lens_covers_image(genome: np.ndarray, size: tuple[int, int]) -> bool:
    """True when every border pixel has a physical ray (inside the lens model's fold, with a
    margin) and the lens is physical out to the farthest of them (`lens_is_physical`)."""
    g = as_population(genome)[0]
    width, height = size
    u = np.concatenate([np.linspace(0, width - 1, 40), np.full(20, 0.0), np.full(20, width - 1.0)])
    v = np.concatenate([np.zeros(20), np.full(20, height - 1.0), np.linspace(0, height - 1, 20)])
    u = np.concatenate([u, np.linspace(0, width - 1, 20)])
    v = np.concatenate([v, np.full(20, 0.0), np.full(20, height - 1.0)])[: len(u)]
    x, y, ok = undistort_normalized((u - g[2]) / g[0], (v - g[3]) / g[1], g[DISTORTION_GENES])
    radius = np.hypot(x, y)
    fold = lens_fold_radius(g)
    return bool(np.all(ok) and np.all(radius < 0.9 * fold) and lens_is_physical(g, radius.max()))


K2_STEPS = np.linspace(0.0, 0.3, 61)


def unfold_lens(genome: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    """The camera with the smallest k2 >= its own (steps of 0.005 up to 0.3) that keeps the whole
    picture inside the lens model's usable field with a physical lens (`lens_covers_image`), or
    None. A strong barrel k1 alone folds back inside the corners of a wide picture, or squeezes
    them more than any real lens; real wide lenses are fitted with a positive k2 too."""
    g = as_population(genome)[0]
    if lens_covers_image(g, size):
        return g
    k2_gene = DISTORTION_GENES.start + 1
    for k2 in K2_STEPS:
        if k2 <= g[k2_gene]:
            continue
        trial = g.copy()
        trial[k2_gene] = k2
        if lens_covers_image(trial, size):
            return trial
    return None


# ----------------------------------------------------------------------------------------------
# The visibility rule


def _overlay_mask(style: SceneStyle, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    covered = np.zeros((height, width), bool)
    for overlay in style.overlays:
        x0, y0, x1, y1 = overlay.rect
        r0, r1 = int(round(y0 * height)), int(round(y1 * height))
        c0, c1 = int(round(x0 * width)), int(round(x1 * width))
        if overlay.kind == "letterbox":
            covered[:r0] = True
            covered[r1:] = True
        elif overlay.alpha > 0.5:
            covered[max(r0, 0) : r1, max(c0, 0) : c1] = True
    return covered


def court_visibility(
    genome: np.ndarray, size: tuple[int, int], spec: str, style: SceneStyle
) -> tuple[dict[str, float], float]:
    """Visible pixel length of each floor line of `FLOOR_LINES` and the fraction of the picture the
    court floor covers. A line point counts when it is in the picture (2 px margin), inside the
    lens's usable field, in a clear line of sight and not under an opaque graphic."""
    width, height = size
    g = as_population(genome)[0]
    model = court_model(spec)
    covered = _overlay_mask(style, size)
    fold = lens_fold_radius(g)
    out: dict[str, float] = {}
    for name, (edges, _) in FLOOR_LINES.items():
        pts = []
        for edge in edges:
            ia, ib = model.edges[model.edge_names.index(edge)]
            a, b = model.nodes[ia], model.nodes[ib]
            n = max(2, int(np.linalg.norm(b - a) / 0.02) + 1)
            pts.append(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
        points = np.concatenate(pts)
        pixels, depth = project_points(g, points)
        r, t = court_extrinsics(g)
        cam = points @ r[0].T + t[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            radius = np.hypot(cam[:, 0], cam[:, 1]) / cam[:, 2]
        inside = (
            (depth > 0.05)
            & (radius < 0.9 * fold)
            & (pixels[:, 0] >= 2)
            & (pixels[:, 0] <= width - 3)
            & (pixels[:, 1] >= 2)
            & (pixels[:, 1] <= height - 3)
        )
        ok = inside.copy()
        if ok.any():
            idx = np.flatnonzero(ok)
            px = np.round(pixels[idx]).astype(int)
            ok[idx] = ~covered[px[:, 1], px[:, 0]]
        if ok.any():
            idx = np.flatnonzero(ok)
            ok[idx] = scene.visible_points(g, spec, style, points[idx])
        seg_ok = ok[:-1] & ok[1:]
        lengths = np.linalg.norm(np.diff(pixels, axis=0), axis=1)
        out[name] = float(np.where(seg_ok, lengths, 0.0).sum())
    # floor coverage on a coarse grid of pixels
    step = max(4, min(width, height) // 60)
    uu, vv = np.meshgrid(np.arange(step / 2, width, step), np.arange(step / 2, height, step))
    xy, status = pixel_to_floor(g, np.column_stack([uu.ravel(), vv.ravel()]))
    court = get_spec(spec)
    on_floor = (
        (status == 0)
        & (xy[:, 0] >= 0)
        & (xy[:, 0] <= court.width_m)
        & (xy[:, 1] >= 0)
        & (xy[:, 1] <= court.length_m)
    )
    return out, float(on_floor.mean())


def visible_floor_lines(lengths: dict[str, float], min_px: float = MIN_LINE_PX) -> tuple[str, ...]:
    return tuple(name for name, length in lengths.items() if length >= min_px)


def is_calibratable(lines: tuple[str, ...], floor_fraction: float) -> bool:
    directions = {FLOOR_LINES[name][1] for name in lines}
    return (
        len(lines) >= MIN_FLOOR_LINES
        and directions == {"across", "along"}
        and floor_fraction >= MIN_FLOOR_FRACTION
    )


# ----------------------------------------------------------------------------------------------
# Per-class placements


def _choose(rng: np.random.Generator, options: Sequence[tuple[float, _T]]) -> _T:
    """One of the options, drawn with the given weights."""
    weights = np.array([w for w, _ in options], float)
    return options[int(rng.choice(len(options), p=weights / weights.sum()))][1]


def _size(
    rng: np.random.Generator, options: Sequence[tuple[float, tuple[int, int]]]
) -> tuple[int, int]:
    return _choose(rng, options)


BROADCAST_SIZES = [
    (0.2, (1920, 1080)),
    (0.35, (1280, 720)),
    (0.1, (960, 540)),
    (0.1, (854, 480)),
    (0.25, (640, 360)),
]
CLUB_SIZES = [
    (0.3, (1920, 1080)),
    (0.4, (1280, 720)),
    (0.1, (960, 540)),
    (0.1, (640, 360)),
    (0.1, (640, 480)),
]
PHONE_SIZES = [(0.45, (1920, 1080)), (0.3, (1280, 720)), (0.15, (1440, 1080)), (0.1, (1024, 768))]
PHOTO_SIZES = [
    (0.3, (1200, 800)),
    (0.2, (1024, 768)),
    (0.2, (1440, 1080)),
    (0.15, (800, 600)),
    (0.15, (1500, 1000)),
]


def _framing_points(rng: np.random.Generator, spec: str, region: str) -> np.ndarray:
    """Court points a camera operator frames: the whole court or part of it."""
    court = get_spec(spec)
    w, length = court.width_m, court.length_m
    top = -(court.front_out_lower_m + 0.3)
    if region == "full":
        back = length
        return np.array(
            [[0, 0, 0], [w, 0, 0], [0, 0, top], [w, 0, top], [0, back, 0], [w, back, 0]], float
        )
    if region == "cut_back":
        back = length - float(rng.uniform(0.5, 2.5))
        return np.array(
            [[0, 0, 0], [w, 0, 0], [0, 0, top], [w, 0, top], [0, back, 0], [w, back, 0]], float
        )
    if region == "cut_top":
        top = -(court.service_lower_m + float(rng.uniform(0.4, 2.0)))
        return np.array(
            [[0, 0, 0], [w, 0, 0], [0, 0, top], [w, 0, top], [0, length, 0], [w, length, 0]], float
        )
    if region == "front_half":
        y1 = float(rng.uniform(6.8, 7.8))
        return np.array(
            [[0, 0, 0], [w, 0, 0], [0, 0, -0.6], [w, 0, -0.6], [0, y1, 0], [w, y1, 0]], float
        )
    if region == "back_half":
        y0 = float(rng.uniform(4.0, 5.0))
        return np.array([[0, y0, 0], [w, y0, 0], [0, length, 0], [w, length, 0]], float)
    if region == "side_half":
        x1 = w * float(rng.uniform(0.55, 0.75))
        if rng.random() < 0.5:
            return np.array([[0, 2.0, 0], [x1, 2.0, 0], [0, length, 0], [x1, length, 0]], float)
        return np.array([[w - x1, 2.0, 0], [w, 2.0, 0], [w - x1, length, 0], [w, length, 0]], float)
    raise ValueError(region)


@dataclass(frozen=True)
class _Placement:
    genome: np.ndarray
    size: tuple[int, int]
    preset: str
    inside: bool  # camera inside the court box


def _behind_back_wall(
    rng: np.random.Generator,
    spec: str,
    size: tuple[int, int],
    distance: tuple[float, float],
    height: tuple[float, float],
    off_centre: float,
    k1: tuple[float, float],
    region: str,
    fill: tuple[float, float],
    roll_deg: float,
    aspect: float = 1.0,
    principal: tuple[float, float] | None = None,
) -> np.ndarray:
    court = get_spec(spec)
    d = float(np.exp(rng.uniform(np.log(distance[0]), np.log(distance[1]))))
    h = float(rng.uniform(*height))
    x = court.width_m / 2.0 + float(rng.normal(0.0, 0.25))
    if rng.random() < off_centre:
        x = court.width_m / 2.0 + float(rng.uniform(-1.0, 1.0)) * court.width_m * 0.3
    centre = np.array([x, court.length_m + d, -h])
    dist = _fold_safe_dist(rng, float(rng.uniform(*k1)))
    points = _framing_points(rng, spec, region)
    return frame_camera(
        centre,
        points,
        size,
        float(rng.uniform(*fill)),
        float(np.radians(rng.normal(0.0, roll_deg))),
        dist,
        aspect,
        principal,
        (float(rng.normal(0.0, 0.02)), float(rng.normal(0.0, 0.03))),
    )


def _place(rng: np.random.Generator, class_name: str, spec: str) -> _Placement:
    court = get_spec(spec)
    w, length = court.width_m, court.length_m
    if class_name == "broadcast_glass":
        size = _size(rng, BROADCAST_SIZES)
        region = str(_choose(rng, [(5, "full"), (3.5, "cut_back"), (1.5, "cut_top")]))
        g = _behind_back_wall(
            rng, spec, size, (2.0, 15.0), (2.5, 8.0), 0.2, (-0.2, 0.05), region, (0.82, 1.05), 0.4
        )
        return _Placement(g, size, "glass", False)
    if class_name == "club":
        size = _size(rng, CLUB_SIZES)
        if rng.random() < 0.2:
            # mounted high on the back wall, inside the court
            centre = np.array(
                [
                    w / 2 + float(rng.normal(0, 0.4)),
                    length - float(rng.uniform(0.1, 0.3)),
                    -float(rng.uniform(2.4, 3.6)),
                ]
            )
            dist = _fold_safe_dist(rng, float(rng.uniform(-0.3, -0.02)))
            g = frame_camera(
                centre,
                _framing_points(rng, spec, "cut_back"),
                size,
                float(rng.uniform(0.85, 1.02)),
                float(np.radians(rng.normal(0, 0.8))),
                dist,
            )
            return _Placement(g, size, "club", True)
        region = str(_choose(rng, [(5, "full"), (4, "cut_back"), (1, "cut_top")]))
        g = _behind_back_wall(
            rng, spec, size, (0.4, 7.0), (2.2, 5.5), 0.25, (-0.35, 0.0), region, (0.85, 1.05), 0.7
        )
        return _Placement(g, size, "club", False)
    if class_name == "tripod_phone":
        size = _size(rng, PHONE_SIZES)
        inside = rng.random() < 0.2
        if inside:
            y = length - float(rng.uniform(0.3, 1.5))
        else:
            y = length + float(rng.uniform(0.2, 3.0))
        if rng.random() < 0.5:
            x = w / 2 + float(rng.normal(0, 0.3))
        else:
            x = w / 2 + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.8, 2.9))
        centre = np.array([x, y, -float(rng.uniform(1.0, 1.6))])
        target = np.array(
            [
                w / 2 + float(rng.normal(0, 0.6)),
                float(rng.uniform(0.0, 3.0)),
                -float(rng.uniform(0.0, 1.6)),
            ]
        )
        ultrawide = rng.random() < 0.3
        f_rel = float(rng.uniform(0.33, 0.45)) if ultrawide else float(rng.uniform(0.55, 0.9))
        k1 = float(rng.uniform(-0.03, 0.02)) if ultrawide else float(rng.uniform(-0.06, 0.04))
        rotation = look_at_rotation(centre, target, float(np.radians(rng.normal(0, 1.5))))
        f = f_rel * size[0]
        g = make_genome(
            centre, rotation, f, f, tuple(picture_centre(size)), _fold_safe_dist(rng, k1)
        )
        return _Placement(g, size, "club" if rng.random() < 0.6 else "glass", inside)
    if class_name == "wide_angle":
        size = _size(
            rng, [(0.4, (1280, 720)), (0.3, (1920, 1080)), (0.15, (1200, 800)), (0.15, (640, 480))]
        )
        k1 = float(rng.uniform(-0.35, -0.15))
        k2 = float(rng.uniform(0.0, 0.08)) if rng.random() < 0.35 else 0.0
        dist = _fold_safe_dist(rng, k1, k2)
        if rng.random() < 0.6:
            side = float(rng.choice([-1.0, 1.0]))
            x = w / 2 + side * (w / 2 - float(rng.uniform(0.2, 0.8)))
            centre = np.array(
                [x, length - float(rng.uniform(0.15, 0.8)), -float(rng.uniform(2.0, 3.5))]
            )
            points = np.array(
                [
                    [0, 0, 0],
                    [w, 0, 0],
                    [0, 0, -2.0],
                    [w, 0, -2.0],
                    [w / 2 - side * w / 2, length - 1.0, 0],
                    [w / 2 - side * w / 2, 4.0, 0],
                ],
                float,
            )
            g = frame_camera(
                centre,
                points,
                size,
                float(rng.uniform(0.8, 1.0)),
                float(np.radians(rng.normal(0, 2.0))),
                dist,
            )
            return _Placement(g, size, str(_choose(rng, [(0.7, "club"), (0.3, "glass")])), True)
        region = str(_choose(rng, [(1, "full"), (1, "cut_back")]))
        g = _behind_back_wall(
            rng, spec, size, (0.4, 4.0), (2.2, 5.0), 0.4, (k1, k1), region, (0.85, 1.05), 1.5
        )
        return _Placement(g, size, str(_choose(rng, [(0.7, "club"), (0.3, "glass")])), False)
    if class_name == "corner_side":
        size = _size(
            rng, [(0.4, (1280, 720)), (0.3, (1920, 1080)), (0.2, (960, 540)), (0.1, (1024, 768))]
        )
        kind = str(
            _choose(rng, [(0.45, "side_gallery"), (0.35, "low_corner"), (0.2, "front_corner")])
        )
        preset = str(_choose(rng, [(0.55, "glass"), (0.45, "club")]))
        side = float(rng.choice([-1.0, 1.0]))
        dist = _fold_safe_dist(rng, float(rng.uniform(-0.15, 0.03)))
        inside = False
        if kind == "side_gallery":
            # beside a glass side wall, or at the top of a plaster one looking over it
            d = float(rng.uniform(0.8, 5.0)) if preset == "glass" else float(rng.uniform(-0.2, 1.0))
            x = -d if side < 0 else w + d
            y = float(rng.uniform(3.0, 11.0))
            if preset == "glass":
                h = float(rng.uniform(2.5, 6.5))
            else:
                # a gallery above a plaster side wall: well above the wall's top at that point
                out_line = (
                    court.front_out_lower_m
                    + (court.back_out_lower_m - court.front_out_lower_m) * min(y, length) / length
                )
                h = out_line + float(rng.uniform(2.0, 4.0))
            centre = np.array([x, y, -h])
            points = np.array([[0, 0, 0], [w, 0, 0], [0, length, 0], [w, length, 0]], float)
            if rng.random() < 0.5:
                # include the front wall up to the service line
                points = np.vstack([points, [[w / 2, 0.0, -2.0]]])
        elif kind == "low_corner":
            x = (0.0 if side < 0 else w) + side * float(rng.uniform(-0.6, 1.5))
            centre = np.array(
                [x, length + float(rng.uniform(0.3, 3.0)), -float(rng.uniform(0.8, 2.2))]
            )
            points = np.array(
                [
                    [0, 0, 0],
                    [w, 0, 0],
                    [0, 0, -2.5],
                    [w, 0, -2.5],
                    [0, length - 0.5, 0],
                    [w, length - 0.5, 0],
                ],
                float,
            )
        else:
            inside = True
            x = w / 2 + side * (w / 2 - float(rng.uniform(0.2, 1.0)))
            centre = np.array([x, float(rng.uniform(0.2, 1.0)), -float(rng.uniform(1.5, 3.0))])
            points = np.array(
                [
                    [0, 2.0, 0],
                    [w, 2.0, 0],
                    [0, length, 0],
                    [w, length, 0],
                    [0, length, -2.0],
                    [w, length, -2.0],
                ],
                float,
            )
        g = frame_camera(
            centre,
            points,
            size,
            float(rng.uniform(0.8, 1.1)),
            float(np.radians(rng.normal(0, 1.0))),
            dist,
        )
        return _Placement(g, size, preset, inside)
    if class_name == "zoomed":
        size = _size(rng, BROADCAST_SIZES)
        region = str(_choose(rng, [(0.45, "front_half"), (0.35, "back_half"), (0.2, "side_half")]))
        preset = str(_choose(rng, [(0.6, "glass"), (0.4, "club")]))
        if preset == "glass":
            g = _behind_back_wall(
                rng,
                spec,
                size,
                (5.0, 25.0),
                (4.0, 9.0),
                0.3,
                (-0.05, 0.1),
                region,
                (0.9, 1.15),
                0.5,
            )
        else:
            g = _behind_back_wall(
                rng, spec, size, (1.5, 7.0), (3.0, 5.5), 0.3, (-0.1, 0.05), region, (0.9, 1.15), 0.5
            )
        return _Placement(g, size, preset, False)
    if class_name == "anamorphic_cropped":
        preset = str(_choose(rng, [(0.6, "glass"), (0.4, "club")]))
        if rng.random() < 0.5:
            size = _size(rng, [(0.6, (1920, 1080)), (0.4, (1280, 720))])
            aspect = float(
                _choose(
                    rng,
                    [
                        (0.5, 0.75),
                        (0.25, float(rng.uniform(0.7, 0.92))),
                        (0.25, float(rng.uniform(1.08, 1.25))),
                    ],
                )
            )
            region = str(_choose(rng, [(1, "full"), (1, "cut_back")]))
            g = _behind_back_wall(
                rng,
                spec,
                size,
                (2.0, 12.0),
                (2.5, 7.0),
                0.2,
                (-0.2, 0.05),
                region,
                (0.85, 1.05),
                0.4,
                aspect=aspect,
            )
            return _Placement(g, size, preset, False)
        size = _size(rng, PHOTO_SIZES)
        cu = (
            picture_centre(size)[0]
            + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.15, 0.45)) * size[0]
        )
        cv = picture_centre(size)[1] + float(rng.uniform(-0.4, 0.4)) * size[1]
        region = str(_choose(rng, [(1, "full"), (1, "cut_back"), (0.5, "cut_top")]))
        g = _behind_back_wall(
            rng,
            spec,
            size,
            (1.0, 10.0),
            (2.0, 6.0),
            0.4,
            (-0.12, 0.03),
            region,
            (0.8, 1.0),
            1.0,
            principal=(cu, cv),
        )
        return _Placement(g, size, preset, False)
    raise ValueError(
        f"unknown case class {class_name!r}; expected one of {', '.join(CASE_CLASSES)}"
    )


# ----------------------------------------------------------------------------------------------
# Camera-dependent scene parts: gallery and railing, players, graphics, video chain


def _gallery(
    rng: np.random.Generator,
    style: SceneStyle,
    genome: np.ndarray,
    size: tuple[int, int],
    spec: str,
) -> SceneStyle:
    """A balcony under a camera behind the back wall; its railing, when there is one, stays in the
    bottom quarter of the picture (the camera stands just behind it, the top rail below the lens)."""
    court = get_spec(spec)
    centre = scene.camera_centre(genome)
    behind = centre[1] - court.length_m
    h = -centre[2]
    if not (behind > 0.8 and h > 2.4 and rng.random() < 0.6):
        return style
    gallery_h = h - float(rng.uniform(1.3, 1.8))
    edge = centre[1] - float(rng.uniform(0.3, min(behind - 0.3, 1.5)))
    style = replace(style, gallery=True, gallery_y=edge, gallery_height_m=gallery_h)
    if rng.random() < 0.3:
        return style
    rail_h = float(rng.uniform(0.85, 1.1))
    top = np.array([[centre[0], edge, -(gallery_h + rail_h)]])
    v = project_points(genome, top)[0][0, 1]
    if v < 0.78 * size[1]:
        return style
    colour = ((40.0, 40.0, 40.0), (150.0, 150.0, 150.0), (60.0, 90.0, 140.0))[int(rng.integers(3))]
    return replace(
        style,
        railing=True,
        railing_y=edge,
        railing_height_m=rail_h,
        railing_mid_bars=int(rng.integers(0, 4)),
        railing_post_spacing_m=float(rng.uniform(0.12, 2.0)),
        railing_bar_m=float(rng.uniform(0.03, 0.06)),
        railing_colour=scene_styles._jitter(rng, colour, 8.0),
    )


def _people(
    rng: np.random.Generator, spec: str, n: int, centre: np.ndarray | None = None
) -> tuple[Person, ...]:
    """Players around the T, at least 3 m from the camera (4.5 m from a camera below 2 m)."""
    court = get_spec(spec)
    model = court_model(court)
    t = model.node("T")
    shirts = [
        (120, 40, 20),
        (30, 30, 160),
        (40, 110, 30),
        (25, 25, 25),
        (20, 140, 200),
        (110, 30, 110),
        (230, 230, 230),
        (200, 160, 40),
        (60, 60, 200),
    ]
    skins = [(140, 170, 215), (80, 105, 150), (105, 135, 185), (60, 80, 120), (160, 190, 230)]
    order = rng.permutation(len(shirts))
    people = []
    for k in range(n):
        for _ in range(20):
            x = float(np.clip(t[0] + rng.normal(0.0, 1.3), 0.4, court.width_m - 0.4))
            y = float(np.clip(t[1] + rng.normal(0.3, 1.6), 0.6, court.length_m - 0.4))
            if centre is None:
                break
            near = 4.5 if -centre[2] < 2.0 else 3.0
            if np.hypot(x - centre[0], y - centre[1]) > near:
                break
        people.append(
            Person(
                x,
                y,
                shirts[int(order[k % len(shirts)])],
                scene_styles._jitter(
                    rng,
                    ((30.0, 30.0, 30.0), (230.0, 230.0, 230.0), (90.0, 40.0, 20.0))[
                        int(rng.integers(3))
                    ],
                    8.0,
                ),
                skins[int(rng.integers(len(skins)))],
                float(rng.uniform(1.65, 1.95)),
                float(rng.uniform(0.08, 0.45)),
                float(rng.normal(0.0, 0.06)),
                float(rng.uniform(0.0, 1.0)),
            )
        )
    return tuple(people)


def _broadcast_overlays(rng: np.random.Generator) -> tuple[Overlay, ...]:
    out = []
    if rng.random() < 0.85:
        w = float(rng.uniform(0.3, 0.55))
        h = float(rng.uniform(0.035, 0.06))
        x0 = float(rng.uniform(0.05, 0.95 - w)) if rng.random() < 0.4 else 0.5 - w / 2
        y0 = (
            float(rng.uniform(0.82, 0.93 - h))
            if rng.random() < 0.75
            else float(rng.uniform(0.03, 0.1))
        )
        names = f"{scene_art.player_name(rng)}|{scene_art.player_name(rng)}"
        if rng.random() < 0.3:
            names = f"{scene_art.country_code(rng)}|{scene_art.country_code(rng)}"
        colours = (
            (int(rng.integers(225, 256)),) * 3,
            (30, 30, 30),
            scene_styles._jitter(
                rng,
                ((40.0, 40.0, 40.0), (40.0, 40.0, 190.0), (150.0, 70.0, 20.0))[
                    int(rng.integers(3))
                ],
            ),
        )
        out.append(
            Overlay(
                "score_bar",
                (x0, y0, x0 + w, y0 + h),
                names,
                colours,
                float(rng.uniform(0.85, 1.0)),
                int(rng.integers(1 << 30)),
            )
        )
    if rng.random() < 0.5:
        s = float(rng.uniform(0.04, 0.08))
        x0 = float(rng.choice([0.02, 0.98 - s]))
        out.append(
            Overlay(
                "logo",
                (x0, 0.03, x0 + s, 0.03 + s * 16 / 9),
                str(rng.choice(["TV", "HD", "SQ", "PSA", "ESPN", "LIVE"])),
                ((200, 200, 200), (40, 40, 40), (40, 40, 40)),
                float(rng.uniform(0.4, 0.9)),
                int(rng.integers(1 << 30)),
            )
        )
    if rng.random() < 0.2:
        out.append(
            Overlay(
                "clock",
                (0.44, 0.94, 0.56, 0.98),
                f"00:{int(rng.integers(0, 60)):02d}:{int(rng.integers(0, 60)):02d}",
                ((30, 30, 30), (240, 240, 240)),
                1.0,
                0,
            )
        )
    if rng.random() < 0.08:
        bar = float(rng.uniform(0.04, 0.1))
        out.append(Overlay("letterbox", (0.0, bar, 1.0, 1.0 - bar)))
    return tuple(out)


def _club_overlays(rng: np.random.Generator) -> tuple[Overlay, ...]:
    out = []
    if rng.random() < 0.35:
        y0 = float(rng.uniform(0.45, 0.7))
        x0 = float(rng.uniform(0.05, 0.3))
        out.append(
            Overlay(
                "text",
                (x0, y0, x0 + float(rng.uniform(0.25, 0.45)), y0 + 0.03),
                f"INSTAGRAM.COM/{scene_art.brand_name(rng).replace(' ', '')}/",
                ((0, 0, 0), (20, 20, 20)),
                1.0,
                int(rng.integers(1 << 30)),
            )
        )
    if rng.random() < 0.35:
        y0 = float(rng.uniform(0.8, 0.9))
        out.append(
            Overlay(
                "score_box",
                (0.7, y0, 0.98, y0 + 0.08),
                f"{scene_art.player_name(rng)}|{scene_art.player_name(rng)}",
                ((40, 40, 40), (230, 230, 230), (40, 120, 40)),
                0.9,
                int(rng.integers(1 << 30)),
            )
        )
    if rng.random() < 0.3:
        out.append(
            Overlay(
                "logo",
                (0.03, 0.03, 0.12, 0.19),
                scene_art.brand_name(rng)[:4],
                ((40, 40, 200), (255, 255, 255)),
                float(rng.uniform(0.5, 1.0)),
                int(rng.integers(1 << 30)),
            )
        )
    if rng.random() < 0.2:
        out.append(
            Overlay(
                "box",
                (0.6, 0.0, 0.96, 0.09),
                "",
                (scene_styles._jitter(rng, (250.0, 240.0, 0.0)),),
                1.0,
                0,
            )
        )
    if rng.random() < 0.25:
        out.append(
            Overlay(
                "clock",
                (0.02, 0.93, 0.2, 0.98),
                f"2024-0{int(rng.integers(1, 10))}-1{int(rng.integers(0, 10))} 1{int(rng.integers(0, 10))}:{int(rng.integers(10, 60))}",
                ((0, 0, 0), (230, 230, 230)),
                0.6,
                0,
            )
        )
    return tuple(out)


def _video_chain(rng: np.random.Generator, kind: str) -> dict[str, Any]:
    """Exposure, white balance, optics and compression for broadcast, club or phone footage."""
    wb = tuple(float(v) for v in np.clip(rng.normal(1.0, 0.04, 3), 0.88, 1.12))
    grading = {
        "saturation": float(rng.uniform(0.7, 1.2)),
        "contrast": float(rng.uniform(0.85, 1.15)),
        "sharpen": float(rng.uniform(0.0, 0.8)) if rng.random() < 0.6 else 0.0,
        "bloom": float(rng.uniform(0.0, 0.5)) if rng.random() < 0.5 else 0.0,
    }
    if kind == "broadcast":
        return {
            "exposure": float(rng.uniform(0.8, 1.1)),
            "white_balance": wb,
            "gamma": float(rng.uniform(0.85, 1.1)),
            "vignetting": float(rng.uniform(0.0, 0.15)),
            "blur_px": float(rng.uniform(0.3, 1.1)),
            "noise_sigma": float(rng.uniform(0.5, 2.5)),
            "jpeg_quality": int(rng.integers(35, 92)),
            **grading,
        }
    if kind == "phone":
        return {
            "exposure": float(rng.uniform(0.8, 1.25)),
            "white_balance": wb,
            "gamma": float(rng.uniform(0.85, 1.1)),
            "vignetting": float(rng.uniform(0.0, 0.3)),
            "blur_px": float(rng.uniform(0.0, 0.9)),
            "noise_sigma": float(rng.uniform(1.0, 4.0)),
            "jpeg_quality": int(rng.integers(60, 96)),
            **grading,
        }
    return {
        "exposure": float(rng.uniform(0.75, 1.2)),
        "white_balance": wb,
        "gamma": float(rng.uniform(0.8, 1.1)),
        "vignetting": float(rng.uniform(0.0, 0.35)),
        "blur_px": float(rng.uniform(0.2, 1.3)),
        "noise_sigma": float(rng.uniform(1.0, 4.5)),
        "jpeg_quality": int(rng.integers(30, 92)),
        **grading,
    }


def _dress(
    rng: np.random.Generator, class_name: str, placement: _Placement, spec: str
) -> SceneStyle:
    """The style around a placement: court family, gallery, players, graphics, video chain."""
    style = scene_styles.sample_style(rng, placement.preset, spec)
    court = get_spec(spec)
    centre = scene.camera_centre(placement.genome)
    inside = 0 <= centre[0] <= court.width_m and 0 <= centre[1] <= court.length_m
    if inside and style.back_glass and rng.random() < 0.4 and placement.preset == "club":
        style = replace(style, back_glass=False)
    outside_side = centre[0] < 0 or centre[0] > court.width_m
    if outside_side and not style.side_glass:
        # a gallery above the side wall: walls must stay below the camera
        style = replace(
            style, side_above_out_m=(float(rng.uniform(0.1, 0.6)), float(rng.uniform(0.1, 0.6)))
        )
    if centre[1] > court.length_m and not style.back_glass:
        style = replace(style, back_glass=True)
    if style.back_glass and placement.preset == "club":
        # Half the clubs' glass back walls show no out line. Drawn from its own stream, so that
        # every other draw of a seeded case stays as it was.
        own = np.random.default_rng(
            [zlib.crc32(b"back wall lines"), zlib.crc32(placement.genome.tobytes())]
        )
        if own.random() < CLUB_GLASS_BACK_WITHOUT_LINES:
            style = replace(style, back_wall_lines=False)
    if placement.preset == "glass" and centre[1] < court.length_m and rng.random() < 0.7:
        # spectators behind the back glass too, seen from the front or the sides
        style = replace(style, stand_back=True)
    style = _gallery(rng, style, placement.genome, placement.size, spec)
    broadcast = placement.preset == "glass" and class_name not in ("tripod_phone",)
    n_players = int(_choose(rng, [(0.3, 0), (0.15, 1), (0.55, 2)])) if class_name != "clip" else 0
    chain = _video_chain(
        rng, "phone" if class_name == "tripod_phone" else ("broadcast" if broadcast else "club")
    )
    if class_name == "tripod_phone":
        overlays: tuple[Overlay, ...] = ()
    elif broadcast:
        overlays = _broadcast_overlays(rng)
    else:
        overlays = _club_overlays(rng)
    g = as_population(placement.genome)[0]
    softness = min(1.0, g[1] / g[0]) if abs(g[1] / g[0] - 1.0) > 0.02 else 1.0
    return replace(
        style,
        players=_people(rng, spec, n_players, centre),
        overlays=overlays,
        horizontal_softness=softness,
        **chain,
    )


def _spec(rng: np.random.Generator) -> str:
    return str(_choose(rng, [(0.85, "wsf"), (0.1, "psa"), (0.05, "doubles")]))


def _sample_valid(
    rng: np.random.Generator, class_name: str, spec: str
) -> tuple[_Placement, SceneStyle, tuple[str, ...], float]:
    last = None
    for _ in range(MAX_PLACEMENT_ATTEMPTS):
        placement = _place(rng, class_name, spec)
        unfolded = unfold_lens(placement.genome, placement.size)
        if unfolded is None:
            continue
        placement = _Placement(unfolded, placement.size, placement.preset, placement.inside)
        style = _dress(rng, class_name, placement, spec)
        lengths, fraction = court_visibility(placement.genome, placement.size, spec, style)
        lines = visible_floor_lines(lengths)
        last = (placement, style, lines, fraction)
        if is_calibratable(lines, fraction):
            return last
    raise RuntimeError(
        f"no calibratable placement for {class_name} after {MAX_PLACEMENT_ATTEMPTS} attempts ({last and last[2:]})"
    )


@dataclass(frozen=True, eq=False)
class CasePlan:
    """A case before rendering: the true camera, picture size, court spec, style and what the
    visibility rule found (floor lines in view, fraction of the picture that is court floor)."""

    genome: np.ndarray
    size: tuple[int, int]
    spec: str
    style: SceneStyle
    visible_lines: tuple[str, ...]
    floor_fraction: float
    filmed_like: str  # the class whose camera placement was drawn (a clip's base class)


def _check_class(class_name: str) -> None:
    if class_name not in CASE_CLASSES:
        raise ValueError(
            f"unknown case class {class_name!r}; expected one of {', '.join(CASE_CLASSES)}"
        )


def _plan(rng: np.random.Generator, class_name: str) -> CasePlan:
    spec = _spec(rng)
    placement, style, lines, fraction = _sample_valid(rng, class_name, spec)
    return CasePlan(placement.genome, placement.size, spec, style, lines, fraction, class_name)


def plan_case(class_name: str, seed: int) -> CasePlan:
    """The camera, court and style `make_case` would render, without rendering (cheap). Clips are
    planned from the class their main shot is filmed like; this returns that main shot's plan."""
    _check_class(class_name)
    rng = _rng(class_name, seed)
    if class_name == "clip":
        return _clip_plan(rng, _spec(rng))
    return _plan(rng, class_name)


def make_case(class_name: str, seed: int) -> SyntheticCase:
    """The seeded case of a class (see the module doc). Deterministic."""
    _check_class(class_name)
    rng = _rng(class_name, seed)
    if class_name == "clip":
        return _make_clip(rng, seed, _spec(rng))
    plan = _plan(rng, class_name)
    render_rng = np.random.default_rng(rng.integers(1 << 62))
    image = scene.render_scene(plan.genome, plan.size, plan.spec, plan.style, render_rng)
    return SyntheticCase(
        image,
        plan.genome,
        plan.spec,
        class_name,
        int(seed),
        plan.style,
        plan.size,
        visible_lines=plan.visible_lines,
        floor_fraction=plan.floor_fraction,
    )


# ----------------------------------------------------------------------------------------------
# Clips


CLIP_BASES = [(0.4, "broadcast_glass"), (0.35, "club"), (0.15, "tripod_phone"), (0.1, "wide_angle")]


def _close_up(
    rng: np.random.Generator, genome: np.ndarray, size: tuple[int, int], around: np.ndarray
) -> np.ndarray:
    """A cut-away shot: the same camera position zoomed onto a player (or another spot)."""
    centre = scene.camera_centre(genome)
    target = np.array([around[0], around[1], -float(rng.uniform(0.6, 1.2))])
    rotation = look_at_rotation(centre, target, float(np.radians(rng.normal(0, 1.0))))
    g = as_population(genome)[0]
    f = g[0] * float(rng.uniform(2.0, 4.0))
    return make_genome(
        centre, rotation, f, f * g[1] / g[0], (g[2], g[3]), (0.0, 0.0, 0.0, 0.0, 0.0)
    )


def _clip_plan(rng: np.random.Generator, spec: str) -> CasePlan:
    """The main shot of a clip: planned like its base class, at most 1280 px wide (cheap)."""
    base = _choose(rng, CLIP_BASES)
    placement, style, lines, fraction = _sample_valid(rng, base, spec)
    size = placement.size
    genome = placement.genome
    if size[0] * size[1] > 1280 * 720:
        scale = 1280.0 / size[0]
        size = (1280, int(round(size[1] * scale)))
        genome = as_population(genome)[0].copy()
        genome[0:4] = [
            genome[0] * scale,
            genome[1] * scale,
            (genome[2] + 0.5) * scale - 0.5,
            (genome[3] + 0.5) * scale - 0.5,
        ]
        lengths, fraction = court_visibility(genome, size, spec, style)
        lines = visible_floor_lines(lengths)
    return CasePlan(genome, size, spec, style, lines, fraction, base)


# How long a clip lasts (s): a user's clip lasts seconds or minutes; the service asks for a
# static view of at least `background.MIN_STATIC_VIEW_S`.
CLIP_SECONDS = 3.0


def _make_clip(rng: np.random.Generator, seed: int, spec: str) -> SyntheticCase:
    plan = _clip_plan(rng, spec)
    base = plan.filmed_like
    style = plan.style
    size = plan.size
    lines, fraction = plan.visible_lines, plan.floor_fraction
    placement = _Placement(plan.genome, size, plan.style.preset, False)
    n_frames = int(rng.integers(10, 17))
    fps = float(_choose(rng, [(0.7, 25.0), (0.3, 30.0)]))
    paths = scene.player_paths(n_frames, 2, rng, spec)
    people0 = _people(rng, spec, 2)
    cut = base == "broadcast_glass" and rng.random() < 0.5 or rng.random() < 0.1
    cut_frames: set[int] = set()
    if cut:
        n_cut = int(rng.integers(1, 4))
        start = 0 if rng.random() < 0.6 else int(rng.integers(3, n_frames - n_cut))
        cut_frames = set(range(start, start + n_cut))
    main = [k for k in range(n_frames) if k not in cut_frames]
    # the longest run of main-shot frames
    runs: list[tuple[int, int]] = []
    for k in main:
        if runs and runs[-1][1] == k:
            runs[-1] = (runs[-1][0], k + 1)
        else:
            runs.append((k, k + 1))
    main_shot = max(runs, key=lambda r: r[1] - r[0])
    render_rng = np.random.default_rng(rng.integers(1 << 62))
    layers = scene.render_layers(placement.genome, size, spec, style, render_rng)
    cut_layers = None
    cut_genome = None
    if cut_frames:
        k0 = min(cut_frames)
        cut_genome = _close_up(rng, placement.genome, size, paths[k0, int(rng.integers(2))])
        cut_style = replace(
            style, blur_px=style.blur_px + float(rng.uniform(0.5, 2.5)), overlays=()
        )
        cut_layers = scene.render_layers(cut_genome, size, spec, cut_style, render_rng)
    frames = []
    for k in range(n_frames):
        people = tuple(
            replace(
                p,
                x=float(paths[k, i, 0]),
                y=float(paths[k, i, 1]),
                arm=float(0.5 + 0.5 * np.sin(0.7 * k + i)),
            )
            for i, p in enumerate(people0)
        )
        if k in cut_frames:
            assert cut_layers is not None and cut_genome is not None
            frames.append(
                scene.finish_frame(
                    cut_layers, cut_genome, replace(style, overlays=()), render_rng, people
                )
            )
        else:
            frames.append(scene.finish_frame(layers, placement.genome, style, render_rng, people))
    final_style = replace(
        style,
        players=tuple(
            replace(p, x=float(paths[main_shot[0], i, 0]), y=float(paths[main_shot[0], i, 1]))
            for i, p in enumerate(people0)
        ),
    )
    return SyntheticCase(
        frames[main_shot[0]],
        placement.genome,
        spec,
        "clip",
        int(seed),
        final_style,
        size,
        frames=tuple(frames),
        fps=fps,
        main_shot=main_shot,
        cut_frames=tuple(sorted(cut_frames)),
        visible_lines=lines,
        floor_fraction=fraction,
        frame_hold=max(1, round(CLIP_SECONDS * fps / n_frames)),
    )


# ----------------------------------------------------------------------------------------------
# Negatives: no squash court anywhere


def _line(ax: float, ay: float, bx: float, by: float, colour: int) -> tuple[float, ...]:
    return (ax, ay, 0.0, bx, by, 0.0, 0.0, float(colour))


def _rect_lines(x0: float, y0: float, x1: float, y1: float, colour: int) -> list[tuple[float, ...]]:
    return [
        _line(x0, y0, x1, y0, colour),
        _line(x1, y0, x1, y1, colour),
        _line(x1, y1, x0, y1, colour),
        _line(x0, y1, x0, y0, colour),
    ]


def sport_layout(
    sport: str, x0: float, y0: float, colour: int
) -> tuple[list[tuple[float, ...]], list[tuple[float, ...]], tuple[float, float]]:
    """Floor lines and arcs of another sport's court with its corner at (x0, y0) (x across, y
    along); returns (lines, arcs, (width, length))."""
    lines: list[tuple[float, ...]] = []
    arcs: list[tuple[float, ...]] = []
    if sport == "badminton":
        w, length = 6.1, 13.4
        lines += _rect_lines(x0, y0, x0 + w, y0 + length, colour)
        mid = y0 + length / 2
        for sx in (0.46, w - 0.46):
            lines.append(_line(x0 + sx, y0, x0 + sx, y0 + length, colour))
        for dy in (-1.98, 1.98):
            lines.append(_line(x0, mid + dy, x0 + w, mid + dy, colour))
        for yy in (y0 + 0.76, y0 + length - 0.76):
            lines.append(_line(x0, yy, x0 + w, yy, colour))
        lines.append(_line(x0 + w / 2, y0, x0 + w / 2, mid - 1.98, colour))
        lines.append(_line(x0 + w / 2, mid + 1.98, x0 + w / 2, y0 + length, colour))
    elif sport == "tennis":
        w, length = 10.97, 23.77
        lines += _rect_lines(x0, y0, x0 + w, y0 + length, colour)
        mid = y0 + length / 2
        for sx in (1.37, w - 1.37):
            lines.append(_line(x0 + sx, y0, x0 + sx, y0 + length, colour))
        for dy in (-6.4, 6.4):
            lines.append(_line(x0 + 1.37, mid + dy, x0 + w - 1.37, mid + dy, colour))
        lines.append(_line(x0 + w / 2, mid - 6.4, x0 + w / 2, mid + 6.4, colour))
        for yy, d in ((y0, 0.1), (y0 + length, -0.1)):
            lines.append(_line(x0 + w / 2, yy, x0 + w / 2, yy + d, colour))
    elif sport == "basketball":
        w, length = 15.0, 28.0
        lines += _rect_lines(x0, y0, x0 + w, y0 + length, colour)
        mid = y0 + length / 2
        lines.append(_line(x0, mid, x0 + w, mid, colour))
        arcs.append((x0 + w / 2, mid, 1.8, 0.0, 2 * np.pi, float(colour)))
        for end, sign in ((y0, 1.0), (y0 + length, -1.0)):
            kx0, kx1 = x0 + w / 2 - 2.45, x0 + w / 2 + 2.45
            ky = end + sign * 5.8
            lines += [
                _line(kx0, end, kx0, ky, colour),
                _line(kx1, end, kx1, ky, colour),
                _line(kx0, ky, kx1, ky, colour),
            ]
            arcs.append((x0 + w / 2, ky, 1.8, 0.0, 2 * np.pi, float(colour)))
            basket_y = end + sign * 1.575
            a0, a1 = (0.2, np.pi - 0.2) if sign > 0 else (np.pi + 0.2, 2 * np.pi - 0.2)
            arcs.append((x0 + w / 2, basket_y, 6.75, a0, a1, float(colour)))
            for sx in (0.9, w - 0.9):
                lines.append(
                    _line(x0 + sx, end, x0 + sx, basket_y + sign * 6.75 * np.sin(0.2), colour)
                )
    elif sport == "volleyball":
        w, length = 9.0, 18.0
        lines += _rect_lines(x0, y0, x0 + w, y0 + length, colour)
        mid = y0 + length / 2
        for dy in (-3.0, 0.0, 3.0):
            lines.append(_line(x0, mid + dy, x0 + w, mid + dy, colour))
    elif sport == "futsal":
        w, length = 20.0, 40.0
        lines += _rect_lines(x0, y0, x0 + w, y0 + length, colour)
        mid = y0 + length / 2
        lines.append(_line(x0, mid, x0 + w, mid, colour))
        arcs.append((x0 + w / 2, mid, 3.0, 0.0, 2 * np.pi, float(colour)))
        for end, sign in ((y0, 1.0), (y0 + length, -1.0)):
            a0, a1 = (0.0, np.pi) if sign > 0 else (np.pi, 2 * np.pi)
            arcs.append((x0 + w / 2, end, 6.0, a0, a1, float(colour)))
            arcs.append((x0 + w / 2, end + sign * 10.0, 0.1, 0.0, 2 * np.pi, float(colour)))
    else:
        raise ValueError(sport)
    return lines, arcs, (w, length)


# painted sports floors by colour; None: plain wooden strips
SPORT_FLOORS: list[tuple[float, tuple[float, float, float] | None]] = [
    (0.35, None),
    (0.25, (150.0, 95.0, 45.0)),
    (0.15, (60.0, 110.0, 60.0)),
    (0.15, (60.0, 110.0, 190.0)),
    (0.1, (110.0, 110.0, 110.0)),
]
SPORT_LINE_COLOURS = [
    (236, 236, 236),
    (40, 210, 232),
    (40, 42, 190),
    (205, 120, 30),
    (40, 40, 40),
    (60, 160, 60),
]


def _sports_hall(
    rng: np.random.Generator, kind: str
) -> tuple[np.ndarray, tuple[int, int], SceneStyle]:
    sports = (
        [kind]
        if kind != "multisport"
        else list(
            rng.choice(
                ["badminton", "basketball", "volleyball", "futsal"],
                size=int(rng.integers(2, 4)),
                replace=False,
            )
        )
    )
    palette = [SPORT_LINE_COLOURS[int(k)] for k in rng.permutation(len(SPORT_LINE_COLOURS))]
    lines: list[tuple[float, ...]] = []
    arcs: list[tuple[float, ...]] = []
    extent = np.zeros(2)
    layouts = []
    for k, sport in enumerate(sports):
        _, _, dims = sport_layout(sport, 0.0, 0.0, 0)
        layouts.append((sport, dims, k))
        extent = np.maximum(extent, dims)
    for sport, dims, k in layouts:
        x0 = (extent[0] - dims[0]) / 2 + float(rng.uniform(-0.5, 0.5)) * (len(sports) > 1)
        y0 = (extent[1] - dims[1]) / 2
        ln, ar, _ = sport_layout(sport, x0, y0, k)
        lines += ln
        arcs += ar
    margin = float(rng.uniform(1.0, 3.0))
    floor_choice = _choose(rng, SPORT_FLOORS)
    if floor_choice is None:
        floor = scene_styles._wood_floor(rng, [(1, "maple"), (1, "honey"), (1, "pale")])
    else:
        floor = scene.Material(
            "flat", scene_styles._jitter(rng, floor_choice), 1.0, (0.04, 0.02, 0.05, 0.0)
        )
    surround = scene.Material(
        "flat",
        scene_styles._jitter(rng, (float(rng.uniform(40, 200)),) * 3, 30.0),
        1.0,
        (0.04, 0.02, 0.0, 0.0),
    )
    walls, ceiling = scene_styles._hall_lit(rng)
    hall = (
        -margin - float(rng.uniform(1, 6)),
        extent[0] + margin + float(rng.uniform(1, 6)),
        -margin - float(rng.uniform(1, 6)),
        extent[1] + margin + float(rng.uniform(1, 8)),
        float(rng.uniform(6.0, 12.0)),
    )
    net = sports[0] in ("badminton", "volleyball", "tennis") and rng.random() < 0.6
    net_height = {"badminton": 1.55, "volleyball": 2.43, "tennis": 1.07}.get(sports[0], 1.0)
    style = SceneStyle(
        preset=f"negative_{kind}",
        court=False,
        floor_area=(
            -margin * 0.3,
            -margin * 0.3,
            extent[0] + margin * 0.3,
            extent[1] + margin * 0.3,
        ),
        floor=floor,
        floor_gloss=float(rng.uniform(0.0, 0.2)),
        hall=hall,
        hall_floor=surround,
        hall_walls=walls,
        ceiling=ceiling,
        line_colours=tuple(palette[: max(4, len(sports))]),
        extra_lines=tuple(lines),
        extra_arcs=tuple(arcs),
        stands=(rng.random() < 0.3, rng.random() < 0.3),
        stand_offset_m=margin + 1.0,
        stand_span=(0.0, float(extent[1])),
        railing=net,
        railing_y=float(extent[1] / 2),
        railing_height_m=net_height,
        railing_mid_bars=int(rng.integers(6, 14)),
        railing_post_spacing_m=float(rng.uniform(0.05, 0.15)),
        railing_bar_m=0.012,
        railing_colour=(30, 30, 30),
        adverts=tuple(scene_styles._hall_decor(rng, hall, True)),
    )
    # a camera at one end or one side, up in the stands or on a balcony
    size = _size(
        rng, [(0.3, (1280, 720)), (0.3, (960, 540)), (0.2, (1920, 1080)), (0.2, (640, 360))]
    )
    court_pts = np.array(
        [[0, 0, 0], [extent[0], 0, 0], [0, extent[1], 0], [extent[0], extent[1], 0]], float
    )
    if rng.random() < 0.5:
        centre = np.array(
            [
                extent[0] / 2 + float(rng.normal(0, 1.0)),
                extent[1] + margin + float(rng.uniform(0.5, 5.0)),
                -float(rng.uniform(2.0, 9.0)),
            ]
        )
    else:
        centre = np.array(
            [
                -margin - float(rng.uniform(0.3, 4.0)),
                extent[1] / 2 + float(rng.normal(0, 2.0)),
                -float(rng.uniform(2.0, 9.0)),
            ]
        )
    if rng.random() < 0.4:
        # only part of the floor
        court_pts = court_pts * np.array([1.0, float(rng.uniform(0.4, 0.7)), 1.0]) + np.array(
            [0.0, float(rng.uniform(0.0, 0.3)) * extent[1], 0.0]
        )
    genome = frame_camera(
        centre,
        court_pts,
        size,
        float(rng.uniform(0.8, 1.1)),
        float(np.radians(rng.normal(0, 1.0))),
        _fold_safe_dist(rng, float(rng.uniform(-0.2, 0.03))),
    )
    chain = _video_chain(rng, str(rng.choice(["broadcast", "club", "phone"])))
    style = replace(style, **chain)
    return genome, size, style


def _room(
    rng: np.random.Generator, corridor: bool
) -> tuple[np.ndarray, tuple[int, int], SceneStyle]:
    if corridor:
        width, length, height = (
            float(rng.uniform(1.6, 3.2)),
            float(rng.uniform(10.0, 30.0)),
            float(rng.uniform(2.4, 3.2)),
        )
    else:
        width, length, height = (
            float(rng.uniform(3.0, 7.0)),
            float(rng.uniform(3.5, 9.0)),
            float(rng.uniform(2.4, 3.4)),
        )
    kind = str(rng.choice(["planks", "tiles", "carpet", "flat"]))
    if kind == "planks":
        floor = scene_styles._wood_floor(
            rng, [(1, "maple"), (1, "honey"), (1, "amber"), (1, "dark")]
        )
    elif kind == "tiles":
        floor = scene.Material(
            "tiles",
            scene_styles._jitter(rng, (float(rng.uniform(80, 220)),) * 3, 40.0),
            1.0,
            (
                float(rng.uniform(0.2, 0.8)),
                float(rng.uniform(0.002, 0.008)),
                float(rng.uniform(0.2, 0.5)),
                0.1,
            ),
        )
    elif kind == "carpet":
        floor = scene.Material(
            "carpet",
            scene_styles._jitter(rng, (float(rng.uniform(40, 160)),) * 3, 50.0),
            1.0,
            (0.1, 0.2),
        )
    else:
        floor = scene.Material(
            "flat",
            scene_styles._jitter(rng, (float(rng.uniform(60, 200)),) * 3, 40.0),
            1.0,
            (0.04, 0.03, 0.0, 0.0),
        )
    wall_colour = scene_styles._jitter(
        rng,
        (
            (228.0, 232.0, 234.0),
            (200.0, 215.0, 225.0),
            (180.0, 200.0, 210.0),
            (150.0, 170.0, 190.0),
            (200.0, 190.0, 170.0),
        )[int(rng.integers(5))],
        10.0,
    )
    walls = scene.Material(
        "panels",
        wall_colour,
        float(rng.uniform(0.7, 1.0)),
        (
            float(rng.uniform(1.0, 4.0)),
            float(rng.uniform(0.0, 0.15)),
            float(rng.uniform(0.0, 1.1)),
            float(rng.uniform(0.8, 1.0)),
            0.04,
        ),
    )
    ceiling = scene.Material(
        "ceiling",
        scene_styles._jitter(rng, (225.0, 228.0, 228.0), 10.0),
        float(rng.uniform(0.7, 0.95)),
        (
            float(rng.uniform(1.5, 3.5)),
            float(rng.uniform(1.5, 3.5)),
            float(rng.uniform(0.2, 1.2)),
            float(rng.uniform(0.2, 0.6)),
            float(rng.uniform(250, 320)),
            0.0,
            0.0,
        ),
    )
    hall = (0.0, width, 0.0, length, height)
    # skirting boards: painted bands along the foot of every wall; door frames; windows
    skirting = float(rng.uniform(0.05, 0.12))
    colour = 0
    lines = [
        (0.0, 0.0, -skirting, 0.0, length, -skirting, 6.0, float(colour)),
        (width, 0.0, -skirting, width, length, -skirting, 7.0, float(colour)),
        (0.0, 0.0, -skirting, width, 0.0, -skirting, 8.0, float(colour)),
        (0.0, 0.0, -0.01, 0.0, length, -0.01, 6.0, float(colour)),
        (width, 0.0, -0.01, width, length, -0.01, 7.0, float(colour)),
        (0.0, 0.0, -0.01, width, 0.0, -0.01, 8.0, float(colour)),
    ]
    adverts = []
    for surface, extent in (("hall_left", length), ("hall_right", length), ("hall_front", width)):
        n = int(rng.integers(0, 4 if not corridor else 7))
        for _ in range(n):
            kind_ad = str(
                rng.choice(
                    ["door", "window", "poster", "door"]
                    if surface != "hall_front" or not corridor
                    else ["door", "window"]
                )
            )
            if kind_ad == "door":
                w_ad, h_ad, b0 = 0.9, 2.05, 0.0
            elif kind_ad == "window":
                w_ad, h_ad = float(rng.uniform(0.8, 2.5)), float(rng.uniform(1.0, 1.5))
                b0 = float(rng.uniform(0.8, 1.1))
            else:
                w_ad = float(rng.uniform(0.4, 1.2))
                h_ad = w_ad * float(rng.uniform(0.6, 1.4))
                b0 = float(rng.uniform(1.0, 1.6))
            if w_ad > extent - 0.4 or b0 + h_ad > height - 0.1:
                continue
            a0 = float(rng.uniform(0.2, extent - w_ad - 0.2))
            colours = (
                ((235, 235, 230), (60, 60, 60), (150, 150, 150))
                if kind_ad == "window"
                else (
                    scene_styles._jitter(rng, (float(rng.uniform(60, 220)),) * 3, 50.0),
                    (60, 60, 60),
                    scene_styles._jitter(rng, (200.0, 200.0, 200.0), 40.0),
                )
            )
            adverts.append(
                scene_styles._advert(
                    rng,
                    surface,
                    (a0, a0 + w_ad, b0, b0 + h_ad),
                    kind_ad,
                    1.0,
                    0.6 if kind_ad == "window" else 0.0,
                    colours=colours,
                )
            )
    style = SceneStyle(
        preset="negative_room",
        court=False,
        floor_area=(0.0, 0.0, width, length),
        floor=floor,
        floor_gloss=float(rng.uniform(0.0, 0.15)),
        hall=hall,
        hall_floor=floor,
        hall_walls=walls,
        ceiling=ceiling,
        line_colours=(
            scene_styles._jitter(
                rng,
                ((240.0, 240.0, 240.0), (60.0, 60.0, 60.0), (90.0, 120.0, 150.0))[
                    int(rng.integers(3))
                ],
                8.0,
            ),
        )
        * 4,
        extra_lines=tuple(lines),
        adverts=tuple(adverts),
    )
    size = _size(
        rng, [(0.3, (1280, 720)), (0.3, (960, 540)), (0.2, (1024, 768)), (0.2, (640, 480))]
    )
    centre = np.array(
        [
            width * float(rng.uniform(0.2, 0.8)),
            length - float(rng.uniform(0.3, 1.0)),
            -float(rng.uniform(1.2, 1.8)),
        ]
    )
    target = np.array(
        [
            width * float(rng.uniform(0.2, 0.8)),
            float(rng.uniform(0.0, length * 0.5)),
            -float(rng.uniform(0.3, 1.8)),
        ]
    )
    rotation = look_at_rotation(centre, target, float(np.radians(rng.normal(0, 1.5))))
    f = size[0] * float(rng.uniform(0.45, 0.9))
    genome = make_genome(
        centre,
        rotation,
        f,
        f,
        tuple(picture_centre(size)),
        _fold_safe_dist(rng, float(rng.uniform(-0.08, 0.02))),
    )
    style = replace(style, **_video_chain(rng, "phone"))
    return genome, size, style


def _texture_image(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    kind = str(rng.choice(["planks", "tiles", "brick", "carpet"]))
    big = np.zeros((height * 2, width * 2, 3), np.float32)
    h2, w2 = big.shape[:2]
    base = np.array(
        scene_styles._jitter(
            rng,
            (
                (150.0, 196.0, 228.0),
                (180.0, 180.0, 175.0),
                (60.0, 80.0, 150.0),
                (90.0, 90.0, 110.0),
            )[int(rng.integers(4))],
            30.0,
        ),
        np.float32,
    )
    blurred = cv2.GaussianBlur(
        rng.normal(0, 1, (h2, w2)).astype(np.float32), (0, 0), float(rng.uniform(1, 6))
    )
    noise = np.asarray(blurred, np.float32) / max(1e-6, float(np.abs(blurred).max()))
    big[:] = base
    big *= (1.0 + 0.08 * noise)[:, :, None]
    if kind == "planks":
        pw = int(rng.integers(20, 80))
        for x0 in range(0, w2, pw):
            tone = float(rng.uniform(0.8, 1.2))
            big[:, x0 : x0 + pw] *= tone
            cv2.line(big, (x0, 0), (x0, h2), tuple(float(c) * 0.6 for c in base), 1)
            y = int(rng.integers(0, h2))
            cv2.line(big, (x0, y), (x0 + pw, y), tuple(float(c) * 0.6 for c in base), 1)
    elif kind in ("tiles", "brick"):
        tw = int(rng.integers(30, 120))
        th = tw if kind == "tiles" else tw // 3
        grout = tuple(
            float(v)
            for v in scene_styles._jitter(
                rng, (200.0, 200.0, 200.0) if rng.random() < 0.5 else (60.0, 60.0, 60.0), 20.0
            )
        )
        for r, y0 in enumerate(range(0, h2, th)):
            offset = (tw // 2) * (r % 2) if kind == "brick" else 0
            for x0 in range(-offset, w2, tw):
                big[y0 : y0 + th, max(x0, 0) : x0 + tw] *= float(rng.uniform(0.85, 1.15))
                cv2.rectangle(big, (x0, y0), (x0 + tw, y0 + th), grout, max(1, tw // 25))
    else:
        fine = rng.normal(0, 1, (h2, w2)).astype(np.float32)
        big *= (1.0 + 0.15 * fine)[:, :, None]
    if rng.random() < 0.6:
        big = _perspective(rng, big, (w2, h2), (w2, h2), (40, 40, 40))
    return cv2.resize(big, (width, height), interpolation=cv2.INTER_AREA)


def _perspective(
    rng: np.random.Generator,
    image: np.ndarray,
    src_size: tuple[int, int],
    dst_size: tuple[int, int],
    background: tuple[int, int, int],
) -> np.ndarray:
    sw, sh = src_size
    dw, dh = dst_size
    src = np.array([[0, 0], [sw, 0], [sw, sh], [0, sh]], np.float32)
    jit = rng.uniform(-0.25, 0.25, (4, 2)) * [dw, dh]
    dst = np.array(
        [[0.1 * dw, 0.1 * dh], [0.9 * dw, 0.1 * dh], [0.9 * dw, 0.9 * dh], [0.1 * dw, 0.9 * dh]],
        np.float32,
    ) + jit.astype(np.float32)
    if rng.random() < 0.5:
        # a floor seen at an angle: the far edge shrinks
        squeeze = float(rng.uniform(0.15, 0.4)) * dw
        dst = np.array(
            [
                [squeeze, 0.2 * dh],
                [dw - squeeze, 0.2 * dh],
                [dw * 1.3, dh * 1.1],
                [-0.3 * dw, dh * 1.1],
            ],
            np.float32,
        )
    m = cv2.getPerspectiveTransform(src, dst)
    return cv2.warpPerspective(
        image, m, (dw, dh), borderMode=cv2.BORDER_CONSTANT, borderValue=background
    )


def _text_page(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    pw, ph = 850, 1100
    page = np.full((ph, pw, 3), scene_styles._jitter(rng, (238.0, 242.0, 245.0), 8.0), np.uint8)
    y = 80
    font = int(
        rng.choice(
            [
                cv2.FONT_HERSHEY_SIMPLEX,
                cv2.FONT_HERSHEY_COMPLEX,
                cv2.FONT_HERSHEY_TRIPLEX,
                cv2.FONT_HERSHEY_DUPLEX,
            ]
        )
    )
    cv2.putText(
        page, scene_art.brand_name(rng).title(), (70, y), font, 1.4, (20, 20, 20), 2, cv2.LINE_AA
    )
    y += 60
    while y < ph - 60:
        if rng.random() < 0.08:
            # a small table: a grid of rules
            rows, cols = int(rng.integers(3, 7)), int(rng.integers(2, 5))
            th = rows * 28
            if y + th > ph - 60:
                break
            for r in range(rows + 1):
                cv2.line(page, (70, y + r * 28), (pw - 70, y + r * 28), (40, 40, 40), 1)
            for c in range(cols + 1):
                x = 70 + c * (pw - 140) // cols
                cv2.line(page, (x, y), (x, y + th), (40, 40, 40), 1)
            y += th + 30
            continue
        words = " ".join(scene_art.brand_name(rng).lower() for _ in range(int(rng.integers(4, 9))))
        cv2.putText(page, words[:70], (70, y), font, 0.6, (30, 30, 30), 1, cv2.LINE_AA)
        y += int(rng.integers(24, 34))
    desk = np.full(
        (height, width, 3), scene_styles._jitter(rng, (60.0, 90.0, 120.0), 40.0), np.uint8
    )
    if rng.random() < 0.4:
        return cv2.resize(page, (width, height), interpolation=cv2.INTER_AREA)
    corner = (int(desk[0, 0, 0]), int(desk[0, 0, 1]), int(desk[0, 0, 2]))
    return _perspective(rng, page, (pw, ph), (width, height), corner)


def _checkerboard(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    nx, ny = int(rng.integers(5, 13)), int(rng.integers(4, 10))
    sq = 60
    board = np.full(((ny + 2) * sq, (nx + 2) * sq, 3), 245, np.uint8)
    for j in range(ny):
        for i in range(nx):
            if (i + j) % 2 == 0:
                board[(j + 1) * sq : (j + 2) * sq, (i + 1) * sq : (i + 2) * sq] = 15
    background = scene_styles._jitter(rng, (float(rng.uniform(40, 200)),) * 3, 40.0)
    if rng.random() < 0.35:
        out = cv2.resize(board, (width, height), interpolation=cv2.INTER_AREA)
    else:
        out = _perspective(
            rng, board, (board.shape[1], board.shape[0]), (width, height), background
        )
    return out


def _photo(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A procedural 'photo': a lit gradient backdrop, a floor, furniture-like boxes, random shapes."""
    width, height = size
    yy = np.linspace(0, 1, height, dtype=np.float32)[:, None, None]
    top = np.array(scene_styles._jitter(rng, (float(rng.uniform(120, 250)),) * 3, 60.0), np.float32)
    bottom = np.array(
        scene_styles._jitter(rng, (float(rng.uniform(30, 160)),) * 3, 60.0), np.float32
    )
    image = np.ascontiguousarray(
        np.broadcast_to(top * (1 - yy) + bottom * yy, (height, width, 3))
    ).astype(np.float32)
    horizon = int(height * float(rng.uniform(0.4, 0.75)))
    floor_colour = np.array(
        scene_styles._jitter(rng, (float(rng.uniform(50, 200)),) * 3, 50.0), np.float32
    )
    image[horizon:] = (
        floor_colour * np.linspace(0.8, 1.1, height - horizon, dtype=np.float32)[:, None, None]
    )
    # furniture: boxes with three shaded faces
    for _ in range(int(rng.integers(1, 6))):
        bw = int(rng.uniform(0.1, 0.35) * width)
        bh = int(rng.uniform(0.1, 0.4) * height)
        x0 = int(rng.uniform(0, width - bw))
        y1 = int(rng.uniform(horizon, height))
        depth = int(rng.uniform(0.02, 0.1) * width)
        colour = np.array(
            scene_styles._jitter(rng, (float(rng.uniform(40, 220)),) * 3, 70.0), np.float32
        )
        front = np.array([[x0, y1], [x0 + bw, y1], [x0 + bw, y1 - bh], [x0, y1 - bh]], np.int32)
        top_face = np.array(
            [
                [x0, y1 - bh],
                [x0 + bw, y1 - bh],
                [x0 + bw + depth, y1 - bh - depth],
                [x0 + depth, y1 - bh - depth],
            ],
            np.int32,
        )
        side = np.array(
            [
                [x0 + bw, y1],
                [x0 + bw + depth, y1 - depth],
                [x0 + bw + depth, y1 - bh - depth],
                [x0 + bw, y1 - bh],
            ],
            np.int32,
        )
        cv2.fillPoly(image, [side], tuple(float(c) * 0.6 for c in colour), cv2.LINE_AA)
        cv2.fillPoly(image, [top_face], tuple(float(c) * 1.15 for c in colour), cv2.LINE_AA)
        cv2.fillPoly(image, [front], tuple(float(c) for c in colour), cv2.LINE_AA)
    for _ in range(int(rng.integers(3, 15))):
        paint = tuple(float(c) for c in rng.uniform(0, 255, 3))
        shape = int(rng.integers(3))
        if shape == 0:
            cv2.circle(
                image,
                (int(rng.integers(0, width)), int(rng.integers(0, height))),
                int(rng.integers(5, max(6, width // 8))),
                paint,
                -1,
                cv2.LINE_AA,
            )
        elif shape == 1:
            cv2.line(
                image,
                (int(rng.integers(0, width)), int(rng.integers(0, height))),
                (int(rng.integers(0, width)), int(rng.integers(0, height))),
                paint,
                int(rng.integers(1, 6)),
                cv2.LINE_AA,
            )
        else:
            pts = rng.integers(0, [width, height], (int(rng.integers(3, 7)), 2)).astype(np.int32)
            cv2.fillPoly(image, [pts], paint, cv2.LINE_AA)
    return image


def make_negative(kind: str, seed: int) -> NegativeCase:
    """An image with no squash court (see `NEGATIVE_KINDS`). Deterministic."""
    if kind not in NEGATIVE_KINDS:
        raise ValueError(
            f"unknown negative kind {kind!r}; expected one of {', '.join(NEGATIVE_KINDS)}"
        )
    rng = _rng("negative_" + kind, seed)
    if kind in (
        "badminton",
        "tennis",
        "basketball",
        "volleyball",
        "futsal",
        "multisport",
        "room",
        "corridor",
    ):
        if kind in ("room", "corridor"):
            genome, size, style = _room(rng, kind == "corridor")
        else:
            genome, size, style = _sports_hall(rng, kind)
        if not lens_covers_image(genome, size):
            genome = as_population(genome)[0].copy()
            genome[DISTORTION_GENES] = 0.0
        image = scene.render_scene(
            genome, size, "wsf", style, np.random.default_rng(rng.integers(1 << 62))
        )
        return NegativeCase(image, kind, int(seed), style)
    size = _size(
        rng, [(0.3, (1280, 720)), (0.3, (960, 540)), (0.2, (1024, 768)), (0.2, (640, 480))]
    )
    if kind == "texture":
        picture = _texture_image(rng, size)
    elif kind == "text_page":
        picture = _text_page(rng, size).astype(np.float32)
    elif kind == "checkerboard":
        picture = _checkerboard(rng, size).astype(np.float32)
    else:
        picture = _photo(rng, size)
    chain = SceneStyle(**_video_chain(rng, "phone"))
    image = scene.apply_camera(picture, chain, rng)
    image = scene.apply_jpeg(image, chain.jpeg_quality)
    return NegativeCase(image, kind, int(seed))
