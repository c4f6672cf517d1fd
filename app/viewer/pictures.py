"""Pictures of a calibration: court over the background, line evidence, court diagram, convergence.

All drawing is anti-aliased (OpenCV LINE_AA with sub-pixel vertices), with line widths and text
sizes scaled to the picture so they stay visible when a browser shows it at page size. Every
function returns a BGR uint8 image; the API encodes it as PNG.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from app.calib import camera, pipeline, render
from app.calib.court import CourtModel, court_model

# BGR colours
FITTED = (60, 220, 60)
START = (0, 160, 255)
EVIDENCE = (255, 230, 80)
HALO = (0, 0, 0)
INK = (40, 40, 40)
GRID = (215, 215, 215)
PAPER = (255, 255, 255)
FLOOR = (170, 205, 230)
PAINT = (40, 40, 200)
VISIBLE = (120, 190, 120)
POINT = (200, 60, 20)

FONT = cv2.FONT_HERSHEY_SIMPLEX
_SHIFT = 4  # fixed-point bits for sub-pixel vertices
_SCALE = float(1 << _SHIFT)


def line_evidence(image: np.ndarray, moving_mask: np.ndarray | None = None) -> np.ndarray:
    """uint8 (H, W), nonzero on the line evidence the fit used (the one place that says which)."""
    return pipeline.evidence_image(image, moving_mask)


def _bgr(image: np.ndarray) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim == 2:
        return cv2.cvtColor(arr, cv2.COLOR_GRAY2BGR)
    if arr.shape[2] == 4:
        return cv2.cvtColor(arr, cv2.COLOR_BGRA2BGR)
    return arr.copy()


def _fixed(points: np.ndarray, limit: float) -> np.ndarray:
    return np.round(np.clip(points, -limit, limit) * _SCALE).astype(np.int32).reshape(-1, 1, 2)


def _polylines(
    image: np.ndarray,
    lines: Sequence[np.ndarray],
    color: tuple[int, int, int],
    thickness: int,
    halo: bool = True,
) -> None:
    """Anti-aliased polylines (pixel coordinates, float) with a dark halo so they read on any
    background."""
    height, width = image.shape[:2]
    limit = 4.0 * max(width, height)
    fixed = [_fixed(line, limit) for line in lines if len(line) >= 2]
    if not fixed:
        return
    if halo:
        cv2.polylines(image, fixed, False, HALO, thickness + 2, cv2.LINE_AA, _SHIFT)
    cv2.polylines(image, fixed, False, color, thickness, cv2.LINE_AA, _SHIFT)


def _text(
    image: np.ndarray,
    text: str,
    origin: tuple[float, float],
    scale: float,
    color: tuple[int, int, int] = INK,
    halo: tuple[int, int, int] | None = None,
    align: str = "left",
) -> None:
    thickness = max(1, round(scale * 1.6))
    (w, h), _ = cv2.getTextSize(text, FONT, scale, thickness)
    x, y = origin
    if align == "center":
        x -= w / 2
    elif align == "right":
        x -= w
    org = (round(x), round(y))
    if halo is not None:
        cv2.putText(image, text, org, FONT, scale, halo, thickness + 3, cv2.LINE_AA)
    cv2.putText(image, text, org, FONT, scale, color, thickness, cv2.LINE_AA)


def scaled_to_width(image: np.ndarray, width: int | None) -> tuple[np.ndarray, float]:
    """`image` shrunk to `width` pixels wide (never enlarged) and the scale factor used."""
    if width is None or width >= image.shape[1]:
        return image, 1.0
    scale = width / image.shape[1]
    size = (width, max(1, round(image.shape[0] * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA), scale


def _pixel_lines(genome: np.ndarray, model: CourtModel, scale: float) -> list[np.ndarray]:
    # pixel centres sit at integers: scaling maps centre u to (u + 0.5) * s - 0.5
    return [(line + 0.5) * scale - 0.5 for line in render.court_polylines(genome, model)]


def overlay_picture(
    background: np.ndarray,
    genome: np.ndarray,
    spec: str,
    start_genome: np.ndarray | None = None,
    width: int | None = None,
    show_fitted: bool = True,
) -> np.ndarray:
    """The background with the fitted court (green) and optionally the start camera's court
    (orange) drawn over it, with a legend; `width` shrinks it (thumbnails)."""
    image, scale = scaled_to_width(_bgr(background), width)
    model = court_model(spec)
    thickness = max(1, round(image.shape[1] / 640))
    legend: list[tuple[str, tuple[int, int, int]]] = []
    if start_genome is not None:
        _polylines(image, _pixel_lines(start_genome, model, scale), START, thickness)
        legend.append(("start camera", START))
    if show_fitted:
        _polylines(image, _pixel_lines(genome, model, scale), FITTED, thickness)
        legend.append(("fitted court", FITTED))
    if image.shape[1] >= 480 and legend:
        _legend(image, legend, image.shape[1] / 1600)
    return image


def _legend(
    image: np.ndarray, items: list[tuple[str, tuple[int, int, int]]], text_scale: float
) -> None:
    """Labels in their colours on a dark translucent box in the bottom-left corner."""
    thickness = max(1, round(text_scale * 1.6))
    sizes = [cv2.getTextSize(label, FONT, text_scale, thickness)[0] for label, _ in items]
    line_h = max(h for _, h in sizes) * 1.9
    pad = line_h * 0.45
    box_w = max(w for w, _ in sizes) + 2 * pad
    box_h = line_h * len(items) + pad
    x0, y1 = pad, image.shape[0] - pad
    y0 = y1 - box_h
    region = image[round(y0) : round(y1), round(x0) : round(x0 + box_w)]
    region[:] = (region.astype(np.float32) * 0.35).astype(np.uint8)
    for i, (label, color) in enumerate(items):
        _text(image, label, (x0 + pad, y0 + line_h * (i + 0.75)), text_scale, color)


def evidence_picture(evidence: np.ndarray, width: int | None = None) -> np.ndarray:
    """Line evidence (nonzero pixels) in a light colour on black; shrinking keeps thin lines
    visible (area averaging, then stretched)."""
    mask = (np.asarray(evidence) > 0).astype(np.float32)
    small, _ = scaled_to_width(mask, width)
    if small is not mask:
        small = np.clip(small * 3.0, 0.0, 1.0)
    colour = np.array(EVIDENCE, dtype=np.float32)
    return np.rint(small[:, :, None] * colour).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# court diagram (top-down)


class _Plan:
    """Floor metres <-> diagram pixels: front wall at the top, left wall on the left."""

    def __init__(self, width_m: float, length_m: float, px_per_m: float) -> None:
        self.px_per_m = px_per_m
        self.margin_left = 1.1 * px_per_m
        self.margin_top = 1.0 * px_per_m
        self.size = (
            round(width_m * px_per_m + 2.0 * px_per_m),
            round(length_m * px_per_m + 2.8 * px_per_m),
        )

    def px(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.column_stack(
            [
                self.margin_left + xy[:, 0] * self.px_per_m,
                self.margin_top + xy[:, 1] * self.px_per_m,
            ]
        )


def _floor_segments(model: CourtModel) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Floor edges of the court model as (outline, painted) lists of (2, 2) floor xy."""
    outline: list[np.ndarray] = []
    painted: list[np.ndarray] = []
    for name, (a, b) in zip(model.edge_names, model.edges, strict=True):
        p, q = model.nodes[a], model.nodes[b]
        if p[2] != 0.0 or q[2] != 0.0:
            continue
        segment = np.array([p[:2], q[:2]])
        (outline if "floor" in name else painted).append(segment)
    return outline, painted


def floor_lines_m(spec: str) -> dict[str, list[list[list[float]]]]:
    """The floor plan as segments in metres: {"outline": [...], "painted": [...]}."""
    outline, painted = _floor_segments(court_model(spec))
    return {"outline": [s.tolist() for s in outline], "painted": [s.tolist() for s in painted]}


def _visible_floor(
    genome: np.ndarray, image_size: tuple[int, int], model: CourtModel, step_m: float = 0.05
) -> np.ndarray:
    """bool (ny, nx) over the floor on a step_m grid: True where the camera sees the floor."""
    xs = np.arange(step_m / 2, model.spec.width_m, step_m)
    ys = np.arange(step_m / 2, model.spec.length_m, step_m)
    gx, gy = np.meshgrid(xs, ys)
    pixels = camera.floor_to_pixel(genome, np.column_stack([gx.ravel(), gy.ravel()]))
    inside = camera.pixels_in_image(pixels, image_size)
    return inside.reshape(gx.shape)


HEATMAP_MIN_POINTS = 50  # "auto" mode draws a heatmap from this many points on


def topdown_picture(
    spec: str,
    genome: np.ndarray | None = None,
    image_size: tuple[int, int] | None = None,
    points_m: np.ndarray | None = None,
    mode: str = "auto",
    px_per_m: float = 64.0,
) -> np.ndarray:
    """The court seen from above (front wall at the top), the floor the camera sees shaded, and
    `points_m` (M, 2) floor positions marked (mode "points"), or as a density heatmap ("heatmap";
    "auto" picks the heatmap from HEATMAP_MIN_POINTS points on)."""
    if mode not in ("auto", "points", "heatmap"):
        raise ValueError(f"mode must be auto, points or heatmap, got {mode!r}")
    model = court_model(spec)
    w_m, l_m = model.spec.width_m, model.spec.length_m
    plan = _Plan(w_m, l_m, px_per_m)
    image = np.full((plan.size[1], plan.size[0], 3), PAPER, np.uint8)
    (x0, y0), (x1, y1) = plan.px(np.array([[0.0, 0.0], [w_m, l_m]]))
    cv2.rectangle(image, (round(x0), round(y0)), (round(x1), round(y1)), FLOOR, cv2.FILLED)

    step = 0.05
    if genome is not None and image_size is not None:
        seen = _visible_floor(genome, image_size, model, step)
        tile = cv2.resize(
            seen.astype(np.float32),
            (round(x1) - round(x0), round(y1) - round(y0)),
            interpolation=cv2.INTER_LINEAR,
        )
        region = image[round(y0) : round(y1), round(x0) : round(x1)].astype(np.float32)
        alpha = 0.45 * tile[:, :, None]
        region = region * (1 - alpha) + np.array(VISIBLE, np.float32) * alpha
        image[round(y0) : round(y1), round(x0) : round(x1)] = np.rint(region).astype(np.uint8)

    points = None if points_m is None else np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
    points = None if points is None else points[np.isfinite(points).all(axis=1)]
    heat = points is not None and (
        mode == "heatmap" or (mode == "auto" and len(points) >= HEATMAP_MIN_POINTS)
    )
    if heat and points is not None and len(points):
        _heatmap(image, plan, points, w_m, l_m)

    thickness = max(2, round(px_per_m / 22))
    outline, painted = _floor_segments(model)
    _polylines(image, [plan.px(s) for s in painted], PAINT, thickness, halo=False)
    _polylines(image, [plan.px(s) for s in outline], INK, thickness + 1, halo=False)

    text_scale = px_per_m / 110
    _text(
        image, "FRONT WALL", ((x0 + x1) / 2, y0 - 0.35 * px_per_m), text_scale, INK, align="center"
    )
    _text(image, "BACK WALL", ((x0 + x1) / 2, y1 + 0.5 * px_per_m), text_scale, INK, align="center")
    tick = 0.12 * px_per_m
    for x in np.arange(0.0, w_m + 1e-9, 1.0):
        ((u, _),) = plan.px(np.array([[x, 0.0]]))
        cv2.line(image, (round(u), round(y0 - tick)), (round(u), round(y0)), INK, 1, cv2.LINE_AA)
    for y in np.arange(0.0, l_m + 1e-9, 1.0):
        ((_, v),) = plan.px(np.array([[0.0, y]]))
        cv2.line(image, (round(x0 - tick), round(v)), (round(x0), round(v)), INK, 1, cv2.LINE_AA)
        _text(
            image,
            f"{y:g}",
            (x0 - 1.6 * tick, v + 0.08 * px_per_m),
            0.8 * text_scale,
            INK,
            align="right",
        )
    _text(
        image,
        "y (m)",
        (x0 - 1.6 * tick, y1 + 0.55 * px_per_m),
        0.8 * text_scale,
        INK,
        align="right",
    )
    _text(
        image, f"x 0 .. {w_m:g} m", (x1, y0 - 0.35 * px_per_m), 0.8 * text_scale, INK, align="right"
    )

    if genome is not None:
        _camera_marker(image, plan, genome, w_m, l_m, text_scale)
    if points is not None and len(points) and not heat:
        radius = max(4, round(px_per_m / 10))
        for i, (u, v) in enumerate(plan.px(points)):
            centre = (round(u * _SCALE), round(v * _SCALE))
            cv2.circle(image, centre, (radius + 2) << _SHIFT, PAPER, -1, cv2.LINE_AA, _SHIFT)
            cv2.circle(image, centre, radius << _SHIFT, POINT, -1, cv2.LINE_AA, _SHIFT)
            if len(points) <= 20:
                _text(
                    image, str(i + 1), (u + radius + 3, v - radius), 0.8 * text_scale, POINT, PAPER
                )
    return image


def _heatmap(image: np.ndarray, plan: _Plan, points: np.ndarray, w_m: float, l_m: float) -> None:
    """Density of floor positions over the court, colour-mapped, blended where there are any."""
    cell = 0.1
    nx, ny = int(math.ceil(w_m / cell)), int(math.ceil(l_m / cell))
    on_court = points[
        (points[:, 0] >= 0) & (points[:, 0] <= w_m) & (points[:, 1] >= 0) & (points[:, 1] <= l_m)
    ]
    counts, _, _ = np.histogram2d(
        on_court[:, 1], on_court[:, 0], bins=(ny, nx), range=((0, l_m), (0, w_m))
    )
    density = cv2.GaussianBlur(counts.astype(np.float32), (0, 0), 2.5)
    if density.max() <= 0:
        return
    density /= density.max()
    (x0, y0), (x1, y1) = plan.px(np.array([[0.0, 0.0], [w_m, l_m]]))
    size = (round(x1) - round(x0), round(y1) - round(y0))
    big = cv2.resize(density, size, interpolation=cv2.INTER_CUBIC).clip(0, 1)
    colours = cv2.applyColorMap(np.rint(big * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)
    alpha = np.clip(big * 1.5, 0, 0.85)[:, :, None]
    region = image[round(y0) : round(y1), round(x0) : round(x1)].astype(np.float32)
    region = region * (1 - alpha) + colours.astype(np.float32) * alpha
    image[round(y0) : round(y1), round(x0) : round(x1)] = np.rint(region).astype(np.uint8)


def _camera_marker(
    image: np.ndarray, plan: _Plan, genome: np.ndarray, w_m: float, l_m: float, text_scale: float
) -> None:
    """The camera's floor position (clamped to the picture's edge, with its true distance)."""
    r, t = camera.court_extrinsics(genome)
    centre = -r[0].T @ t[0]
    forward = r[0][2]
    height, width = image.shape[:2]
    pad = 0.3 * plan.px_per_m
    ((u, v),) = plan.px(centre[None, :2])
    # room for the label below: the marker stays above the picture's last line
    cu, cv_ = float(np.clip(u, pad, width - pad)), float(np.clip(v, pad, height - 3 * pad))
    heading = forward[:2] / max(float(np.linalg.norm(forward[:2])), 1e-9)
    size = 0.28 * plan.px_per_m
    tip = np.array([cu, cv_]) + heading * size
    side = np.array([-heading[1], heading[0]]) * size * 0.6
    back = np.array([cu, cv_]) - heading * size * 0.5
    triangle = np.array([tip, back + side, back - side])
    cv2.fillPoly(image, [_fixed(triangle, 1e6)], INK, cv2.LINE_AA, _SHIFT)
    label = f"camera {-centre[2]:.1f} m high"
    if centre[1] > l_m:
        label += f", {centre[1] - l_m:.1f} m behind the back wall"
    elif centre[1] < 0:
        label += f", {-centre[1]:.1f} m in front of the front wall"
    (text_w, _), _ = cv2.getTextSize(label, FONT, 0.8 * text_scale, 1)
    text_x = float(np.clip(cu, text_w / 2 + 4, width - text_w / 2 - 4))
    _text(
        image,
        label,
        (text_x, cv_ + 0.75 * plan.px_per_m),
        0.8 * text_scale,
        INK,
        PAPER,
        align="center",
    )


# ---------------------------------------------------------------------------------------------
# convergence


def _nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    if not hi > lo:
        hi = lo + 1.0
    raw = (hi - lo) / n
    magnitude = 10 ** math.floor(math.log10(raw))
    step = min((m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw), default=raw)
    return np.arange(math.ceil(lo / step) * step, hi + step * 1e-9, step)


STAGE_COLOURS = [(180, 110, 30), (40, 140, 230), (60, 170, 60), (160, 60, 160), (60, 60, 200)]


def convergence_picture(
    convergence: Sequence[dict[str, Any]] | None,
    timings_s: dict[str, float] | None,
    width: int = 960,
) -> np.ndarray:
    """Best (solid) and mean (thin) fitness per generation for each optimisation stage, and
    below it the seconds each stage of the calibration took."""
    height = round(width * 0.5)
    bar_h = round(width * 0.13)
    image = np.full((height + bar_h, width, 3), PAPER, np.uint8)
    s = width / 960
    left, right, top, bottom = 90 * s, width - 24 * s, 40 * s, height - 60 * s
    text_scale = 0.5 * s
    _text(
        image,
        "How the fit converged: search hypotheses, GA generations",
        (left, 26 * s),
        0.6 * s,
        INK,
    )

    curves = [c for c in (convergence or []) if len(c.get("x") or []) >= 1]
    if not curves:
        _text(
            image,
            "no optimisation history was recorded for this calibration",
            ((left + right) / 2, (top + bottom) / 2),
            text_scale,
            INK,
            align="center",
        )
    else:
        xs = np.concatenate([np.asarray(c["x"], float) for c in curves])
        ys = np.concatenate(
            [np.asarray(c.get(k) or [], float) for c in curves for k in ("best", "mean")]
        )
        ys = ys[np.isfinite(ys)]
        x_lo, x_hi = float(xs.min()), float(max(xs.max(), xs.min() + 1))
        y_lo, y_hi = (float(ys.min()), float(ys.max())) if len(ys) else (0.0, 1.0)
        pad = 0.05 * (y_hi - y_lo or 1.0)
        y_lo, y_hi = y_lo - pad, y_hi + pad

        def to_px(x: np.ndarray, y: np.ndarray) -> np.ndarray:
            u = left + (x - x_lo) / (x_hi - x_lo) * (right - left)
            v = bottom - (y - y_lo) / (y_hi - y_lo) * (bottom - top)
            return np.column_stack([u, v])

        for y in _nice_ticks(y_lo, y_hi):
            ((_, v),) = to_px(np.array([x_lo]), np.array([y]))
            cv2.line(image, (round(left), round(v)), (round(right), round(v)), GRID, 1)
            _text(image, f"{y:.4g}", (left - 8 * s, v + 5 * s), text_scale, INK, align="right")
        for x in _nice_ticks(x_lo, x_hi, 6):
            ((u, _),) = to_px(np.array([x]), np.array([y_lo]))
            cv2.line(image, (round(u), round(top)), (round(u), round(bottom)), GRID, 1)
            _text(image, f"{x:g}", (u, bottom + 20 * s), text_scale, INK, align="center")
        cv2.rectangle(image, (round(left), round(top)), (round(right), round(bottom)), INK, 1)
        x_label = str(curves[0].get("x_label") or "step")
        _text(
            image, x_label, ((left + right) / 2, bottom + 44 * s), text_scale, INK, align="center"
        )
        _text(image, "fitness", (8 * s, top - 10 * s), text_scale, INK)
        legend_x = right
        for i, curve in enumerate(curves):
            colour = STAGE_COLOURS[i % len(STAGE_COLOURS)]
            x = np.asarray(curve["x"], float)
            light = tuple(round(0.35 * c + 0.65 * 255) for c in colour)
            for key, thick, shade in (
                ("mean", 1, light),
                ("best", max(2, round(2.5 * s)), colour),
            ):
                y = np.asarray(curve.get(key) or [], float)
                if len(y) != len(x):
                    continue
                ok = np.isfinite(y)
                line = to_px(x[ok], y[ok])
                if len(line) == 1:
                    line = np.vstack([line, line + [1.0, 0.0]])
                _polylines(image, [line], shade, thick, halo=False)  # type: ignore[arg-type]
            label = f"{curve.get('stage', 'stage')}: best (thick), mean (thin)"
            (tw, _), _ = cv2.getTextSize(label, FONT, text_scale, 1)
            legend_x = right - tw - 10 * s
            _text(image, label, (legend_x, bottom - 12 * s - 22 * s * i), text_scale, colour, PAPER)

    _timings_bar(image, timings_s or {}, height, bar_h, s)
    return image


def _timings_bar(
    image: np.ndarray, timings_s: dict[str, float], y0: float, bar_h: int, s: float
) -> None:
    stages = [(k, float(v)) for k, v in timings_s.items() if k != "total" and float(v) > 0]
    left, right = 90 * s, image.shape[1] - 24 * s
    _text(image, "seconds per stage", (8 * s, y0 + 18 * s), 0.5 * s, INK)
    if not stages:
        _text(image, "no stage times recorded", (left, y0 + 60 * s), 0.5 * s, INK)
        return
    total = sum(v for _, v in stages)
    x = left
    top, bottom = y0 + 28 * s, y0 + bar_h - 46 * s
    key_x, key_y = left, bottom + 24 * s
    for i, (name, seconds) in enumerate(stages):
        w = (right - left) * seconds / total
        colour = STAGE_COLOURS[i % len(STAGE_COLOURS)]
        cv2.rectangle(image, (round(x), round(top)), (round(x + w), round(bottom)), colour, -1)
        x += w
        # the key below the bar: a colour swatch and "stage 1.23 s", wrapping to a second row
        label = f"{name.replace('_', ' ')} {seconds:.2f} s"
        (tw, th), _ = cv2.getTextSize(label, FONT, 0.45 * s, 1)
        if key_x + th + 6 * s + tw > right and key_x > left:
            key_x, key_y = left, key_y + 20 * s
        cv2.rectangle(
            image, (round(key_x), round(key_y - th)), (round(key_x + th), round(key_y)), colour, -1
        )
        _text(image, label, (key_x + th + 6 * s, key_y), 0.45 * s, INK)
        key_x += th + 6 * s + tw + 22 * s
    _text(image, f"total {total:.2f} s", (right, y0 + 18 * s), 0.5 * s, INK, align="right")
