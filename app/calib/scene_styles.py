"""Sampling `SceneStyle`s: what the courts users film look like, drawn from a seed.

Two families: "glass" (all-glass show courts of broadcasts: glass side and back walls that mirror
the court, coloured or wooden floors, coloured or lit lines, adverts everywhere, crowd in the
stands, a dark or lit arena) and "club" (plaster walls with red or maroon lines on maple, a glass
back wall with its frame, fins, clamps and door, a lit hall above). The camera-dependent parts
(gallery, railing, players, graphics, video chain) are added by the case generator.

Colours are BGR.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np

from app.calib import scene_art
from app.calib.court import court_model, get_spec
from app.calib.scene import Advert, Material, SceneStyle

PRESETS: tuple[str, ...] = ("glass", "club")

BGRf = tuple[float, float, float]
_T = TypeVar("_T")


def _jitter(
    rng: np.random.Generator, colour: tuple[float, ...], spread: float = 12.0
) -> tuple[int, int, int]:
    c = np.asarray(colour, float) * rng.uniform(0.9, 1.1) + rng.normal(0.0, spread / 3.0, 3)
    b, g, r = (int(v) for v in np.clip(np.rint(c), 0, 255))
    return b, g, r


def _pick(rng: np.random.Generator, options: Sequence[tuple[float, _T]]) -> _T:
    """One of the options, drawn with the given weights."""
    weights = np.array([w for w, _ in options], float)
    k = int(rng.choice(len(options), p=weights / weights.sum()))
    return options[k][1]


# ----------------------------------------------------------------------------------------------
# Palettes

WOOD = {
    "maple": (150.0, 196.0, 228.0),
    "honey": (105.0, 165.0, 212.0),
    "pale": (172.0, 206.0, 226.0),
    "amber": (80.0, 140.0, 196.0),
    "dark": (62.0, 86.0, 112.0),
    "greywood": (78.0, 86.0, 94.0),
}
FLAT_FLOORS = {
    "blue": (150.0, 92.0, 42.0),
    "deep_blue": (105.0, 58.0, 28.0),
    "grey": (128.0, 128.0, 124.0),
    "dark": (62.0, 62.0, 66.0),
    "green": (70.0, 110.0, 60.0),
}
LINES = {
    "red": (40.0, 42.0, 190.0),
    "bright_red": (35.0, 35.0, 225.0),
    "maroon": (45.0, 32.0, 118.0),
    "yellow": (40.0, 210.0, 232.0),
    "blue": (205.0, 120.0, 30.0),
    "navy": (95.0, 45.0, 25.0),
    "white": (236.0, 236.0, 236.0),
    "led_blue": (255.0, 205.0, 120.0),
    "black": (32.0, 32.0, 32.0),
}
FRONT_WALLS = {
    "white": (228.0, 232.0, 234.0),
    "off_white": (200.0, 214.0, 222.0),
    "grey": (176.0, 176.0, 172.0),
    "blue": (172.0, 112.0, 42.0),
    "deep_blue": (120.0, 62.0, 22.0),
    "dark_glass": (62.0, 46.0, 36.0),
    "black": (36.0, 36.0, 38.0),
}
SPONSOR_COLOURS = [
    ((255, 255, 255), (30, 30, 30), (40, 40, 200)),
    ((30, 30, 30), (255, 255, 255), (0, 170, 255)),
    ((120, 40, 10), (255, 255, 255), (0, 200, 255)),
    ((20, 20, 180), (255, 255, 255), (20, 20, 20)),
    ((40, 120, 30), (255, 255, 255), (240, 240, 240)),
    ((0, 180, 255), (30, 30, 30), (255, 255, 255)),
    ((230, 230, 230), (140, 40, 20), (30, 30, 200)),
    ((90, 20, 90), (255, 255, 255), (0, 220, 255)),
]


def _sponsor(rng: np.random.Generator) -> tuple[tuple[int, int, int], ...]:
    colours = SPONSOR_COLOURS[int(rng.integers(len(SPONSOR_COLOURS)))]
    return tuple(_jitter(rng, c, 10.0) for c in colours)


def _contrasting_line(
    rng: np.random.Generator, surface: tuple[float, ...], options: list[str]
) -> tuple[int, int, int]:
    """A line colour from `options` that stands out from a surface colour."""
    luma = float(np.dot(surface, (0.11, 0.59, 0.3)))
    best = None
    for _ in range(12):
        name = options[int(rng.integers(len(options)))]
        colour = LINES[name]
        contrast = abs(float(np.dot(colour, (0.11, 0.59, 0.3))) - luma) + 0.4 * float(
            np.abs(np.subtract(colour, surface)).max()
        )
        if contrast > 60.0:
            return _jitter(rng, colour, 8.0)
        if best is None or contrast > best[0]:
            best = (contrast, colour)
    assert best is not None
    return _jitter(rng, best[1], 8.0)


# ----------------------------------------------------------------------------------------------
# Floors and walls


def _wood_floor(rng: np.random.Generator, tones: list[tuple[float, str]]) -> Material:
    tone = str(_pick(rng, list(tones)))
    return Material(
        "planks",
        _jitter(rng, WOOD[tone]),
        1.0,
        (
            float(rng.uniform(0.05, 0.1)),  # strip width
            float(rng.uniform(0.6, 2.4)),  # strip length
            float(rng.uniform(0.06, 0.28)),  # tone spread
            float(rng.uniform(0.02, 0.08)),  # grain
            float(rng.uniform(0.05, 0.25)),  # seam darkness
            0.0 if rng.random() < 0.9 else 1.0,
            float(rng.uniform(0.0, 0.12)),  # light pool
        ),
    )


def _plaster(
    rng: np.random.Generator, colour: tuple[float, ...], light: float, scuffs: bool
) -> Material:
    return Material(
        "plaster",
        _jitter(rng, colour, 8.0),
        light,
        (
            float(rng.uniform(0.01, 0.06)),
            float(rng.uniform(0.1, 0.5)) if scuffs else 0.0,
            float(rng.uniform(0.2, 0.55)),
            float(rng.uniform(0.0, 0.12)) if scuffs else 0.0,
            float(rng.uniform(-0.15, 0.15)),
            float(rng.uniform(-0.15, 0.15)),
        ),
    )


def _hall_lit(rng: np.random.Generator) -> tuple[Material, Material]:
    walls = Material(
        "panels",
        _jitter(
            rng,
            _pick(
                rng,
                [
                    (3, (205.0, 208.0, 206.0)),
                    (1, (120.0, 150.0, 175.0)),
                    (1, (150.0, 140.0, 120.0)),
                    (1, (90.0, 90.0, 95.0)),
                ],
            ),
        ),
        float(rng.uniform(0.6, 1.0)),
        (
            float(rng.uniform(0.8, 3.0)),
            float(rng.uniform(0.0, 0.3)),
            float(rng.uniform(0.0, 1.2)),
            float(rng.uniform(0.5, 1.0)),
            0.05,
        ),
    )
    ceiling = Material(
        "ceiling",
        _jitter(
            rng,
            _pick(
                rng,
                [(3, (200.0, 200.0, 198.0)), (1, (80.0, 120.0, 160.0)), (1, (60.0, 60.0, 62.0))],
            ),
        ),
        float(rng.uniform(0.5, 0.9)),
        (
            float(rng.uniform(1.8, 4.0)),
            float(rng.uniform(1.8, 4.0)),
            float(rng.uniform(0.15, 1.2)),
            float(rng.uniform(0.15, 1.2)),
            float(rng.uniform(255.0, 330.0)),
            float(rng.uniform(1.5, 4.0)) if rng.random() < 0.5 else 0.0,
            float(rng.uniform(0.2, 0.5)),
        ),
    )
    return walls, ceiling


def _hall_dark(rng: np.random.Generator) -> tuple[Material, Material]:
    walls = Material(
        "panels",
        _jitter(rng, (40.0, 36.0, 34.0), 10.0),
        float(rng.uniform(0.5, 1.2)),
        (float(rng.uniform(1.0, 4.0)), float(rng.uniform(0.0, 0.3)), 0.0, 1.0, 0.1),
    )
    ceiling = Material(
        "ceiling",
        _jitter(rng, (22.0, 22.0, 24.0), 6.0),
        1.0,
        (
            float(rng.uniform(2.0, 5.0)),
            float(rng.uniform(2.0, 5.0)),
            float(rng.uniform(0.1, 0.5)),
            float(rng.uniform(0.1, 0.5)),
            float(rng.uniform(200.0, 300.0)) if rng.random() < 0.7 else 30.0,
            float(rng.uniform(2.0, 5.0)) if rng.random() < 0.5 else 0.0,
            0.4,
        ),
    )
    return walls, ceiling


# ----------------------------------------------------------------------------------------------
# Glass back wall: joints, fins, clamps, door


def _back_wall_glass(rng: np.random.Generator, width: float) -> dict[str, Any]:
    n_panels = int(rng.integers(3, 6))
    edges = np.linspace(0.0, width, n_panels + 1)
    edges[1:-1] += rng.uniform(-0.15, 0.15, n_panels - 1)
    joints = tuple(float(x) for x in edges[1:-1])
    door_panel = (
        int(rng.integers(0, n_panels))
        if rng.random() < 0.35
        else (n_panels - 1) // 2 + (int(rng.integers(0, 2)) if n_panels % 2 == 0 else 0)
    )
    door = (
        (float(edges[door_panel]), float(edges[door_panel + 1]))
        if rng.random() < 0.85
        else (0.0, 0.0)
    )
    if door[1] - door[0] > 1.2:
        centre = 0.5 * (door[0] + door[1])
        door = (centre - 0.45, centre + 0.45)
    fins = rng.random() < 0.65
    clamp_h = float(rng.uniform(0.05, 0.12))
    return {
        "back_joints": joints,
        "fin_depth_m": float(rng.uniform(0.2, 0.45)) if fins else 0.0,
        "clamp_size_m": (float(rng.uniform(0.05, 0.12)), clamp_h),
        "clamp_heights_m": (
            float(rng.uniform(0.15, 0.4)),
            float(rng.uniform(0.9, 1.3)) if rng.random() < 0.6 else 0.0,
            float(rng.uniform(1.7, 2.1)),
        ),
        "door": door,
        "door_post_m": float(rng.uniform(0.02, 0.06)) if rng.random() < 0.35 else 0.0,
        "top_rail_m": float(rng.uniform(0.03, 0.08)) if rng.random() < 0.45 else 0.0,
        "corner_post_m": float(rng.uniform(0.02, 0.06)) if rng.random() < 0.3 else 0.0,
        "metal_colour": _jitter(
            rng,
            _pick(
                rng,
                [(3, (165.0, 165.0, 165.0)), (1, (40.0, 40.0, 40.0)), (1, (200.0, 200.0, 200.0))],
            ),
            10.0,
        ),
    }


# ----------------------------------------------------------------------------------------------
# Adverts


def _advert(
    rng: np.random.Generator,
    surface: str,
    rect: tuple[float, float, float, float],
    kind: str,
    opacity: float = 1.0,
    emissive: float = 0.0,
    mirrored: bool = False,
    colours: tuple[tuple[int, int, int], ...] | None = None,
    text: str | None = None,
) -> Advert:
    return Advert(
        surface,
        (float(rect[0]), float(rect[1]), float(rect[2]), float(rect[3])),
        kind,
        scene_art.brand_name(rng) if text is None else text,
        _sponsor(rng) if colours is None else colours,
        float(opacity),
        float(emissive),
        mirrored,
        int(rng.integers(1 << 30)),
    )


def _wall_logos(
    rng: np.random.Generator,
    surface: str,
    length: float,
    low: float,
    high: float,
    count: int,
    kinds: list[str],
    opacity: tuple[float, float],
    mirrored: bool = False,
) -> list[Advert]:
    out = []
    for _ in range(count):
        h = float(rng.uniform(0.25, 0.9)) * min(1.0, high - low)
        w = h * float(rng.uniform(1.2, 4.0))
        if w >= length - 0.2 or high - low < h + 0.05:
            continue
        a0 = float(rng.uniform(0.1, length - w - 0.1))
        b0 = float(rng.uniform(low, high - h))
        kind = kinds[int(rng.integers(len(kinds)))]
        out.append(
            _advert(
                rng,
                surface,
                (a0, a0 + w, b0, b0 + h),
                kind,
                rng.uniform(*opacity),
                mirrored=mirrored,
            )
        )
    return out


def _tin_advert(rng: np.random.Generator, width: float, tin_top: float, led: bool) -> Advert:
    return _advert(
        rng,
        "front",
        (0.0, width, 0.0, tin_top - 0.03),
        "board" if rng.random() < 0.7 else "banner",
        1.0,
        emissive=float(rng.uniform(0.4, 0.9)) if led else 0.0,
    )


def _floor_logos(rng: np.random.Generator, width: float, length: float, count: int) -> list[Advert]:
    out = []
    short_y = length - 4.26 - 0.05
    for _ in range(count):
        w = float(rng.uniform(1.0, 2.6))
        h = w * float(rng.uniform(0.3, 0.9))
        if rng.random() < 0.6:
            # in the front court, between the front wall and the short line
            y0 = float(rng.uniform(0.6, max(0.7, short_y - h - 0.5)))
        else:
            y0 = float(rng.uniform(short_y + 1.9, max(short_y + 2.0, length - h - 0.3)))
        x0 = 0.5 * width - 0.5 * w + float(rng.uniform(-0.4, 0.4))
        out.append(
            _advert(
                rng,
                "floor",
                (x0, x0 + w, y0, y0 + h),
                str(rng.choice(["logo", "wordmark"])),
                float(rng.uniform(0.2, 0.75)),
            )
        )
    return out


def _hall_decor(
    rng: np.random.Generator, hall: tuple[float, float, float, float, float], lit: bool
) -> list[Advert]:
    x0, x1, y0, y1, height = hall
    out: list[Advert] = []
    for surface, length in (
        ("hall_left", y1 - y0),
        ("hall_right", y1 - y0),
        ("hall_front", x1 - x0),
    ):
        n = int(rng.integers(0, 7))
        base = y0 if surface != "hall_front" else x0
        for _ in range(n):
            kind = str(
                rng.choice(
                    ["flag", "banner", "poster", "window", "door"]
                    if lit
                    else ["banner", "board", "flag"]
                )
            )
            if kind == "door":
                w, h, b0 = 0.9, 2.05, 0.0
            elif kind == "window":
                w, h = float(rng.uniform(1.0, 3.0)), float(rng.uniform(0.8, 1.6))
                b0 = float(rng.uniform(1.0, max(1.1, height - h - 0.3)))
            else:
                w = float(rng.uniform(0.8, 3.0))
                h = w * float(rng.uniform(0.3, 0.7))
                b0 = float(rng.uniform(1.5, max(1.6, height - h - 0.3)))
            if w > length - 0.2:
                continue
            a0 = base + float(rng.uniform(0.1, length - w - 0.1))
            emissive = (
                0.7
                if kind == "window"
                else (float(rng.uniform(0.3, 0.8)) if kind == "board" else 0.0)
            )
            colours = ((230, 225, 215), (60, 60, 60), (120, 120, 120)) if kind == "window" else None
            out.append(
                _advert(
                    rng, surface, (a0, a0 + w, b0, b0 + h), kind, 1.0, emissive, colours=colours
                )
            )
    return out


# ----------------------------------------------------------------------------------------------
# The two families


def sample_style(
    rng: np.random.Generator | int | None, preset: str, spec: str = "wsf"
) -> SceneStyle:
    """A random style of the given family ("glass" or "club"); camera-dependent parts left default."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; expected one of {', '.join(PRESETS)}")
    rng = np.random.default_rng(rng)
    return _glass_style(rng, spec) if preset == "glass" else _club_style(rng, spec)


def _glass_style(rng: np.random.Generator, spec: str) -> SceneStyle:
    court = get_spec(spec)
    width, length = court.width_m, court.length_m
    model = court_model(court)
    tin_top = -model.node("tin_left")[2] - court.line_width_m / 2.0
    floor_kind = str(_pick(rng, [(5, "wood"), (2, "flat"), (1.2, "glass")]))
    gloss = 0.0
    glow = 0.0
    if floor_kind == "wood":
        floor = _wood_floor(
            rng,
            [
                (3, "maple"),
                (2, "honey"),
                (1, "pale"),
                (1, "amber"),
                (1.5, "dark"),
                (1.5, "greywood"),
            ],
        )
        gloss = float(rng.uniform(0.0, 0.18))
    elif floor_kind == "flat":
        tone = str(rng.choice(list(FLAT_FLOORS)))
        floor = Material(
            "flat",
            _jitter(rng, FLAT_FLOORS[tone]),
            1.0,
            (
                float(rng.uniform(0.02, 0.08)),
                float(rng.uniform(0.01, 0.04)),
                float(rng.uniform(0.0, 0.1)),
                float(rng.uniform(0.0, 1.0)),
            ),
        )
        gloss = float(rng.uniform(0.05, 0.25))
    else:
        floor = Material(
            "glass",
            _jitter(rng, (float(rng.uniform(45, 100)),) * 3, 8.0),
            1.0,
            (float(rng.uniform(0.8, 1.6)), float(rng.uniform(0.1, 0.4)), 0.04),
        )
        gloss = float(rng.uniform(0.25, 0.55))
    floor_colour = tuple(float(c) for c in floor.colour)
    if floor_kind == "glass" or rng.random() < 0.12:
        floor_line = _jitter(rng, LINES[str(rng.choice(["led_blue", "white"]))], 6.0)
        glow = float(rng.uniform(0.15, 0.6))
    else:
        floor_line = _contrasting_line(
            rng,
            floor_colour,
            ["red", "red", "yellow", "yellow", "blue", "white", "white", "bright_red", "maroon"],
        )
    front_name = str(
        _pick(
            rng,
            [
                (3, "white"),
                (1, "off_white"),
                (1, "grey"),
                (3, "blue"),
                (1.5, "deep_blue"),
                (1.5, "dark_glass"),
                (0.5, "black"),
            ],
        )
    )
    front_colour = FRONT_WALLS[front_name]
    front_line = (
        _contrasting_line(
            rng, front_colour, ["red", "bright_red", "white", "yellow", "navy", "black"]
        )
        if rng.random() < 0.6
        else floor_line
    )
    side_line = (
        _contrasting_line(
            rng, (40.0, 40.0, 40.0), ["red", "bright_red", "white", "yellow", "led_blue"]
        )
        if rng.random() < 0.5
        else floor_line
    )
    back_line = side_line if rng.random() < 0.7 else floor_line
    lit_arena = rng.random() < 0.3
    walls, ceiling = _hall_lit(rng) if lit_arena else _hall_dark(rng)
    hall = (
        -float(rng.uniform(5.0, 12.0)),
        width + float(rng.uniform(5.0, 12.0)),
        -float(rng.uniform(2.0, 8.0)),
        length + float(rng.uniform(8.0, 20.0)),
        float(rng.uniform(7.0, 14.0)),
    )
    glass_tint = _pick(
        rng,
        [
            (2.0, (float(rng.uniform(0.95, 1.02)), 1.0, float(rng.uniform(0.9, 0.99)))),
            (1.5, (1.0, float(rng.uniform(0.86, 0.95)), float(rng.uniform(0.72, 0.86)))),
            (1.0, (1.0, float(rng.uniform(0.75, 0.86)), float(rng.uniform(0.55, 0.72)))),
        ],
    )
    glass = _back_wall_glass(rng, width)
    adverts: list[Advert] = []
    front_h = 4.62 + 0.4
    adverts += _wall_logos(
        rng,
        "front",
        width,
        2.0,
        front_h - 0.1,
        int(rng.integers(0, 4)),
        ["logo", "wordmark", "wordmark", "banner"],
        (0.5, 1.0),
    )
    if rng.random() < 0.8:
        adverts.append(_tin_advert(rng, width, tin_top, led=rng.random() < 0.7))
    for side in ("left", "right"):
        adverts += _wall_logos(
            rng,
            side,
            length,
            0.2,
            2.2,
            int(rng.integers(0, 6)),
            ["logo", "wordmark", "banner"],
            (0.35, 0.85),
            mirrored=rng.random() < 0.5,
        )
    adverts += _floor_logos(rng, width, length, int(_pick(rng, [(3, 0), (3, 1), (1, 2)])))
    if rng.random() < 0.3:
        adverts += _wall_logos(
            rng, "back", width, 0.1, 1.2, int(rng.integers(1, 3)), ["wordmark", "logo"], (0.3, 0.8)
        )
    adverts += _hall_decor(rng, hall, lit_arena)
    return SceneStyle(
        preset="glass",
        floor=floor,
        floor_gloss=gloss,
        front=Material(
            "plaster",
            _jitter(rng, front_colour, 8.0),
            float(rng.uniform(0.8, 1.1)),
            (float(rng.uniform(0.0, 0.03)), 0.0, 0.0, 0.0),
        ),
        left=Material("plaster", (200, 200, 200), float(rng.uniform(0.75, 1.0))),
        right=Material("plaster", (200, 200, 200), float(rng.uniform(0.75, 1.0))),
        back=Material("plaster", (200, 200, 200), float(rng.uniform(0.8, 1.0))),
        tin_colour=_jitter(
            rng,
            _pick(rng, [(1, (235.0, 235.0, 235.0)), (1, (40.0, 40.0, 40.0)), (1, front_colour)]),
            10.0,
        ),
        line_colours=(floor_line, front_line, side_line, back_line),
        line_alpha=float(rng.uniform(0.85, 1.0)),
        line_wear=float(rng.uniform(0.0, 0.2)),
        line_glow=glow,
        line_glow_width_m=float(rng.uniform(0.02, 0.08)),
        front_above_out_m=float(rng.uniform(0.05, 0.6)),
        side_above_out_m=(float(rng.uniform(0.05, 0.4)), float(rng.uniform(0.05, 0.4))),
        back_above_out_m=float(rng.uniform(0.05, 0.3)),
        ambient_occlusion=float(rng.uniform(0.0, 0.15)),
        side_glass=True,
        back_glass=True,
        glass_tint=glass_tint,
        glass_transmit=float(rng.uniform(0.75, 0.95)),
        glass_reflect_side=float(rng.uniform(0.025, 0.08)),
        glass_reflect_back=float(rng.uniform(0.0, 0.05)),
        glass_haze=float(rng.uniform(0.01, 0.06)),
        side_joint_spacing_m=float(rng.uniform(1.2, 2.5)) if rng.random() < 0.7 else 0.0,
        hall=hall,
        hall_floor=Material(
            "carpet",
            _jitter(rng, (40.0, 38.0, 38.0), 15.0),
            float(rng.uniform(0.5, 1.0)),
            (0.1, 0.3),
        ),
        hall_walls=walls,
        ceiling=ceiling,
        stands=(rng.random() < 0.9, rng.random() < 0.9),
        stand_offset_m=float(rng.uniform(0.6, 3.0)),
        stand_slope=float(rng.uniform(0.4, 0.75)),
        stand_span=(-float(rng.uniform(0.0, 3.0)), length + float(rng.uniform(0.0, 6.0))),
        crowd=Material(
            "crowd",
            _jitter(
                rng,
                _pick(
                    rng,
                    [(3, (45.0, 42.0, 42.0)), (1, (40.0, 40.0, 140.0)), (1, (120.0, 70.0, 35.0))],
                ),
                10.0,
            ),
            float(rng.uniform(0.35, 1.0)),
            (
                float(rng.uniform(0.4, 0.97)),
                float(rng.uniform(0.75, 0.95)),
                float(rng.uniform(0.45, 0.6)),
                float(rng.uniform(0.5, 1.0)),
                float(rng.integers(1 << 20)),
            ),
        ),
        adverts=tuple(adverts),
        **glass,
    )


def _club_style(rng: np.random.Generator, spec: str) -> SceneStyle:
    court = get_spec(spec)
    width, length = court.width_m, court.length_m
    model = court_model(court)
    tin_top = -model.node("tin_left")[2] - court.line_width_m / 2.0
    floor = _wood_floor(rng, [(5, "maple"), (2, "pale"), (2, "honey"), (0.6, "amber")])
    wall_colour = _pick(
        rng,
        [
            (4, (228.0, 232.0, 234.0)),
            (2, (208.0, 218.0, 224.0)),
            (1, (220.0, 222.0, 215.0)),
            (0.4, (215.0, 205.0, 190.0)),
        ],
    )
    scuffs = rng.random() < 0.6
    line_name = str(
        _pick(
            rng,
            [
                (6, "red"),
                (2, "maroon"),
                (1, "bright_red"),
                (0.5, "navy"),
                (0.4, "black"),
                (0.4, "blue"),
            ],
        )
    )
    line = _jitter(rng, LINES[line_name], 8.0)
    front_line = line if rng.random() < 0.85 else _jitter(rng, LINES["navy"], 8.0)
    light_side = float(rng.uniform(0.78, 0.98))
    walls, ceiling = _hall_lit(rng)
    to_ceiling = rng.random() < 0.35
    hall_height = float(rng.uniform(5.6, 8.0))
    side_above = (
        (hall_height - 4.62 - 0.05, hall_height - 2.18 - 0.05)
        if to_ceiling
        else (float(rng.uniform(0.1, 1.2)), float(rng.uniform(0.1, 1.0)))
    )
    hall = (
        -float(rng.uniform(1.0, 6.0)),
        width + float(rng.uniform(1.0, 6.0)),
        -float(rng.uniform(0.5, 3.0)),
        length + float(rng.uniform(4.0, 12.0)),
        hall_height,
    )
    glass = _back_wall_glass(rng, width)
    adverts: list[Advert] = []
    if rng.random() < 0.55:
        adverts.append(_tin_advert(rng, width, tin_top, led=False))
    if rng.random() < 0.3:
        adverts.append(
            _advert(
                rng,
                "front",
                (0.1, width - 0.1, 4.72, 4.72 + float(rng.uniform(0.3, 0.5))),
                "banner",
            )
        )
    for side in ("left", "right"):
        if rng.random() < 0.45:
            adverts += _wall_logos(
                rng,
                side,
                length,
                2.6,
                4.3,
                int(rng.integers(1, 4)),
                ["banner", "poster", "text"],
                (1.0, 1.0),
            )
    adverts += _floor_logos(rng, width, length, 1 if rng.random() < 0.12 else 0)
    if rng.random() < 0.25:
        adverts.append(
            _advert(
                rng,
                "back",
                (0.0, width, 0.0, float(rng.uniform(0.25, 0.6))),
                "stripes",
                float(rng.uniform(0.4, 0.8)),
                colours=((235, 235, 235), (235, 235, 235), (235, 235, 235)),
            )
        )
    if rng.random() < 0.25:
        adverts += _wall_logos(rng, "back", width, 0.5, 1.8, 1, ["wordmark", "logo"], (0.4, 0.9))
    adverts += _hall_decor(rng, hall, True)
    tin_colour = _pick(
        rng,
        [
            (3, (225.0, 228.0, 230.0)),
            (1.5, (150.0, 150.0, 158.0)),
            (1, (50.0, 50.0, 170.0)),
            (0.5, (60.0, 60.0, 60.0)),
        ],
    )
    hall_floor = str(_pick(rng, [(2, "carpet"), (2, "tiles"), (1, "planks")]))
    if hall_floor == "tiles":
        hall_mat = Material(
            "tiles",
            _jitter(rng, (170.0, 170.0, 165.0), 30.0),
            0.85,
            (float(rng.uniform(0.3, 0.6)), 0.005, 0.3, 0.1),
        )
    elif hall_floor == "planks":
        hall_mat = _wood_floor(rng, [(1, "honey"), (1, "amber")])
    else:
        hall_mat = Material("carpet", _jitter(rng, (90.0, 85.0, 80.0), 40.0), 0.8, (0.12, 0.2))
    return SceneStyle(
        preset="club",
        floor=floor,
        floor_gloss=float(rng.uniform(0.02, 0.2)),
        front=_plaster(rng, wall_colour, float(rng.uniform(0.95, 1.08)), scuffs),
        left=_plaster(rng, wall_colour, light_side, scuffs),
        right=_plaster(rng, wall_colour, light_side * float(rng.uniform(0.88, 1.05)), scuffs),
        back=_plaster(rng, wall_colour, float(rng.uniform(0.85, 1.0)), scuffs),
        tin_colour=_jitter(rng, tin_colour, 8.0),
        line_colours=(line, front_line, line, line),
        line_alpha=float(rng.uniform(0.75, 1.0)),
        line_wear=float(rng.uniform(0.0, 0.35)),
        front_above_out_m=float(rng.uniform(0.1, 1.5))
        if not to_ceiling
        else hall_height - 4.62 - 0.05,
        side_above_out_m=side_above,
        back_above_out_m=float(rng.uniform(0.05, 0.4)),
        ambient_occlusion=float(rng.uniform(0.05, 0.3)),
        side_glass=False,
        back_glass=True,
        glass_tint=(float(rng.uniform(0.94, 1.0)), 1.0, float(rng.uniform(0.9, 0.98))),
        glass_transmit=float(rng.uniform(0.8, 0.95)),
        glass_reflect_side=0.0,
        glass_reflect_back=float(rng.uniform(0.0, 0.06)),
        glass_haze=float(rng.uniform(0.005, 0.03)),
        hall=hall,
        hall_floor=hall_mat,
        hall_walls=walls,
        ceiling=ceiling,
        adverts=tuple(adverts),
        **glass,
    )
