"""Realistic, domain-randomised renders of squash courts (and of other scenes, for negatives).

Every pixel's ray (2 x 2 supersamples) is cast through the lens model (`scene_raycast`), so painted
lines sit exactly on the model's line centres (50 mm wide) under any distortion, and glass walls
mirror the court by tracing the reflected ray. A `SceneStyle` (plain values, sampled from a seed by
`sample_style`) says what the court and its hall look like; `render_scene` renders it:

1. the ray-cast court, walls, glass (tint, haze, Fresnel reflections, fins, clamps, door), hall,
   crowd, gallery and railing, adverts and decals;
2. players (figures with shadows) composited behind whatever lies between camera and court;
3. the camera: exposure, white balance, vignetting, tone curve, blur, anamorphic softness, noise;
4. burned-in graphics (score bars, channel logos, clocks, stream text, letterboxing);
5. JPEG compression.

`render_court_image` / `render_clip_frames` keep the plain club look of the earlier renderer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from app.calib import scene_art
from app.calib import scene_raycast as rc
from app.calib.camera import (
    DISTORTION_GENES,
    as_population,
    check_image_size,
    court_extrinsics,
    floor_to_pixel,
    project_points,
    undistort_normalized,
)
from app.calib.court import PAINTED_EDGES, CourtModel, court_model, get_spec

SUPERSAMPLING = 2  # 2 x 2 samples per pixel, box-filtered: anti-aliased edges
# Rays are exact on a grid of pixel positions and bilinear between. An 8 px grid is exact enough
# (< 0.01 px) for mild lenses, but where a strong barrel lens compresses the periphery most its
# inverse bends faster than bilinear follows (k1 -0.14, f 620 px at 1080p: 1 px off at 8 px,
# 0.07 px at 2 px), which drew wide-angle benchmark cases' side walls where the camera model does
# not: the coarsest step whose worst error stays under RAY_GRID_MAX_ERROR_PX is used.
RAY_GRID_STEPS_PX = (8, 4, 2, 1)
RAY_GRID_MAX_ERROR_PX = 0.1
RAY_GRID_ORIGIN_PX = -0.5
SENSOR_NOISE_SIGMA = 1.5  # grey levels, per channel (render_court_image)
TEXTURE_SIZE = 256
PLAYER_HEIGHT_M = 1.8

BGR = tuple[int, int, int]

# line colour slots: the court's own lines use the first four, extra lines index further
_LINE_SLOT = {rc.S_FLOOR: 0, rc.S_FRONT: 1, rc.S_LEFT: 2, rc.S_RIGHT: 2, rc.S_BACK: 3}
N_COURT_LINE_COLOURS = 4

_MATERIALS = {
    "plaster": rc.M_PLASTER,
    "planks": rc.M_PLANKS,
    "flat": rc.M_FLAT,
    "glass": rc.M_GLASS_FLOOR,
    "carpet": rc.M_CARPET,
    "tiles": rc.M_TILES,
    "panels": rc.M_PANELS,
    "ceiling": rc.M_CEILING,
    "crowd": rc.M_CROWD,
    "metal": rc.M_METAL,
}


@dataclass(frozen=True)
class Material:
    """A surface finish: kind (a key of the renderer's materials), base colour, light, parameters.

    Parameters by kind (metres where lengths): planks (width, length, tone spread, grain, seam
    darkness, axis 0 = along y / 1 = along x, light pool); flat (mottle, fine noise, pool, planks
    under paint 0..1); glass (panel size, joint darkness, mottle); carpet (strength, scale); tiles
    (size, grout width, grout darkness, tone spread); panels (width, joint darkness, dado height,
    dado multiplier, mottle); ceiling (light spacing x, y, light size x, y, light level, beam
    spacing, beam darkness); crowd (density, row depth, seat width, clothes light, seed);
    plaster (mottle, ball-mark density, ball-mark strength, dirt near the floor, light gradient with
    height, light gradient along the wall); metal (sheen).
    """

    kind: str
    colour: BGR
    light: float = 1.0
    params: tuple[float, ...] = ()


@dataclass(frozen=True)
class Advert:
    """A textured rectangle on a surface: `rect` = (a0, a1, b0, b1) metres in surface coordinates.

    Surface coordinates: floor, hall floor, gallery, ceiling (x, y); front, back, hall front/back,
    railing (x, height); left, right, hall left/right (y, height). Kinds: banner, board, text,
    logo, wordmark, flag, stripes, door, window, poster (`scene_art.advert_texture`).
    """

    surface: str
    rect: tuple[float, float, float, float]
    kind: str
    text: str = ""
    colours: tuple[BGR, ...] = ((255, 255, 255), (20, 20, 20), (30, 30, 200))
    opacity: float = 1.0
    emissive: float = 0.0
    mirrored: bool = False
    seed: int = 0


@dataclass(frozen=True)
class Overlay:
    """A burned-in graphic: `rect` = (x0, y0, x1, y1) as fractions of the image width / height."""

    kind: str
    rect: tuple[float, float, float, float]
    text: str = ""
    colours: tuple[BGR, ...] = ((245, 245, 245), (30, 30, 30), (40, 40, 200))
    alpha: float = 1.0
    seed: int = 0


@dataclass(frozen=True)
class Person:
    """A player standing on the floor at (x, y) metres."""

    x: float
    y: float
    shirt: BGR
    shorts: BGR
    skin: BGR
    height_m: float = PLAYER_HEIGHT_M
    stride: float = 0.25  # feet apart, fraction of the height
    lean: float = 0.0  # sideways lean, fraction of the height
    arm: float = 0.5  # racket arm raise 0..1
    shoes: BGR = (235, 235, 235)


@dataclass(frozen=True)
class SceneStyle:
    """Everything a render looks like, as plain values (sampled from a seed by `sample_style`)."""

    preset: str = "classic"
    # the squash court (False: no squash court at all, e.g. another sport's hall or a room)
    court: bool = True
    floor_area: tuple[float, float, float, float] = (
        0.0,
        0.0,
        0.0,
        0.0,
    )  # x0, y0, x1, y1 if no court
    floor: Material = Material(
        "planks", (146, 190, 224), 1.0, (0.075, 2.1, 0.12, 0.05, 0.15, 0, 0.06)
    )
    floor_gloss: float = 0.0
    front: Material = Material("plaster", (226, 230, 233), 1.0, (0.05, 0.0, 0.0, 0.0))
    left: Material = Material("plaster", (226, 230, 233), 0.93, (0.05, 0.0, 0.0, 0.0))
    right: Material = Material("plaster", (226, 230, 233), 0.88, (0.05, 0.0, 0.0, 0.0))
    back: Material = Material("plaster", (226, 230, 233), 1.0, (0.05, 0.0, 0.0, 0.0))
    tin_colour: BGR = (150, 150, 158)
    # line colours: floor, front wall, side walls, back wall; extra (non-squash) lines follow
    line_colours: tuple[BGR, ...] = ((40, 42, 188),) * 4
    line_alpha: float = 1.0
    line_wear: float = 0.0
    line_glow: float = 0.0
    line_glow_width_m: float = 0.05
    # wall heights above the out lines' upper edges (m)
    front_above_out_m: float = 0.5
    side_above_out_m: tuple[float, float] = (0.3, 0.3)  # at the front, at the back
    back_above_out_m: float = 0.25
    ambient_occlusion: float = 0.0
    # glass
    side_glass: bool = False
    back_glass: bool = True
    # many clubs' glass back walls carry no painted out line (or one too faint to show)
    back_wall_lines: bool = True
    glass_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    glass_transmit: float = 0.9
    glass_reflect_side: float = 0.0
    glass_reflect_back: float = 0.0
    glass_haze: float = 0.045
    side_joint_spacing_m: float = 0.0
    back_joints: tuple[float, ...] = ()
    fin_depth_m: float = 0.0
    clamp_size_m: tuple[float, float] = (0.0, 0.0)
    clamp_heights_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    door: tuple[float, float] = (0.0, 0.0)
    door_post_m: float = 0.0
    top_rail_m: float = 0.0
    corner_post_m: float = 0.0
    metal_colour: BGR = (150, 150, 150)
    # the hall: x0, x1, y0, y1, height (grown to contain the camera)
    hall: tuple[float, float, float, float, float] = (-3.0, 9.4, -2.0, 16.0, 7.0)
    hall_floor: Material = Material("carpet", (58, 60, 64), 1.0, (0.12, 0.25))
    hall_walls: Material = Material("panels", (38, 34, 30), 1.0, (2.0, 0.1, 0.0, 1.0, 0.05))
    ceiling: Material = Material("ceiling", (30, 27, 24), 1.0, (4.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    stands: tuple[bool, bool] = (False, False)  # beyond the left and the right side wall
    stand_back: bool = False  # behind the back wall (only where the camera is not)
    stand_offset_m: float = 1.0
    stand_slope: float = 0.55
    stand_span: tuple[float, float] = (-1.0, 12.0)
    crowd: Material = Material("crowd", (60, 50, 50), 0.6, (0.8, 0.85, 0.5, 0.8, 0))
    gallery: bool = False
    gallery_y: float = 12.0
    gallery_height_m: float = 2.5
    railing: bool = False
    railing_y: float = 12.0
    railing_height_m: float = 1.0  # above the gallery floor
    railing_mid_bars: int = 2
    railing_post_spacing_m: float = 1.5
    railing_bar_m: float = 0.04
    railing_colour: BGR = (40, 40, 40)
    adverts: tuple[Advert, ...] = ()
    extra_lines: tuple[tuple[float, ...], ...] = ()  # (ax, ay, az, bx, by, bz, surface id, colour)
    extra_arcs: tuple[tuple[float, ...], ...] = ()  # floor arcs (cx, cy, r, a0, a1, colour)
    players: tuple[Person, ...] = ()
    # the camera and the video chain
    exposure: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    gamma: float = 1.0
    saturation: float = 1.0
    contrast: float = 1.0
    vignetting: float = 0.0
    blur_px: float = 0.0
    sharpen: float = 0.0  # unsharp-mask strength (broadcast and phone cameras sharpen)
    bloom: float = 0.0  # glow around overexposed areas
    horizontal_softness: float = 1.0  # < 1: resampled from fewer columns (anamorphic broadcast)
    noise_sigma: float = SENSOR_NOISE_SIGMA
    jpeg_quality: int = 0  # 0: no JPEG
    # 2 x 2 supersamples in every pixel (False: only where edges and painted lines are)
    supersample_all: bool = False
    overlays: tuple[Overlay, ...] = ()
    notes: tuple[str, ...] = field(default=(), compare=False)


# ----------------------------------------------------------------------------------------------
# Scene arrays for the ray caster


class SceneArrays(NamedTuple):
    p: np.ndarray
    surf: np.ndarray
    segs: np.ndarray
    seg_lo: np.ndarray
    seg_hi: np.ndarray
    arcs: np.ndarray
    line_cols: np.ndarray
    ads: np.ndarray
    ad_lo: np.ndarray
    ad_hi: np.ndarray
    texs: np.ndarray
    tex: np.ndarray
    joints: np.ndarray


def _periodic_noise(rng: np.random.Generator, size: int, sigma_texels: float) -> np.ndarray:
    """Smooth, tileable noise (size, size) in [-1, 1]: white noise low-passed in the Fourier domain."""
    white = rng.standard_normal((size, size))
    freq = np.fft.fftfreq(size)
    gain = np.exp(-2.0 * (np.pi * sigma_texels) ** 2 * (freq[:, None] ** 2 + freq[None, :] ** 2))
    smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * gain))
    smooth /= np.abs(smooth).max()
    return smooth.astype(np.float64)


def _surface_of_edge(model: CourtModel, a: np.ndarray, b: np.ndarray) -> int:
    width, length = model.spec.width_m, model.spec.length_m
    for surface, axis, value in (
        (rc.S_FLOOR, 2, 0.0),
        (rc.S_FRONT, 1, 0.0),
        (rc.S_LEFT, 0, 0.0),
        (rc.S_RIGHT, 0, width),
        (rc.S_BACK, 1, length),
    ):
        if abs(a[axis] - value) < 1e-9 and abs(b[axis] - value) < 1e-9:
            return surface
    raise ValueError("painted edge does not lie on a court surface")


def painted_segments(model: CourtModel) -> list[tuple[float, ...]]:
    """The court's painted lines as (ax, ay, az, bx, by, bz, surface, colour slot) rows."""
    rows = []
    for name, (ia, ib) in zip(model.edge_names, model.edges, strict=True):
        if name in PAINTED_EDGES:
            a, b = model.nodes[ia], model.nodes[ib]
            surface = _surface_of_edge(model, a, b)
            rows.append((*a, *b, float(surface), float(_LINE_SLOT[surface])))
    return rows


def _material_row(material: Material) -> np.ndarray:
    if material.kind not in _MATERIALS:
        raise ValueError(f"unknown material {material.kind!r}")
    row = np.zeros(rc.SURF_COLUMNS)
    row[rc.SF_B : rc.SF_R + 1] = material.colour
    row[rc.SF_LIGHT] = material.light
    row[rc.SF_KIND] = _MATERIALS[material.kind]
    params = material.params[: rc.SURF_COLUMNS - rc.SF_P0]
    row[rc.SF_P0 : rc.SF_P0 + len(params)] = params
    return row


def hall_box(style: SceneStyle, centre: np.ndarray, spec: str = "wsf") -> np.ndarray:
    """The hall (x0, x1, y0, y1, height) grown so that the camera centre is well inside it."""
    x0, x1, y0, y1, height = style.hall
    return np.array(
        [
            min(x0, centre[0] - 1.5),
            max(x1, centre[0] + 1.5),
            min(y0, centre[1] - 1.5),
            max(y1, centre[1] + 1.5),
            max(height, -centre[2] + 1.0),
        ]
    )


def build_scene(
    style: SceneStyle,
    spec: str,
    centre: np.ndarray,
    rng: np.random.Generator,
    textures: bool = True,
) -> SceneArrays:
    """Flatten a style (and the court spec's line model) into the ray caster's arrays.

    `textures=False` skips drawing the advert artwork (geometry-only uses such as visibility).
    """
    court = get_spec(spec)
    model = court_model(court)
    half = court.line_width_m / 2.0
    w, length = court.width_m, court.length_m
    p = np.zeros(rc.N_PARAMS)
    p[rc.P_HAS_COURT] = 1.0 if style.court else 0.0
    p[rc.P_W], p[rc.P_L] = w, length
    p[rc.P_HALF_LINE] = half
    if style.court:
        front_out_z = model.node("front_out_left")[2]
        back_out_z = model.node("back_out_left")[2]
        p[rc.P_FRONT_TOP] = front_out_z - half - style.front_above_out_m
        p[rc.P_SIDE_TOP_FRONT] = front_out_z - half - style.side_above_out_m[0]
        p[rc.P_SIDE_TOP_BACK] = back_out_z - half - style.side_above_out_m[1]
        p[rc.P_BACK_TOP] = back_out_z - half - style.back_above_out_m
        p[rc.P_TIN_TOP] = (
            model.node("tin_left")[2] + half
        )  # the board reaches the line's lower edge
        p[rc.P_AREA_X0 : rc.P_AREA_Y1 + 1] = (0.0, 0.0, w, length)
    else:
        x0, y0, x1, y1 = style.floor_area
        p[rc.P_AREA_X0 : rc.P_AREA_Y1 + 1] = (x0, y0, x1, y1)
    p[rc.P_SIDE_GLASS] = 1.0 if style.side_glass else 0.0
    p[rc.P_BACK_GLASS] = 1.0 if style.back_glass else 0.0
    p[rc.P_GLASS_T] = style.glass_transmit
    p[rc.P_TINT_B : rc.P_TINT_R + 1] = style.glass_tint
    p[rc.P_R0_SIDE] = style.glass_reflect_side
    p[rc.P_R0_BACK] = style.glass_reflect_back
    p[rc.P_HAZE] = style.glass_haze
    p[rc.P_SIDE_JOINT_SPACING] = style.side_joint_spacing_m
    joints = np.zeros(rc.MAX_JOINTS)
    n_joints = min(len(style.back_joints), rc.MAX_JOINTS)
    joints[:n_joints] = style.back_joints[:n_joints]
    p[rc.P_N_JOINTS] = n_joints
    p[rc.P_FIN_DEPTH] = style.fin_depth_m
    p[rc.P_CLAMP_W], p[rc.P_CLAMP_H] = style.clamp_size_m
    p[rc.P_CLAMP_Z0 : rc.P_CLAMP_Z2 + 1] = style.clamp_heights_m
    p[rc.P_DOOR_X0], p[rc.P_DOOR_X1] = style.door
    p[rc.P_DOOR_POST_W] = style.door_post_m
    p[rc.P_TOP_RAIL_H] = style.top_rail_m
    p[rc.P_CORNER_POST_W] = style.corner_post_m
    p[rc.P_METAL_B : rc.P_METAL_R + 1] = style.metal_colour
    p[rc.P_TIN_B : rc.P_TIN_R + 1] = style.tin_colour
    hx0, hx1, hy0, hy1, hh = hall_box(style, centre, spec)
    p[rc.P_HALL_X0], p[rc.P_HALL_X1], p[rc.P_HALL_Y0], p[rc.P_HALL_Y1] = hx0, hx1, hy0, hy1
    p[rc.P_HALL_Z] = -hh
    p[rc.P_STAND_LEFT] = 1.0 if style.stands[0] else 0.0
    p[rc.P_STAND_RIGHT] = 1.0 if style.stands[1] else 0.0
    p[rc.P_STAND_BACK] = 1.0 if style.stand_back else 0.0
    p[rc.P_STAND_OFFSET] = style.stand_offset_m
    p[rc.P_STAND_TAN] = style.stand_slope
    p[rc.P_STAND_Y0], p[rc.P_STAND_Y1] = style.stand_span
    p[rc.P_GALLERY] = 1.0 if style.gallery else 0.0
    p[rc.P_GALLERY_Y] = style.gallery_y
    p[rc.P_GALLERY_Z] = -style.gallery_height_m
    p[rc.P_RAILING] = 1.0 if style.railing else 0.0
    p[rc.P_RAIL_Y] = style.railing_y
    floor_z = -style.gallery_height_m if style.gallery else 0.0
    p[rc.P_RAIL_TOP] = floor_z - style.railing_height_m
    p[rc.P_RAIL_N_MID] = style.railing_mid_bars
    p[rc.P_RAIL_POST_SPACING] = style.railing_post_spacing_m
    p[rc.P_RAIL_BAR] = style.railing_bar_m
    p[rc.P_RAIL_X0], p[rc.P_RAIL_X1] = hx0, hx1
    p[rc.P_LINE_ALPHA] = style.line_alpha
    p[rc.P_LINE_WEAR] = style.line_wear
    p[rc.P_GLOW] = style.line_glow
    p[rc.P_GLOW_W] = style.line_glow_width_m
    p[rc.P_FLOOR_GLOSS] = style.floor_gloss
    p[rc.P_AO] = style.ambient_occlusion
    p[rc.P_SEED] = float(rng.integers(1 << 30))
    p[rc.P_PLAYER_BOX_TOP] = -2.4
    crowd = style.crowd.params + (0.0,) * 5
    p[rc.P_CROWD_DENSITY], p[rc.P_ROW_DEPTH], p[rc.P_SEAT_W] = crowd[0], crowd[1], crowd[2]
    p[rc.P_CROWD_SEED] = crowd[4]

    surf = np.zeros((rc.N_SURFACES, rc.SURF_COLUMNS))
    materials = {
        rc.S_FLOOR: style.floor,
        rc.S_FRONT: style.front,
        rc.S_LEFT: style.left,
        rc.S_RIGHT: style.right,
        rc.S_BACK: style.back,
        rc.S_HALL_FLOOR: style.hall_floor,
        rc.S_HALL_LEFT: style.hall_walls,
        rc.S_HALL_RIGHT: Material(
            style.hall_walls.kind,
            style.hall_walls.colour,
            style.hall_walls.light * 0.9,
            style.hall_walls.params,
        ),
        rc.S_HALL_FRONT: style.hall_walls,
        rc.S_HALL_BACK: style.hall_walls,
        rc.S_CEILING: style.ceiling,
        rc.S_STAND_LEFT: style.crowd,
        rc.S_STAND_RIGHT: style.crowd,
        rc.S_STAND_BACK: style.crowd,
        rc.S_GALLERY: style.hall_floor,
        rc.S_RAILING: Material("metal", style.railing_colour, 1.0, (0.1,)),
        rc.S_FIN: Material("metal", style.metal_colour, 1.0, (0.1,)),
    }
    for surface, material in materials.items():
        surf[surface] = _material_row(material)

    # painted lines, sorted by surface
    rows = painted_segments(model) if style.court else []
    if not style.back_wall_lines:
        rows = [row for row in rows if int(row[6]) != rc.S_BACK]
    rows += [tuple(float(v) for v in line) for line in style.extra_lines]
    segs = np.array(rows, dtype=np.float64).reshape(-1, 8)
    segs = segs[np.argsort(segs[:, 6], kind="stable")]
    seg_lo = np.searchsorted(segs[:, 6], np.arange(rc.N_SURFACES), side="left").astype(np.int64)
    seg_hi = np.searchsorted(segs[:, 6], np.arange(rc.N_SURFACES), side="right").astype(np.int64)
    arcs = np.array(style.extra_arcs, dtype=np.float64).reshape(-1, 6)
    line_cols = np.array(style.line_colours, dtype=np.float64).reshape(-1, 3)
    if line_cols.shape[0] < N_COURT_LINE_COLOURS:
        line_cols = np.vstack([line_cols] + [line_cols[-1:]] * (4 - line_cols.shape[0]))
    n_colours = line_cols.shape[0]
    if len(segs) and segs[:, 7].max() >= n_colours or len(arcs) and arcs[:, 5].max() >= n_colours:
        raise ValueError("a painted line refers to a colour the style does not define")

    # adverts, sorted by surface, with their textures
    ad_rows = []
    art: list[np.ndarray] = []
    for k, advert in enumerate(style.adverts):
        if advert.surface not in rc.SURFACE_IDS:
            raise ValueError(f"unknown advert surface {advert.surface!r}")
        a0, a1, b0, b1 = advert.rect
        if not (a1 > a0 and b1 > b0):
            raise ValueError(f"advert rectangle must have a0 < a1 and b0 < b1, got {advert.rect}")
        if textures:
            art.append(
                scene_art.advert_texture(
                    advert.kind, advert.text, advert.colours, (a1 - a0) / (b1 - b0), advert.seed
                )
            )
        ad_rows.append(
            (
                float(rc.SURFACE_IDS[advert.surface]),
                a0,
                a1,
                b0,
                b1,
                float(k),
                advert.opacity,
                1.0 if advert.mirrored else 0.0,
                advert.emissive,
            )
        )
    ads = np.array(ad_rows, dtype=np.float64).reshape(-1, 9)
    order = np.argsort(ads[:, 0], kind="stable")
    ads = ads[order]
    ad_lo = np.searchsorted(ads[:, 0], np.arange(rc.N_SURFACES), side="left").astype(np.int64)
    ad_hi = np.searchsorted(ads[:, 0], np.arange(rc.N_SURFACES), side="right").astype(np.int64)
    texs = np.stack(art) if art else np.zeros((1, 2, 2, 4), np.uint8)
    tex = _periodic_noise(rng, TEXTURE_SIZE, 2.0)
    return SceneArrays(
        p,
        surf,
        np.ascontiguousarray(segs),
        seg_lo,
        seg_hi,
        np.ascontiguousarray(arcs),
        line_cols,
        np.ascontiguousarray(ads),
        ad_lo,
        ad_hi,
        texs,
        tex,
        joints,
    )


# ----------------------------------------------------------------------------------------------
# Rendering


class SceneLayers(NamedTuple):
    """A ray-cast render before players, optics and graphics (float32, 0..255-ish)."""

    colour: np.ndarray  # (H, W, 3) BGR
    front_acc: np.ndarray  # (H, W, 3) light from what lies between camera and court volume
    front_trans: np.ndarray  # (H, W) fraction of light from inside the court that gets through


def ray_grid(
    genome: np.ndarray, image_size: tuple[int, int], step_px: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undistorted normalised rays (x, y, ok) on a pixel grid with `step_px` spacing from
    RAY_GRID_ORIGIN_PX, one node beyond the picture on every side (rows v, columns u)."""
    width, height = image_size
    g = as_population(genome)[0]
    us = RAY_GRID_ORIGIN_PX + step_px * np.arange(int(np.ceil(width / step_px)) + 2)
    vs = RAY_GRID_ORIGIN_PX + step_px * np.arange(int(np.ceil(height / step_px)) + 2)
    grid_u, grid_v = np.meshgrid(us, vs)
    with np.errstate(all="ignore"):
        ray_x, ray_y, ray_ok = undistort_normalized(
            (grid_u - g[2]) / g[0], (grid_v - g[3]) / g[1], g[DISTORTION_GENES]
        )
    return np.ascontiguousarray(ray_x), np.ascontiguousarray(ray_y), np.ascontiguousarray(ray_ok)


def ray_grid_error_px(
    genome: np.ndarray,
    image_size: tuple[int, int],
    step_px: int,
    rays: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> float:
    """Worst distance (px) between a grid cell's centre and where the camera model projects the
    ray the renderer interpolates there (the mean of the cell's four corner rays); 0 when no
    cell has four valid corners. Cell centres are where bilinear interpolation strays most."""
    width, height = image_size
    ray_x, ray_y, ray_ok = rays
    ok = ray_ok[:-1, :-1] & ray_ok[1:, :-1] & ray_ok[:-1, 1:] & ray_ok[1:, 1:]
    rows, cols = ok.shape
    centre_u = RAY_GRID_ORIGIN_PX + step_px * (np.arange(cols) + 0.5)
    centre_v = RAY_GRID_ORIGIN_PX + step_px * (np.arange(rows) + 0.5)
    in_picture = (centre_v[:, None] < height) & (centre_u[None, :] < width)
    keep = ok & in_picture
    if not keep.any():
        return 0.0

    def cell_mean(a: np.ndarray) -> np.ndarray:
        return 0.25 * (a[:-1, :-1] + a[1:, :-1] + a[:-1, 1:] + a[1:, 1:])[keep]

    x, y = cell_mean(ray_x), cell_mean(ray_y)
    r, t = court_extrinsics(genome)
    r_world_from_cam = r[0].T
    centre = -r_world_from_cam @ t[0]
    # a point along each interpolated ray, projected by the one projection kernel
    points = centre + np.stack([x, y, np.ones_like(x)], axis=1) @ r_world_from_cam.T
    pixels, _ = project_points(genome, points)
    grid_u, grid_v = np.meshgrid(centre_u, centre_v)
    return float(np.hypot(pixels[:, 0] - grid_u[keep], pixels[:, 1] - grid_v[keep]).max())


def camera_rays(
    genome: np.ndarray, image_size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray, np.ndarray]:
    """The renderer's rays: (x, y, ok) on the coarsest RAY_GRID_STEPS_PX grid that follows the
    lens within RAY_GRID_MAX_ERROR_PX, that grid's step, world-from-camera rotation, centre."""
    for step_px in RAY_GRID_STEPS_PX:
        rays = ray_grid(genome, image_size, step_px)
        if ray_grid_error_px(genome, image_size, step_px, rays) <= RAY_GRID_MAX_ERROR_PX:
            break
    r, t = court_extrinsics(genome)
    r_world_from_cam = np.ascontiguousarray(r[0].T)
    centre = -r_world_from_cam @ t[0]
    return (*rays, step_px, r_world_from_cam, centre)


def camera_centre(genome: np.ndarray) -> np.ndarray:
    """The camera centre in the court frame (3,)."""
    r, t = court_extrinsics(genome)
    return -r[0].T @ t[0]


def render_layers(
    genome: np.ndarray,
    image_size: tuple[int, int],
    spec: str,
    style: SceneStyle,
    rng: np.random.Generator,
) -> SceneLayers:
    """Ray-cast the style's scene through the camera: colour and the layers players need."""
    width, height = check_image_size(image_size)
    ray_x, ray_y, ray_ok, step_px, r_world_from_cam, centre = camera_rays(genome, (width, height))
    arrays = build_scene(style, spec, centre, rng)
    colour = np.zeros((height, width, 3), np.float32)
    front_acc = np.zeros((height, width, 3), np.float32)
    front_trans = np.zeros((height, width), np.float32)
    g = as_population(genome)[0]
    rc.render_kernel(
        ray_x,
        ray_y,
        ray_ok,
        RAY_GRID_ORIGIN_PX,
        float(step_px),
        SUPERSAMPLING,
        r_world_from_cam,
        centre,
        tuple(arrays),
        2.0 / (g[0] + g[1]),
        style.supersample_all,
        colour,
        front_acc,
        front_trans,
        np.empty((height, width), np.float64),
        np.empty((height, width), np.float64),
        np.empty((height, width, 3), np.float32),
    )
    return SceneLayers(colour, front_acc, front_trans)


def visible_points(
    genome: np.ndarray, spec: str, style: SceneStyle, points: np.ndarray, tolerance_m: float = 0.02
) -> np.ndarray:
    """(M,) True where a court point (M, 3) has a clear line of sight from the camera (walls,
    railings and glass fittings block it; glass panes do not). Image bounds are not checked."""
    centre = camera_centre(genome)
    arrays = build_scene(style, spec, centre, np.random.default_rng(0), textures=False)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return rc.visible_from(arrays.p, arrays.joints, centre, pts, tolerance_m)


# ----------------------------------------------------------------------------------------------
# Players


def _composite(
    image: np.ndarray,
    layers: SceneLayers,
    lo: np.ndarray,
    colour: np.ndarray,
    alpha: np.ndarray,
) -> None:
    """Blend a figure (colour (h, w, 3), alpha (h, w)) at pixel offset lo behind the front layers."""
    h, w = alpha.shape
    rows = slice(lo[1], lo[1] + h)
    cols = slice(lo[0], lo[0] + w)
    seen = layers.front_acc[rows, cols] + layers.front_trans[rows, cols, None] * colour
    a = alpha[:, :, None]
    image[rows, cols] = image[rows, cols] * (1.0 - a) + a * seen


def _roi(
    points: np.ndarray, pad: float, shape: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray] | None:
    lo = np.floor(points.min(axis=0) - pad).astype(int)
    hi = np.ceil(points.max(axis=0) + pad).astype(int) + 1
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [shape[1], shape[0]])
    if np.any(hi <= lo):
        return None
    return lo, hi


def draw_person(
    image: np.ndarray,
    layers: SceneLayers | None,
    genome: np.ndarray,
    person: Person,
    floor_gloss: float = 0.0,
) -> None:
    """Draw a player (soft shadow, legs, shoes, shorts, shirt, arms, racket, head) in place on a
    float32 BGR image. With `layers`, the figure is seen through whatever lies in front of the court
    (glass tint, railings, fittings); without, it is painted over the image. A glossy floor
    (`floor_gloss` > 0) mirrors the figure upside down under its feet."""
    g = as_population(genome)[0]
    xy = np.array([person.x, person.y])
    foot = floor_to_pixel(g, xy)[0]
    head_top = floor_to_pixel(g, xy, plane_z_m=-person.height_m)[0]
    if not (np.all(np.isfinite(foot)) and np.all(np.isfinite(head_top))):
        return
    up = head_top - foot
    height_px = float(np.hypot(*up))
    if height_px < 4 or height_px > 4 * max(image.shape[:2]):
        return
    side = np.array([-up[1], up[0]]) / height_px  # unit vector to the figure's right in the image
    h = height_px
    if layers is None:
        layers = SceneLayers(
            image,
            np.zeros_like(image),
            np.ones(image.shape[:2], np.float32),
        )

    # shadow: an ellipse on the floor under the player, blurred, darkening what is behind the front
    around = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = xy + np.stack([0.45 * np.cos(around), 0.3 * np.sin(around) + 0.1], axis=1)
    ring_px = floor_to_pixel(g, ring)
    if np.all(np.isfinite(ring_px)):
        box = _roi(ring_px, 0.2 * h + 4, image.shape)
        if box is not None:
            lo, hi = box
            mask = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.float32)
            cv2.fillPoly(
                mask, [np.round((ring_px - lo) * 16).astype(np.int32)], 1.0, cv2.LINE_AA, 4
            )
            blur = max(1, int(h * 0.04)) * 2 + 1
            mask = cv2.GaussianBlur(mask, (blur, blur), 0) * 0.45
            rows, cols = slice(lo[1], hi[1]), slice(lo[0], hi[0])
            behind = image[rows, cols] - layers.front_acc[rows, cols]
            image[rows, cols] -= mask[:, :, None] * behind

    if floor_gloss > 0.02:
        mirrored = floor_to_pixel(g, xy, plane_z_m=person.height_m)[0]
        if np.all(np.isfinite(mirrored)):
            _figure(
                image, layers, foot, mirrored - foot, side, h, person, min(0.6, 1.5 * floor_gloss)
            )
    _figure(image, layers, foot, up, side, h, person, 1.0)


def _figure(
    image: np.ndarray,
    layers: SceneLayers,
    foot: np.ndarray,
    up: np.ndarray,
    side: np.ndarray,
    h: float,
    person: Person,
    opacity: float,
) -> None:
    """The body of `draw_person`: `up` runs from the feet to the top of the head (pixels), `side`
    is the unit vector to the figure's right, `h` its height in pixels."""

    def at(fraction_up: float, fraction_side: float = 0.0) -> np.ndarray:
        return foot + up * fraction_up + side * h * fraction_side

    lean = person.lean
    stride = person.stride
    hip = at(0.5, lean * 0.5)
    feet = (at(0.02, -0.5 * stride), at(0.02, 0.5 * stride))
    knees = (at(0.27, -0.32 * stride + lean * 0.2), at(0.27, 0.32 * stride + lean * 0.2))
    shoulder_c = at(0.8, lean)
    shoulders = (at(0.8, lean - 0.11), at(0.8, lean + 0.11))
    raise_ = person.arm
    hand_r = at(0.55 + 0.45 * raise_, lean + 0.25 + 0.1 * (1 - raise_))
    hand_l = at(0.5, lean - 0.18)
    racket_tip = hand_r + (hand_r - shoulders[1]) * 0.5 + up * 0.04
    head_c = at(0.925, lean * 1.1)
    all_points = np.array([*feet, *knees, hip, *shoulders, hand_r, hand_l, racket_tip, head_c])
    box = _roi(all_points, 0.12 * h + 3, image.shape)
    if box is None:
        return
    lo, hi = box
    shape = (hi[1] - lo[1], hi[0] - lo[0])
    colour = np.zeros((*shape, 3), np.float32)
    alpha = np.zeros(shape, np.float32)

    def pt(v: np.ndarray) -> tuple[int, int]:
        q = (v - lo) * 16
        return int(round(q[0])), int(round(q[1]))

    def limb(a: np.ndarray, b: np.ndarray, width: float, bgr: BGR) -> None:
        t = max(1, int(round(width * h)))
        cv2.line(colour, pt(a), pt(b), tuple(float(c) for c in bgr), t, cv2.LINE_AA, 4)
        cv2.line(alpha, pt(a), pt(b), 1.0, t, cv2.LINE_AA, 4)

    def tapered(a: np.ndarray, b: np.ndarray, wa: float, wb: float, bgr: BGR) -> None:
        """A limb from a (width wa * h) to b (width wb * h) with rounded ends."""
        d = b - a
        n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-6)
        quad = [a + n * wa * h / 2, b + n * wb * h / 2, b - n * wb * h / 2, a - n * wa * h / 2]
        poly(quad, bgr)
        for centre, w in ((a, wa), (b, wb)):
            radius = max(1, int(round(w * h * 8)))
            cv2.circle(colour, pt(centre), radius, tuple(float(c) for c in bgr), -1, cv2.LINE_AA, 4)
            cv2.circle(alpha, pt(centre), radius, 1.0, -1, cv2.LINE_AA, 4)

    def poly(points: list[np.ndarray], bgr: BGR) -> None:
        arr = np.array([pt(v) for v in points], np.int32)
        cv2.fillPoly(colour, [arr], tuple(float(c) for c in bgr), cv2.LINE_AA, 4)
        cv2.fillPoly(alpha, [arr], 1.0, cv2.LINE_AA, 4)

    skin = person.skin
    hips = (at(0.48, lean * 0.5 - 0.055), at(0.48, lean * 0.5 + 0.055))
    for foot_px, knee, hip_px in zip(feet, knees, hips, strict=True):
        tapered(foot_px + up * 0.03, knee, 0.04, 0.055, skin)
        tapered(knee, hip_px, 0.058, 0.085, skin)
        tapered(foot_px, foot_px + up * 0.025 + side * h * 0.035, 0.05, 0.045, person.shoes)
    # racket: handle and head
    limb(hand_r, racket_tip, 0.012, (30, 30, 30))
    head_r = racket_tip + (racket_tip - hand_r) * 0.25
    cv2.ellipse(
        colour,
        pt(head_r),
        (max(1, int(0.045 * h * 16)), max(1, int(0.03 * h * 16))),
        float(np.degrees(np.arctan2(*(racket_tip - hand_r)[::-1]))),
        0,
        360,
        (40.0, 40.0, 40.0),
        max(1, int(0.012 * h)),
        cv2.LINE_AA,
        4,
    )
    cv2.ellipse(
        alpha,
        pt(head_r),
        (max(1, int(0.045 * h * 16)), max(1, int(0.03 * h * 16))),
        float(np.degrees(np.arctan2(*(racket_tip - hand_r)[::-1]))),
        0,
        360,
        1.0,
        max(1, int(0.012 * h)),
        cv2.LINE_AA,
        4,
    )
    poly(
        [
            at(0.42, lean * 0.4 - 0.1),
            at(0.42, lean * 0.4 + 0.1),
            at(0.56, lean * 0.55 + 0.11),
            at(0.56, lean * 0.55 - 0.11),
        ],
        person.shorts,
    )
    poly(
        [at(0.54, lean * 0.55 - 0.1), at(0.54, lean * 0.55 + 0.1), shoulders[1], shoulders[0]],
        person.shirt,
    )
    for shoulder, hand in ((shoulders[0], hand_l), (shoulders[1], hand_r)):
        elbow = shoulder + (hand - shoulder) * 0.5 - up * 0.03
        tapered(shoulder, elbow, 0.05, 0.04, skin)
        tapered(elbow, hand, 0.04, 0.03, skin)
        tapered(shoulder, shoulder + (elbow - shoulder) * 0.6, 0.065, 0.055, person.shirt)
    tapered(shoulder_c, head_c, 0.045, 0.04, skin)
    radius = max(1, int(round(0.065 * h * 16)))
    cv2.circle(colour, pt(head_c), radius, tuple(float(c) for c in skin), -1, cv2.LINE_AA, 4)
    cv2.circle(alpha, pt(head_c), radius, 1.0, -1, cv2.LINE_AA, 4)
    hair = (25.0, 30.0, 40.0)
    cv2.ellipse(
        colour,
        pt(head_c + up * 0.015),
        (radius, int(radius * 0.8)),
        float(np.degrees(np.arctan2(side[1], side[0]))),
        180,
        360,
        hair,
        -1,
        cv2.LINE_AA,
        4,
    )
    # light from one side and from above: rounder bodies than flat paint
    rows = np.arange(shape[0], dtype=np.float32)[:, None] + lo[1] - foot[1]
    cols = np.arange(shape[1], dtype=np.float32)[None, :] + lo[0] - foot[0]
    across = (cols * side[0] + rows * side[1]) / (0.25 * h) - person.lean * 4.0
    height_frac = (cols * up[0] + rows * up[1]) / (h * h)  # 0 at the feet, 1 at the head
    shade = (0.82 + 0.28 * np.clip(0.5 + 0.5 * across, 0.0, 1.0)) * (
        0.9 + 0.15 * np.clip(height_frac, 0.0, 1.0)
    )
    colour *= shade[:, :, None].astype(np.float32)
    _composite(image, layers, lo, colour, opacity * np.clip(alpha, 0.0, 1.0))


def draw_people(
    image: np.ndarray,
    layers: SceneLayers | None,
    genome: np.ndarray,
    people: Sequence[Person],
    floor_gloss: float = 0.0,
) -> None:
    """Players in painter's order (furthest from the camera first)."""
    if not people:
        return
    g = as_population(genome)[0]
    feet = np.array([[q.x, q.y, 0.0] for q in people])
    _, depth = project_points(g, feet)
    for k in np.argsort(-depth):
        draw_person(image, layers, g, people[int(k)], floor_gloss)


# ----------------------------------------------------------------------------------------------
# The camera, the video chain and burned-in graphics


def apply_camera(image: np.ndarray, style: SceneStyle, rng: np.random.Generator) -> np.ndarray:
    """Exposure, white balance, vignetting, tone curve, contrast, saturation, bloom, blur,
    sharpening, anamorphic softness and sensor noise:
    float32 BGR (H, W, 3) linear-ish light in, uint8 BGR out."""
    out = image * (style.exposure * np.asarray(style.white_balance, np.float32))
    height, width = out.shape[:2]
    if style.vignetting > 0.0:
        xx = ((np.arange(width, dtype=np.float32) - width / 2) ** 2)[None, :]
        yy = ((np.arange(height, dtype=np.float32) - height / 2) ** 2)[:, None]
        r2 = (xx + yy) / ((width / 2) ** 2 + (height / 2) ** 2)
        out *= (1.0 - style.vignetting * r2)[:, :, None]
    out = np.clip(out, 0.0, None)
    if style.gamma != 1.0:
        out = 255.0 * (out / 255.0) ** style.gamma
    if style.contrast != 1.0:
        out = 128.0 + style.contrast * (out - 128.0)
    if style.saturation != 1.0:
        grey = out.mean(axis=2, keepdims=True)
        out = grey + style.saturation * (out - grey)
    if style.horizontal_softness < 1.0:
        narrow = max(2, int(round(width * style.horizontal_softness)))
        out = cv2.resize(
            cv2.resize(out, (narrow, height), interpolation=cv2.INTER_AREA),
            (width, height),
            interpolation=cv2.INTER_LINEAR,
        )
    if style.bloom > 0.0:
        # bright lights and white walls bleed into their surroundings
        glow = cv2.GaussianBlur(np.clip(out - 220.0, 0.0, None), (0, 0), 0.006 * max(height, width))
        out = out + style.bloom * glow
    if style.blur_px > 0.0:
        out = cv2.GaussianBlur(out, (0, 0), style.blur_px)
    if style.sharpen > 0.0:
        # the camera's own sharpening: thin halos along edges
        out = out + style.sharpen * (out - cv2.GaussianBlur(out, (0, 0), 1.2))
    if style.noise_sigma > 0.0:
        # shot-like noise: stronger in bright areas, partly shared by the channels
        grey = rng.standard_normal((height, width, 1), dtype=np.float32)
        colour = rng.standard_normal(out.shape, dtype=np.float32)
        scale = style.noise_sigma * np.sqrt(0.3 + 0.7 * np.clip(out, 0.0, 255.0) / 128.0)
        out = out + scale * (0.6 * grey + 0.5 * colour)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def apply_overlays(image: np.ndarray, overlays: Sequence[Overlay]) -> None:
    """Burn the style's graphics into a uint8 BGR image, in place."""
    for overlay in overlays:
        scene_art.draw_overlay(
            image,
            overlay.kind,
            overlay.rect,
            overlay.text,
            overlay.colours,
            overlay.alpha,
            overlay.seed,
        )


def apply_jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    if quality <= 0:
        return image
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR) if ok else None
    if decoded is None:
        raise RuntimeError("JPEG round trip failed")
    return np.asarray(decoded)


def finish_frame(
    layers: SceneLayers,
    genome: np.ndarray,
    style: SceneStyle,
    rng: np.random.Generator,
    people: Sequence[Person] | None = None,
) -> np.ndarray:
    """One output frame from ray-cast layers: players (the style's unless given), camera, graphics,
    JPEG. The layers are not modified, so a clip renders the scene once and finishes every frame."""
    image = layers.colour.copy()
    draw_people(
        image, layers, genome, style.players if people is None else people, style.floor_gloss
    )
    out = apply_camera(image, style, rng)
    apply_overlays(out, style.overlays)
    return apply_jpeg(out, style.jpeg_quality)


def render_scene(
    genome: np.ndarray,
    image_size: tuple[int, int],
    spec: str,
    style: SceneStyle,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """A BGR uint8 (H, W, 3) render of the style's scene seen by `genome` (see the module doc).

    `rng` seeds the surface noise, the hashing of planks and crowd, and the sensor noise; None
    means seed 0. Same inputs, same image, bit for bit.
    """
    rng = np.random.default_rng(0 if rng is None else rng)
    layers = render_layers(genome, image_size, spec, style, rng)
    return finish_frame(layers, genome, style, rng)


# ----------------------------------------------------------------------------------------------
# The plain club court of the earlier renderer

# the earlier renderer's open surroundings: a hall so large its walls sit near the horizon
CLASSIC_STYLE = SceneStyle(
    supersample_all=True,
    hall=(-60.0, 66.4, -60.0, 70.0, 40.0),
    hall_walls=Material("panels", (38, 34, 30), 1.0, (2.0, 0.0, 0.0, 1.0, 0.05)),
    ceiling=Material("ceiling", (24, 22, 20), 1.0, (4.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
)


def render_court_image(
    genome: np.ndarray,
    image_size: tuple[int, int],
    spec: str = "wsf",
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """A realistic BGR uint8 (H, W, 3) image of an empty club court seen by `genome`.

    `render_scene` with `CLASSIC_STYLE`: a maple floor, off-white plaster walls, the tin board, red
    50 mm lines centred on the model's line centres, a glass back wall with its out line, a dark
    hall outside; plus mild sensor noise. `rng` seeds the textures and the noise; None means seed
    0, so renders are reproducible by default.
    """
    size = check_image_size(image_size)
    return render_scene(genome, size, spec, CLASSIC_STYLE, rng)


# ----------------------------------------------------------------------------------------------
# Clips with moving players

_SHIRT_COLOURS = np.array(
    [[120, 40, 20], [30, 30, 160], [40, 110, 30], [25, 25, 25], [20, 140, 200], [110, 30, 110]],
    dtype=np.float64,
)
_SKIN_COLOURS = np.array([[140, 170, 215], [80, 105, 150], [105, 135, 185]], dtype=np.float64)


def player_paths(
    n_frames: int, n_players: int, rng: np.random.Generator, spec: str = "wsf"
) -> np.ndarray:
    """Floor positions (n_frames, n_players, 2) in metres: smooth loops around the T over the clip.

    Each player runs a figure-of-eight (Lissajous) loop through the T area, crossing the short line,
    the half-court line and the service boxes; players start half a loop apart, so they rarely
    overlap and every floor pixel they cover is free for most of the clip.
    """
    if n_frames < 1 or n_players < 0:
        raise ValueError("n_frames must be >= 1 and n_players >= 0")
    court = get_spec(spec)
    model = court_model(court)
    t_x, t_y = model.node("T")[:2]
    phase = np.arange(n_frames)[:, None] / n_frames
    player_phase = (np.arange(n_players) / max(n_players, 1))[None, :] + rng.uniform(0, 1)
    amp_x = rng.uniform(1.6, 2.2, n_players)[None, :]
    amp_y = rng.uniform(1.6, 2.4, n_players)[None, :]
    twist = rng.uniform(0, 2 * np.pi, n_players)[None, :]
    angle = 2 * np.pi * (phase + player_phase)
    x = t_x + amp_x * np.sin(angle)
    y = t_y + 0.4 + amp_y * np.sin(2 * angle + twist)
    margin = 0.4
    x = np.clip(x, margin, court.width_m - margin)
    y = np.clip(y, margin, court.length_m - margin)
    return np.stack([x, y], axis=2)


def _draw_player(
    frame: np.ndarray,
    genome: np.ndarray,
    floor_xy: np.ndarray,
    shirt: np.ndarray,
    skin: np.ndarray,
) -> None:
    """Shadow, legs, torso and head of one player, drawn in place on a float32 BGR frame."""
    foot = floor_to_pixel(genome, floor_xy)[0]
    head_top = floor_to_pixel(genome, floor_xy, plane_z_m=-PLAYER_HEIGHT_M)[0]
    if not (np.all(np.isfinite(foot)) and np.all(np.isfinite(head_top))):
        return
    up = head_top - foot
    height_px = float(np.hypot(*up))
    if height_px < 4:
        return
    up_unit = up / height_px
    angle_deg = float(np.degrees(np.arctan2(up_unit[0], -up_unit[1])))

    # a soft shadow: an ellipse on the floor around the feet, projected, blurred, multiplied in
    around = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = floor_xy + np.stack([0.4 * np.cos(around), 0.25 * np.sin(around) + 0.1], axis=1)
    ring_px = floor_to_pixel(genome, ring)
    if np.all(np.isfinite(ring_px)):
        pad = int(height_px * 0.2) + 4
        lo = np.floor(ring_px.min(axis=0)).astype(int) - pad
        hi = np.ceil(ring_px.max(axis=0)).astype(int) + pad
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, [frame.shape[1], frame.shape[0]])
        if np.all(hi > lo):
            mask = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.float32)
            cv2.fillPoly(
                mask, [np.round((ring_px - lo) * 16).astype(np.int32)], 1.0, cv2.LINE_AA, 4
            )
            blur = max(1, int(height_px * 0.04)) * 2 + 1
            mask = cv2.GaussianBlur(mask, (blur, blur), 0)
            roi = frame[lo[1] : hi[1], lo[0] : hi[0]]
            roi *= 1.0 - 0.45 * mask[:, :, None]

    def at(fraction: float) -> tuple[int, int]:
        p = foot + up * fraction
        return int(round(p[0] * 16)), int(round(p[1] * 16))

    def axes(half_width: float, half_height: float) -> tuple[int, int]:
        return max(1, int(round(half_width * height_px * 16))), max(
            1, int(round(half_height * height_px * 16))
        )

    legs = tuple(float(c) for c in 0.55 * skin)
    torso = tuple(float(c) for c in shirt)
    face = tuple(float(c) for c in skin)
    cv2.ellipse(frame, at(0.25), axes(0.1, 0.25), angle_deg, 0, 360, legs, -1, cv2.LINE_AA, 4)
    cv2.ellipse(frame, at(0.62), axes(0.14, 0.2), angle_deg, 0, 360, torso, -1, cv2.LINE_AA, 4)
    radius = max(1, int(round(0.065 * height_px * 16)))
    cv2.circle(frame, at(0.925), radius, face, -1, cv2.LINE_AA, 4)


def render_clip_frames(
    genome: np.ndarray,
    image_size: tuple[int, int],
    n_frames: int,
    rng: np.random.Generator | int | None,
    n_players: int = 2,
    spec: str = "wsf",
) -> list[np.ndarray]:
    """Frames (BGR uint8) of the court of `render_court_image` with players moving over the floor.

    The court is rendered once (consuming `rng` first, exactly as `render_court_image(genome,
    image_size, spec, rng)` would), then `player_paths(n_frames, n_players, rng, spec)` draws the
    paths, then the players' colours are drawn. Players are composited far to near, each sized by
    projecting a 1.8 m person standing at their floor position. Pixels no player (or shadow) touches
    are identical to the court render in every frame.
    """
    size = check_image_size(image_size)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    rng = np.random.default_rng(rng)
    court = render_court_image(genome, size, spec, rng)
    paths = player_paths(n_frames, n_players, rng, spec)
    shirts = _SHIRT_COLOURS[rng.choice(len(_SHIRT_COLOURS), n_players, replace=n_players > 6)]
    skins = _SKIN_COLOURS[rng.integers(len(_SKIN_COLOURS), size=n_players)]
    g = as_population(genome)[0]
    court_float = court.astype(np.float32)
    frames = []
    for positions in paths:
        frame = court_float.copy()
        # painter's order: the player furthest from the camera first
        feet = np.column_stack([positions, np.zeros(n_players)])
        _, depth = project_points(g, feet)
        for p in np.argsort(-depth):
            _draw_player(frame, g, positions[p], shirts[p], skins[p])
        frames.append(np.clip(np.rint(frame), 0, 255).astype(np.uint8))
    return frames


def write_video(frames: Sequence[np.ndarray], path: str | Path, fps: float = 25.0) -> None:
    """Write BGR frames of one size to a video file (MPEG-4 part 2, 'mp4v', in .mp4 or .avi)."""
    if len(frames) == 0:
        raise ValueError("no frames to write")
    height, width = frames[0].shape[:2]
    fourcc = cv2.VideoWriter.fourcc(*"mp4v")
    writer = cv2.VideoWriter(str(path), fourcc, float(fps), (width, height))
    if not writer.isOpened():
        raise RuntimeError(f"cannot open a video writer for {path}")
    try:
        for frame in frames:
            if frame.shape[:2] != (height, width) or frame.ndim != 3:
                raise ValueError("all frames must be BGR images of the same size")
            writer.write(np.ascontiguousarray(frame, dtype=np.uint8))
    finally:
        writer.release()
