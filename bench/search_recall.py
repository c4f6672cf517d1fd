"""Where the search loses the court: `python -m bench.search_recall [--per-class 12] [--first-seed 0]`.

The global search (`search.search_cameras`) narrows ~10^5 hypotheses down to a few candidates
in stages (hypotheses from the lines and the placement grid, a cheap floor pass, the coarse
ranking, the cameras chosen for polishing, polished, candidates). For each seeded case of
`bench.synthetic`'s classes, rendered with a known camera, this reports per stage the share of
cases where at least one camera of that stage is *near* the true one: the median pixel distance
of the 16 x 16 floor grid points the true camera sees is at most NEAR_SHARE_OF_WIDTH of the
picture's width (where the refinement reliably converges from), and whether the first candidate
(the one refinement starts from first) is near. A stage whose recall drops is where to work.

Also per class: the lens estimate's error (the plumb-line division-model lambda against the one
closest to the true camera's radial terms over the picture) and the search's median time.

'picked' follows the candidates one step further, through `refine.refine_candidates` (each
refined, the best-scoring one picked to start the final fit): the share of cases where the
picked camera is near. A case near at 'candidates' but not at 'picked' is lost to the ranking of
the refined cameras, not to the search (seeds 2000+: zoomed 2003 and 2004, where a camera
metres off lays the court's across lines on the picture's, or its half-court line on a glass
wall's frame, and outscores the right one).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from bench.common import command_line, format_table

NEAR_SHARE_OF_WIDTH = 0.01
STAGES = (
    "hypotheses",
    "floor pass",
    "coarse",
    "chosen for polishing",
    "polished",
    "candidates",
)


@dataclass
class Recall:
    kind: str
    seed: int
    near: dict[str, bool] = field(default_factory=dict)
    first_near: bool = False
    picked_near: bool = False
    lens_error: float = float("nan")
    seconds: float = 0.0


def floor_grid_errors_px(truth: np.ndarray, genomes: np.ndarray, spec: str, size: tuple[int, int]):
    """(N,) median pixel distance of the floor grid points the true camera sees."""
    from app.calib import camera
    from app.calib.court import floor_grid

    width, height = size
    grid = floor_grid(spec)
    true_px = camera.project_visible(truth, grid)
    seen = camera.pixels_in_image(true_px, size)
    if not seen.any() or len(genomes) == 0:
        return np.full(len(genomes), np.inf)
    errors = np.empty(len(genomes))
    for start in range(0, len(genomes), 4096):
        chunk = genomes[start : start + 4096]
        px, depth = camera.project_points(chunk, grid[seen])
        d = np.linalg.norm(px - true_px[seen][None], axis=2)
        d[~(depth > 0) | ~np.isfinite(d)] = np.inf
        errors[start : start + len(chunk)] = np.median(d, axis=1)
    return errors


def expected_lambda(truth: np.ndarray, size: tuple[int, int]) -> float:
    """The division-model lambda (radius in half-diagonals, centre of the picture) closest to
    the true lens over the picture: least squares of the undistorted radius over distorted
    radii up to the corner, weighted by the area at each radius."""
    from app.calib import camera

    half_diagonal = 0.5 * float(np.hypot(*size))
    k1, k2, k3 = (truth[camera.GENE[n]] for n in ("k1", "k2", "k3"))
    # the true lens's radius map on its usable branch (focal units), inverted by interpolation
    r_u = np.linspace(0.0, 6.0, 60001)
    r2 = r_u * r_u
    r_d = r_u * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
    rising = np.flatnonzero(np.diff(r_d) <= 0.0)
    usable = rising[0] + 1 if len(rising) else len(r_d)
    distorted = np.linspace(1.0, half_diagonal, 200) / truth[0]
    distorted = distorted[distorted <= r_d[usable - 1]]
    undistorted = np.interp(distorted, r_d[:usable], r_u[:usable])
    s2 = (distorted * truth[0] / half_diagonal) ** 2
    lambdas = np.linspace(-1.5, 0.6, 2101)
    with np.errstate(divide="ignore", invalid="ignore"):
        model = distorted[None, :] / (1.0 + lambdas[:, None] * s2[None, :])
        cost = np.where(
            np.all(1.0 + lambdas[:, None] * s2[None, :] > 0.0, axis=1),
            (distorted[None, :] * (model - undistorted[None, :]) ** 2).sum(axis=1),
            np.inf,
        )
    return float(lambdas[int(np.argmin(cost))])


def run_case(kind: str, seed: int) -> Recall:
    from app.calib import cases, lines, refine, search, segments, verify
    from app.calib.court import court_model
    from bench.synthetic import clip_background

    case = cases.make_case(kind, seed)
    image, moving = case.image, None
    if case.frames is not None:
        try:
            image, moving = clip_background(case.video_frames(), case.fps or 25.0)
        except Exception:
            return Recall(kind, seed, {s: False for s in STAGES})
        if not moving.any():
            moving = None
    size = (int(image.shape[1]), int(image.shape[0]))
    model = court_model(case.spec)
    near_px = NEAR_SHARE_OF_WIDTH * size[0]
    out = Recall(kind, seed)
    t0 = time.perf_counter()
    evidence = lines.line_evidence_of(image, moving)
    maps = lines.evidence_maps(evidence)
    verify = verify.verify_samples(model)
    errors_of: dict[str, np.ndarray] = {}

    def trace(stage: str, cameras: np.ndarray) -> None:
        errors_of[stage] = floor_grid_errors_px(case.genome, cameras, case.spec, size)

    traced_s = 0.0

    def timed_trace(stage: str, cameras: np.ndarray) -> None:
        nonlocal traced_s
        t = time.perf_counter()
        trace(stage, cameras)
        traced_s += time.perf_counter() - t

    found = search.search_cameras(evidence, maps, model, size, None, verify, trace=timed_trace)
    out.seconds = time.perf_counter() - t0 - traced_s
    if len(found.candidates):
        samples = refine.fit_samples(model, refine.spacing_for_width(size[0]))
        _, fit, _ = refine.refine_candidates(found.candidates, samples, maps, verify, model, size)
        picked = floor_grid_errors_px(case.genome, fit.genome[None, :], case.spec, size)
        out.picked_near = bool(picked[0] <= near_px)
    for stage in STAGES:
        errors = errors_of.get(stage, np.zeros(0))
        out.near[stage] = bool(len(errors) and np.min(errors) <= near_px)
    candidates = errors_of.get("candidates", np.zeros(0))
    out.first_near = bool(len(candidates) and candidates[0] <= near_px)
    lens = segments.estimate_undistortion(segments.chains_of(evidence), size)
    out.lens_error = abs(lens.lam - expected_lambda(case.genome, size))
    return out


def report(results: list[Recall], classes: list[str]) -> str:
    rows = []
    for name in [*classes, "all"]:
        group = [r for r in results if name == "all" or r.kind == name]
        n = len(group)
        if not n:
            continue
        rows.append(
            [
                name,
                n,
                *[f"{100.0 * np.mean([r.near.get(s, False) for r in group]):.0f}" for s in STAGES],
                f"{100.0 * np.mean([r.first_near for r in group]):.0f}",
                f"{100.0 * np.mean([r.picked_near for r in group]):.0f}",
                f"{np.nanmedian([r.lens_error for r in group]):.3f}",
                f"{np.nanpercentile([r.lens_error for r in group], 90):.3f}",
                f"{np.median([r.seconds for r in group]):.2f}",
            ]
        )
    return format_table(
        [
            "class",
            "n",
            *[f"{s} %" for s in STAGES],
            "first %",
            "picked %",
            "lens err med",
            "p90",
            "search s",
        ],
        rows,
    )


def main(argv: list[str] | None = None) -> int:
    from app.calib import cases

    parser = argparse.ArgumentParser(
        prog="python -m bench.search_recall", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--per-class", type=int, default=12)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--classes", nargs="*", default=list(cases.CASE_CLASSES))
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--misses", action="store_true", help="list the cases lost per stage")
    args = parser.parse_args(argv)
    jobs = [
        (c, s)
        for c in args.classes
        for s in range(args.first_seed, args.first_seed + args.per_class)
    ]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(run_case, *zip(*jobs, strict=True)))
    print(f"command: {command_line()}")
    print(
        f"near: median floor-grid pixel error <= {NEAR_SHARE_OF_WIDTH:.0%} of the width; "
        "'first': the first candidate is near; 'picked': the refined candidate picked is near"
    )
    print(report(results, args.classes))
    if args.misses:
        for stage in STAGES:
            lost = [f"{r.kind}:{r.seed}" for r in results if not r.near.get(stage, False)]
            print(f"not near at {stage}: {' '.join(lost)}")
        lost = [f"{r.kind}:{r.seed}" for r in results if not r.first_near]
        print(f"first candidate not near: {' '.join(lost)}")
        lost = [f"{r.kind}:{r.seed}" for r in results if not r.picked_near]
        print(f"picked refined candidate not near: {' '.join(lost)}")
    print(f"wall time {time.perf_counter() - t0:.0f} s, {args.workers} workers")
    return 0


if __name__ == "__main__":
    sys.exit(main())
