"""Contact sheets of the synthetic benchmark: `python -m bench.scene_sheet [--per-class 4]`.

Renders `--per-class` cases of every class of `app.calib.cases` (seeds `--seed`, `--seed` + 1, ...)
and `--negatives` images of every negative kind, and writes two PNG grids to bench/out/ (or
`--out`): `scene_sheet.png` as rendered, and `scene_sheet_court.png` with the true camera's court
model drawn thinly over every case, so a reader can judge both the look and the ground truth.
Each thumbnail is captioned with class, seed, size, court spec and the floor lines in view.

`--real DIR` adds a first row of real images (every PNG/JPG in DIR, e.g. ../shared/data/dev) for
comparison; they are only read, never copied.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from app.calib import cases
from app.calib.court import court_model
from app.calib.render import draw_court
from bench.common import command_line, out_path

CAPTION_PX = 18
COURT_COLOUR = (60, 255, 60)


def _thumb(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """The image scaled to fit width x height, centred on a dark grey tile."""
    h, w = image.shape[:2]
    scale = min(width / w, height / h)
    small = cv2.resize(
        image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA
    )
    tile = np.full((height, width, 3), 40, np.uint8)
    y0 = (height - small.shape[0]) // 2
    x0 = (width - small.shape[1]) // 2
    tile[y0 : y0 + small.shape[0], x0 : x0 + small.shape[1]] = small
    return tile


def _caption(tile: np.ndarray, text: str) -> np.ndarray:
    bar = np.full((CAPTION_PX, tile.shape[1], 3), 20, np.uint8)
    cv2.putText(
        bar,
        text[:60],
        (4, CAPTION_PX - 5),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.38,
        (230, 230, 230),
        1,
        cv2.LINE_AA,
    )
    return np.vstack([tile, bar])


def _render_case(job: tuple[str, int]) -> tuple[str, int, np.ndarray, np.ndarray, str, float]:
    name, seed = job
    start = time.perf_counter()
    case = cases.make_case(name, seed)
    elapsed = time.perf_counter() - start
    overlay = draw_court(case.image, case.genome, court_model(case.spec), COURT_COLOUR, 1)
    lines = len(case.visible_lines)
    extra = (
        f" {len(case.frames)}f cut"
        if case.frames is not None and case.main_shot != (0, len(case.frames))
        else (f" {len(case.frames)}f" if case.frames is not None else "")
    )
    caption = f"{name} {seed} {case.size[0]}x{case.size[1]} {case.spec} {case.style.preset} L{lines}{extra}"
    return name, seed, case.image, overlay, caption, elapsed


def _render_negative(job: tuple[str, int]) -> tuple[str, int, np.ndarray, np.ndarray, str, float]:
    kind, seed = job
    start = time.perf_counter()
    negative = cases.make_negative(kind, seed)
    elapsed = time.perf_counter() - start
    h, w = negative.image.shape[:2]
    return kind, seed, negative.image, negative.image, f"negative {kind} {seed} {w}x{h}", elapsed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--per-class", type=int, default=4, help="cases per class")
    parser.add_argument("--negatives", type=int, default=2, help="images per negative kind")
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument(
        "--classes", default=",".join(cases.CASE_CLASSES), help="comma-separated classes"
    )
    parser.add_argument("--thumb", type=int, default=320, help="thumbnail width (px)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument(
        "--real", type=Path, default=None, help="a folder of real images for a first row"
    )
    parser.add_argument("--out", type=Path, default=None, help="output folder (default bench/out)")
    args = parser.parse_args(argv)
    width, height = args.thumb, args.thumb * 9 // 16
    classes = [c for c in args.classes.split(",") if c]
    case_jobs = [(c, args.seed + k) for c in classes for k in range(args.per_class)]
    negative_jobs = [
        (kind, args.seed + k) for kind in cases.NEGATIVE_KINDS for k in range(args.negatives)
    ]
    print(command_line())
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rendered = list(pool.map(_render_case, case_jobs)) + list(
            pool.map(_render_negative, negative_jobs)
        )
    columns = max(args.per_class, 4)
    plain_tiles: list[np.ndarray] = []
    court_tiles: list[np.ndarray] = []
    if args.real is not None:
        real = sorted(
            p for p in args.real.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg")
        )
        for path in real:
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                continue
            tile = _caption(_thumb(image, width, height), f"REAL {path.stem}")
            plain_tiles.append(tile)
            court_tiles.append(tile)
        while len(plain_tiles) % columns:
            blank = np.zeros_like(plain_tiles[0])
            plain_tiles.append(blank)
            court_tiles.append(blank)
    previous = None
    for name, _seed, image, overlay, caption, _elapsed in rendered:
        group = name if not caption.startswith("negative") else "negatives"
        if previous is not None and group != previous and group != "negatives":
            while len(plain_tiles) % columns:
                plain_tiles.append(np.zeros_like(plain_tiles[-1]))
                court_tiles.append(np.zeros_like(court_tiles[-1]))
        if group == "negatives" and previous != "negatives":
            while len(plain_tiles) % columns:
                plain_tiles.append(np.zeros_like(plain_tiles[-1]))
                court_tiles.append(np.zeros_like(court_tiles[-1]))
        previous = group
        plain_tiles.append(_caption(_thumb(image, width, height), caption))
        court_tiles.append(_caption(_thumb(overlay, width, height), caption))
    while len(plain_tiles) % columns:
        plain_tiles.append(np.zeros_like(plain_tiles[-1]))
        court_tiles.append(np.zeros_like(court_tiles[-1]))
    out_dir = args.out
    paths = []
    for tiles, name in ((plain_tiles, "scene_sheet.png"), (court_tiles, "scene_sheet_court.png")):
        rows = [np.hstack(tiles[k : k + columns]) for k in range(0, len(tiles), columns)]
        sheet = np.vstack(rows)
        path = out_path(name) if out_dir is None else out_dir / name
        path.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(path), sheet)
        paths.append(path)
    times = np.array([r[5] for r in rendered])
    print(
        f"{len(case_jobs)} cases, {len(negative_jobs)} negatives in {time.perf_counter() - start:.1f} s "
        f"(per image: median {np.median(times):.2f} s, max {times.max():.2f} s, {args.jobs} job(s))"
    )
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
