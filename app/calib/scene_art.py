"""2D artwork for scene renders: advert and decal textures, broadcast graphics, brand-like words.

Everything is drawn with OpenCV primitives and `cv2.putText` from a seed, so renders stay
reproducible and the repository holds no images.
"""

from __future__ import annotations

import cv2
import numpy as np

_SYLLABLES = (
    "KA",
    "RO",
    "TEC",
    "MAX",
    "LU",
    "NOR",
    "VI",
    "ZEN",
    "PRO",
    "AR",
    "ON",
    "EX",
    "TRA",
    "MED",
    "AIR",
    "CO",
    "NET",
    "GO",
    "SAN",
    "DEL",
    "TA",
    "VO",
    "RA",
    "KI",
    "MO",
    "STAR",
    "LIN",
    "QUA",
    "BAR",
    "FIN",
    "HOL",
    "TER",
    "MAR",
    "SOL",
    "VEN",
    "PAX",
    "OR",
    "IA",
    "UM",
    "EN",
)
_WORDS = (
    "SQUASH",
    "OPEN",
    "CLASSIC",
    "WORLD TOUR",
    "CHAMPIONSHIPS",
    "BANK",
    "SPORTS",
    "GROUP",
    "CAPITAL",
    "MOTORS",
    "AIRWAYS",
    "ENERGY",
    "TELECOM",
    "INSURANCE",
    "CITY",
    "CLUB",
    "LEAGUE",
    "CUP",
    "MASTERS",
    "FINALS",
    "ARENA",
    "HOTEL",
    "WATER",
    "LABS",
    "SHOES",
    "RACKETS",
)
_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_PLAIN,
)
_FIRST_NAMES = (
    "ALI",
    "MOHAMED",
    "PAUL",
    "DIEGO",
    "NOUR",
    "JOEL",
    "SARAH",
    "HANIA",
    "TOM",
    "MARWAN",
    "AMANDA",
    "NICK",
    "VICTOR",
    "LAURA",
    "RAFAEL",
    "JOSH",
    "TESNI",
    "KARIM",
    "YUKI",
    "OLIVIA",
    "SAM",
    "EMMA",
)
_LAST_NAMES = (
    "FARAG",
    "ELIAS",
    "COLL",
    "MAKIN",
    "GOHAR",
    "KHAN",
    "ROSS",
    "ASAL",
    "SOBHY",
    "WATERS",
    "HESHAM",
    "LEE",
    "ORTIZ",
    "BAKER",
    "NORTH",
    "SMITH",
    "KUMAR",
    "TANAKA",
    "JONES",
    "LOPEZ",
    "DUBOIS",
)
_COUNTRY_CODES = (
    "EGY",
    "ENG",
    "FRA",
    "NZL",
    "PER",
    "USA",
    "HKG",
    "AUS",
    "MAS",
    "COL",
    "WAL",
    "JPN",
)

TEXTURE_PX = 256


def brand_name(rng: np.random.Generator) -> str:
    """A made-up sponsor name: two or three syllables, sometimes with a word after it."""
    name = "".join(rng.choice(_SYLLABLES, size=int(rng.integers(2, 4))))
    if rng.random() < 0.35:
        name += " " + str(rng.choice(_WORDS))
    return name


def player_name(rng: np.random.Generator) -> str:
    if rng.random() < 0.5:
        return str(rng.choice(_LAST_NAMES))
    return f"{str(rng.choice(_FIRST_NAMES))[0]}. {rng.choice(_LAST_NAMES)}"


def country_code(rng: np.random.Generator) -> str:
    return str(rng.choice(_COUNTRY_CODES))


def _fit_text(
    canvas: np.ndarray,
    text: str,
    box: tuple[int, int, int, int],
    colour: tuple[float, ...],
    font: int,
    thickness_fraction: float = 0.09,
    align: str = "centre",
) -> None:
    """Write text as large as fits into box (x0, y0, x1, y1), anti-aliased."""
    x0, y0, x1, y1 = box
    width, height = max(x1 - x0, 1), max(y1 - y0, 1)
    (tw, th), _ = cv2.getTextSize(text, font, 1.0, 1)
    scale = max(min(width / max(tw, 1), height / max(th, 1)) * 0.92, 0.05)
    thickness = max(1, int(round(scale * th * thickness_fraction)))
    (tw, th), base = cv2.getTextSize(text, font, scale, thickness)
    if align == "left":
        x = x0
    elif align == "right":
        x = x1 - tw
    else:
        x = x0 + (width - tw) // 2
    y = y0 + (height + th) // 2
    cv2.putText(canvas, text, (int(x), int(y)), font, scale, colour, thickness, cv2.LINE_AA)


def advert_texture(
    kind: str,
    text: str,
    colours: tuple[tuple[int, int, int], ...],
    aspect: float,
    seed: int,
) -> np.ndarray:
    """A BGRA uint8 (TEXTURE_PX, TEXTURE_PX, 4) texture (alpha 255 = opaque).

    The artwork is drawn at the physical `aspect` (width / height) and resampled to the square
    texture, so it is undistorted once mapped back onto its rectangle.
    """
    rng = np.random.default_rng(seed)
    long_side = 512
    if aspect >= 1.0:
        w, h = long_side, max(8, int(round(long_side / aspect)))
    else:
        w, h = max(8, int(round(long_side * aspect))), long_side
    bgr = np.zeros((h, w, 3), np.uint8)
    alpha = np.zeros((h, w), np.uint8)
    background = tuple(float(c) for c in colours[0])
    foreground = tuple(float(c) for c in colours[1 % len(colours)])
    accent = tuple(float(c) for c in colours[2 % len(colours)])
    font = int(rng.choice(_FONTS))
    if kind in ("banner", "text", "board"):
        bgr[:] = background
        alpha[:] = 255
        if kind == "banner":
            # logo block on the left, a border, the name
            edge = max(2, h // 12)
            cv2.rectangle(bgr, (0, 0), (w - 1, h - 1), accent, edge)
            block = min(h, w // 4)
            cv2.rectangle(bgr, (edge, edge), (block, h - edge), accent, -1)
            cv2.circle(bgr, ((edge + block) // 2, h // 2), max(2, block // 3), foreground, -1)
            _fit_text(
                bgr,
                text,
                (block + 2 * edge, edge * 2, w - 2 * edge, h - 2 * edge),
                foreground,
                font,
            )
        elif kind == "board":
            # an LED board: repeated names with separators
            reps = max(1, int(round(aspect / 3.0)))
            step = w / reps
            for k in range(reps):
                _fit_text(
                    bgr,
                    text,
                    (
                        int(k * step + 0.05 * step),
                        int(0.15 * h),
                        int((k + 1) * step - 0.05 * step),
                        int(0.85 * h),
                    ),
                    foreground,
                    font,
                )
                cv2.line(
                    bgr, (int((k + 1) * step), 0), (int((k + 1) * step), h), accent, max(1, h // 20)
                )
        else:
            _fit_text(
                bgr,
                text,
                (int(0.05 * w), int(0.1 * h), int(0.95 * w), int(0.9 * h)),
                foreground,
                font,
            )
    elif kind == "logo":
        # a shape with the name under it, on a transparent background
        shape = int(rng.integers(4))
        cx, cy, r = w // 2, int(h * 0.38), int(min(w, h) * 0.3)
        if shape == 0:
            cv2.circle(bgr, (cx, cy), r, foreground, -1, cv2.LINE_AA)
            cv2.circle(alpha, (cx, cy), r, 255, -1, cv2.LINE_AA)
            cv2.circle(bgr, (cx, cy), int(r * 0.6), accent, -1, cv2.LINE_AA)
        elif shape == 1:
            pts = np.array([[cx, cy - r], [cx + r, cy + r], [cx - r, cy + r]], np.int32)
            cv2.fillPoly(bgr, [pts], foreground, cv2.LINE_AA)
            cv2.fillPoly(alpha, [pts], 255, cv2.LINE_AA)
        elif shape == 2:
            cv2.ellipse(bgr, (cx, cy), (r, r // 2), -20, 0, 360, foreground, -1, cv2.LINE_AA)
            cv2.ellipse(alpha, (cx, cy), (r, r // 2), -20, 0, 360, 255, -1, cv2.LINE_AA)
            cv2.ellipse(
                bgr, (cx + r // 4, cy), (r // 2, r // 5), -20, 0, 360, accent, -1, cv2.LINE_AA
            )
        else:
            thick = max(2, r // 4)
            for k in range(3):
                cv2.ellipse(
                    bgr,
                    (cx, cy + k * thick),
                    (r, r // 2),
                    0,
                    200,
                    340,
                    foreground,
                    thick,
                    cv2.LINE_AA,
                )
                cv2.ellipse(
                    alpha, (cx, cy + k * thick), (r, r // 2), 0, 200, 340, 255, thick, cv2.LINE_AA
                )
        text_layer = np.zeros((h, w), np.uint8)
        _fit_text(
            text_layer,
            text,
            (int(0.05 * w), int(0.72 * h), int(0.95 * w), int(0.97 * h)),
            (255,),
            font,
        )
        bgr[text_layer > 0] = foreground
        alpha = np.maximum(alpha, text_layer)
    elif kind == "wordmark":
        # text only, transparent background (floor and glass lettering)
        _fit_text(
            alpha,
            text,
            (int(0.03 * w), int(0.1 * h), int(0.97 * w), int(0.9 * h)),
            (255,),
            font,
            0.12,
        )
        bgr[:] = foreground
    elif kind == "flag":
        alpha[:] = 255
        n = int(rng.integers(2, 4))
        palette = [background, foreground, accent]
        vertical = rng.random() < 0.5
        for k in range(n):
            if vertical:
                bgr[:, k * w // n : (k + 1) * w // n] = palette[k % 3]
            else:
                bgr[k * h // n : (k + 1) * h // n, :] = palette[k % 3]
        if rng.random() < 0.5:
            cv2.circle(
                bgr, (w // 2, h // 2), h // 4, accent if vertical else foreground, -1, cv2.LINE_AA
            )
    elif kind == "stripes":
        # thin vertical decal stripes (the frosted bands on glass doors and walls)
        period = max(3, int(w / max(4.0, aspect * 10.0)))
        for x in range(0, w, period):
            cv2.line(alpha, (x, 0), (x, h), 255, max(1, period // 5))
        bgr[:] = foreground
    elif kind == "door":
        alpha[:] = 255
        bgr[:] = background
        edge = max(2, w // 14)
        cv2.rectangle(bgr, (0, 0), (w - 1, h - 1), accent, edge)
        for k in range(2):
            y0 = int(h * (0.08 + 0.47 * k))
            cv2.rectangle(
                bgr,
                (w // 6, y0),
                (5 * w // 6, y0 + int(h * 0.38)),
                tuple(0.85 * c for c in background),
                max(1, edge // 2),
            )
        cv2.rectangle(
            bgr, (int(0.78 * w), int(0.5 * h)), (int(0.9 * w), int(0.53 * h)), foreground, -1
        )
    elif kind == "window":
        alpha[:] = 255
        bgr[:] = background
        frame = max(2, min(w, h) // 16)
        cv2.rectangle(bgr, (0, 0), (w - 1, h - 1), accent, frame)
        n = int(rng.integers(1, 4))
        for k in range(1, n):
            cv2.line(bgr, (k * w // n, 0), (k * w // n, h), accent, frame)
        cv2.line(bgr, (0, h // 2), (w, h // 2), accent, max(1, frame // 2))
    elif kind == "poster":
        alpha[:] = 255
        frame = max(3, min(w, h) // 10)
        bgr[:] = accent
        inner = bgr[frame:-frame, frame:-frame]
        inner[:] = background
        for _ in range(int(rng.integers(2, 6))):
            c = tuple(float(v) for v in rng.integers(30, 230, 3))
            center = (int(rng.integers(0, inner.shape[1])), int(rng.integers(0, inner.shape[0])))
            cv2.circle(
                inner,
                center,
                int(rng.integers(5, max(6, min(inner.shape[:2]) // 2))),
                c,
                -1,
                cv2.LINE_AA,
            )
        if rng.random() < 0.6:
            _fit_text(
                inner,
                text,
                (5, int(0.7 * inner.shape[0]), inner.shape[1] - 5, inner.shape[0] - 5),
                foreground,
                font,
            )
    else:
        raise ValueError(f"unknown advert kind {kind!r}")
    out = np.empty((TEXTURE_PX, TEXTURE_PX, 4), np.uint8)
    size = (TEXTURE_PX, TEXTURE_PX)
    out[:, :, :3] = cv2.resize(bgr, size, interpolation=cv2.INTER_AREA)
    out[:, :, 3] = cv2.resize(alpha, size, interpolation=cv2.INTER_AREA)
    return out


# ----------------------------------------------------------------------------------------------
# Broadcast graphics and other burned-in overlays


def _px_rect(
    rect: tuple[float, float, float, float], width: int, height: int
) -> tuple[int, int, int, int]:
    x0, y0, x1, y1 = rect
    return (
        int(round(x0 * width)),
        int(round(y0 * height)),
        int(round(x1 * width)) - 1,
        int(round(y1 * height)) - 1,
    )


def draw_overlay(
    image: np.ndarray,
    kind: str,
    rect: tuple[float, float, float, float],
    text: str,
    colours: tuple[tuple[int, int, int], ...],
    alpha: float,
    seed: int,
) -> None:
    """Draw one overlay in place on a uint8 BGR image, inside `rect` (fractions of the image).

    kinds: "score_bar" (two names and scores, broadcast style), "score_box" (a stacked score table),
    "logo" (a channel mark), "clock", "text" (stream text with a shadow), "letterbox" (black bars:
    `rect` gives the picture rows kept, columns ignored), "box" (a plain graphic panel).
    """
    height, width = image.shape[:2]
    rng = np.random.default_rng(seed)
    font = int(rng.choice(_FONTS[:4]))
    x0, y0, x1, y1 = _px_rect(rect, width, height)
    base = tuple(float(c) for c in colours[0])
    ink = tuple(float(c) for c in colours[1 % len(colours)])
    accent = tuple(float(c) for c in colours[2 % len(colours)])
    if kind == "letterbox":
        image[: max(0, y0)] = 0
        image[y1 + 1 :] = 0
        return
    layer = image.copy()
    if kind == "score_bar":
        bw, bh = x1 - x0, y1 - y0
        cv2.rectangle(layer, (x0, y0), (x1, y1), base, -1)
        names = text.split("|") if "|" in text else [text, text]
        mid0, mid1 = x0 + int(0.42 * bw), x0 + int(0.58 * bw)
        cv2.rectangle(layer, (mid0, y0), (mid1, y1), accent, -1)
        _fit_text(
            layer,
            names[0],
            (x0 + int(0.03 * bw), y0 + int(0.15 * bh), mid0 - int(0.1 * bw), y1 - int(0.15 * bh)),
            ink,
            font,
        )
        _fit_text(
            layer,
            names[1],
            (mid1 + int(0.1 * bw), y0 + int(0.15 * bh), x1 - int(0.03 * bw), y1 - int(0.15 * bh)),
            ink,
            font,
        )
        scores = f"{int(rng.integers(0, 3))}  {int(rng.integers(0, 12))}-{int(rng.integers(0, 12))}  {int(rng.integers(0, 3))}"
        _fit_text(
            layer,
            scores,
            (mid0 + 2, y0 + int(0.12 * bh), mid1 - 2, y1 - int(0.12 * bh)),
            base,
            font,
        )
        # small game boxes at both ends of the centre block
        cv2.rectangle(layer, (mid0 - int(0.08 * bw), y0), (mid0, y1), ink, 1)
        cv2.rectangle(layer, (mid1, y0), (mid1 + int(0.08 * bw), y1), ink, 1)
        cv2.line(layer, (x0, y1), (x1, y1), accent, max(1, bh // 10))
    elif kind == "score_box":
        bh = y1 - y0
        rows = 2
        for k in range(rows):
            ry0 = y0 + k * bh // rows
            ry1 = y0 + (k + 1) * bh // rows - 1
            cv2.rectangle(layer, (x0, ry0), (x1, ry1), base, -1)
            bw = x1 - x0
            _fit_text(
                layer,
                text.split("|")[k % len(text.split("|"))],
                (x0 + 3, ry0 + 2, x0 + int(0.55 * bw), ry1 - 2),
                ink,
                font,
                align="left",
            )
            for c in range(4):
                cx0 = x0 + int((0.58 + 0.1 * c) * bw)
                cell = (cx0, ry0 + 2, cx0 + int(0.09 * bw), ry1 - 2)
                if c == 0:
                    cv2.rectangle(layer, cell[:2], cell[2:], accent, -1)
                _fit_text(layer, str(int(rng.integers(0, 12))), cell, ink, font)
    elif kind == "logo":
        cx, cy = (x0 + x1) // 2, (y0 + y1) // 2
        r = max(2, min(x1 - x0, y1 - y0) // 2)
        cv2.circle(layer, (cx, cy), r, base, -1, cv2.LINE_AA)
        cv2.circle(layer, (cx, cy), max(1, int(r * 0.8)), ink, max(1, r // 8), cv2.LINE_AA)
        _fit_text(
            layer,
            text,
            (cx - int(0.65 * r), cy - int(0.5 * r), cx + int(0.65 * r), cy + int(0.5 * r)),
            ink,
            font,
        )
    elif kind == "clock":
        cv2.rectangle(layer, (x0, y0), (x1, y1), base, -1)
        _fit_text(layer, text, (x0 + 2, y0 + 1, x1 - 2, y1 - 1), ink, font)
    elif kind == "text":
        shadow = np.zeros_like(layer)
        _fit_text(shadow, text, (x0 + 2, y0 + 2, x1, y1), (255.0, 255.0, 255.0), font, 0.14)
        dark = shadow[:, :, 0] > 100
        layer[dark] = (layer[dark].astype(np.float32) * 0.35).astype(np.uint8)
        _fit_text(layer, text, (x0, y0, x1 - 2, y1 - 2), ink, font, 0.14)
    elif kind == "box":
        cv2.rectangle(layer, (x0, y0), (x1, y1), base, -1)
        if text:
            _fit_text(layer, text, (x0 + 4, y0 + 2, x1 - 4, y1 - 2), ink, font)
    else:
        raise ValueError(f"unknown overlay kind {kind!r}")
    # only the overlay's own rectangle changes
    row_span = slice(max(y0, 0), min(y1 + 1, height))
    col_span = slice(max(x0, 0), min(x1 + 1, width))
    if alpha >= 1.0:
        image[row_span, col_span] = layer[row_span, col_span]
    else:
        image[row_span, col_span] = cv2.addWeighted(
            layer[row_span, col_span], alpha, image[row_span, col_span], 1.0 - alpha, 0.0
        )
