"""Render time of the synthetic scenes per picture size: `python -m bench.scene_speed [--cases 8]`.

Takes the cameras and styles of the first `--cases` seeds of every class (`cases.plan_case`),
rescales each camera to every size, and times `render_layers` (the ray caster) and `finish_frame`
(players, camera chain, graphics, JPEG) in CPU seconds of this process, after one warm-up render
(compiled code loaded). Prints median and worst per size, and `make_case` per class.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from app.calib import cases, scene
from bench.common import command_line, format_table

SIZES = ((640, 360), (960, 540), (1280, 720), (1920, 1080))


def _rescaled(
    genome: np.ndarray, size: tuple[int, int], width: int
) -> tuple[np.ndarray, tuple[int, int]]:
    g = genome.copy()
    s = width / size[0]
    g[0:4] = [g[0] * s, g[1] * s, (g[2] + 0.5) * s - 0.5, (g[3] + 0.5) * s - 0.5]
    return g, (width, int(round(size[1] * s)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--cases", type=int, default=2, help="seeds per class")
    args = parser.parse_args(argv)
    print(command_line())
    plans = [cases.plan_case(c, s) for c in cases.CASE_CLASSES for s in range(args.cases)]
    warm = plans[0]
    scene.render_scene(warm.genome, (64, 36), warm.spec, warm.style, 0)
    rows = []
    for width, _ in SIZES:
        cast, finish = [], []
        for plan in plans:
            g, size = _rescaled(plan.genome, plan.size, width)
            t0 = time.process_time()
            layers = scene.render_layers(g, size, plan.spec, plan.style, np.random.default_rng(0))
            t1 = time.process_time()
            scene.finish_frame(layers, g, plan.style, np.random.default_rng(0))
            t2 = time.process_time()
            cast.append(t1 - t0)
            finish.append(t2 - t1)
        total = np.add(cast, finish)
        rows.append(
            (
                f"{width} wide",
                len(plans),
                f"{np.median(cast):.3f}",
                f"{np.median(finish):.3f}",
                f"{np.median(total):.3f}",
                f"{total.max():.3f}",
            )
        )
    print(format_table(("size", "renders", "ray cast s", "finish s", "total s", "worst s"), rows))
    rows = []
    for name in cases.CASE_CLASSES:
        times = []
        for seed in range(args.cases):
            t0 = time.process_time()
            cases.make_case(name, seed)
            times.append(time.process_time() - t0)
        rows.append((name, len(times), f"{np.mean(times):.2f}", f"{max(times):.2f}"))
    print(format_table(("make_case", "cases", "mean s", "worst s"), rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
