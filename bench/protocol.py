"""The paper's synthetic accuracy protocol (section VII): GA bundles, NLopt, CMA-ES and the product.

For every start distance (Table 3: near, medium, far), noise type (Fig. 8) and repetition, the
typical target camera's court is rasterised at 1920 x 1080 (`synthetic.render_edge_image`), noise is
added, and a start camera is made by the wiggle operator (7 genes moved by +- the Table 3 offset).
Each selected bundle runs `run_ga` from that start, and each selected method (below) from the same
start on the same noisy edge image; every result is scored by the mean reprojection error (MRE) on
the 16 x 16 floor grid G_p (and G_c, G_b). Each (distance, noise, repetition) has its own seeded
start and noise, shared by all bundles and methods, so they meet the same cases.

Methods beside the GA bundles (`--methods`, default all):
  product   `pipeline.calibrate(edge image, start_genome=start)`: what users get (line-evidence
            search with the start as one hint, point-to-line refinement, verdict; no GA). A run
            refused as "court not found" counts as a failure (G_p = inf; the rejected camera's
            G_p is kept as rejected_G_p).
  cmaes     a standard (mu/mu_w, lambda)-CMA-ES (`bench.cmaes`) maximising the same fitness as
            the NLopt methods, from the start, with Table 3's near offsets as the initial
            spread per gene, as Subplex's first step (sigma adapts from there; with the medium
            offsets the first generations land far off and near starts on noisy maps end
            hundreds of px away: measured on 2 repetitions of near/medium/far x 4 noise types).
  subplex   NLopt LN_SBPLX, the start +- the far offsets as box, the near offsets as first step.
  direct_l  NLopt GN_DIRECT_L in the same box (which always holds the target: every wiggle is at
            most the far offsets).
The three baselines get BASELINE_EVALUATIONS evaluations of `population_fitness` on the best
bundle's map (the paper's Fig. 12 setting: 100 000).

Tables printed:
  (a) Fig. 9: percentage of runs with G_p MRE under 2, 4, 6, 8, 10, 50 px by distance, by noise
      type, and per bundle; the paper's values where it states them.
  (b) Table 4: median generations until termination of runs under 10 px, noise x distance (n).
  (c) The best bundle (the default): median G_p MRE of runs under 10 px per distance.
  (d) Fig. 12: the best bundle against the methods: median G_p MRE of runs under 10 px.
  (e) Every method: the share of runs under 1 px G_p MRE per distance and noise type, against
      the product's targets (near >= 99 %, medium >= 98 %, far >= 95 % in every noise type).

Raw per-run results go to bench/out/protocol_<time>.csv; with --overlays, a picture of every
product run at or over 1 px (the noisy edge image, the true court in blue, the start in red, the
result in green) goes to bench/out/protocol_<time>_overlays/.

    python -m bench.protocol                       # default: 3 repetitions (~10 min on 2 cores)
    python -m bench.protocol --reps 20             # more repetitions per (distance, noise) cell
    python -m bench.protocol --reps 32 --all       # the paper's full protocol (days on 2 cores)
    python -m bench.protocol --bundles NAME ... --methods product cmaes --reps 2
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import math
import multiprocessing
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from datetime import datetime
from typing import Any

import numpy as np

from bench.common import command_line, format_table, out_path

IMAGE_SIZE = (1920, 1080)  # the paper's resolution; Table 3's pixel offsets are meant for it
THRESHOLDS_PX = (2, 4, 6, 8, 10, 50)
SUCCESS_PX = 10.0  # the paper's "MRE < 10 px" filter for Table 4 and Fig. 12
SUB_PX = 1.0  # the bar: runs under 1 px G_p MRE
# the product's targets: share (%) of runs under SUB_PX per distance, in every noise type
PRODUCT_TARGETS_PCT = {"near": 99.0, "medium": 98.0, "far": 95.0}
DEFAULT_REPS = 3
N_OTHER_BUNDLES = 5
BASELINE_EVALUATIONS = 100_000
NLOPT_METHODS = ("subplex", "direct_l")
METHODS = ("product", "cmaes", *NLOPT_METHODS)
# NLopt's positive result codes (nlopt.h)
NLOPT_RESULTS = {
    1: "success",
    2: "stopval_reached",
    3: "ftol_reached",
    4: "xtol_reached",
    5: "maxeval_reached",
    6: "maxtime_reached",
}
CMAES_STEP_DISTANCE = "near"  # Table 3 column used as CMA-ES's initial spread per gene (as Subplex)

# The paper's numbers, as far as its text states them (Fig. 9 is a plot; the text quotes these).
PAPER_FIG9_DISTANCE: dict[str, dict[int, int]] = {
    "near": {2: 60, 8: 91, 50: 99},
    "medium": {8: 38, 50: 82},
    "far": {50: 40},
}
PAPER_FIG9_NOISE: dict[str, dict[int, int]] = {
    "none": {2: 19, 4: 47, 6: 59},
    "horizontal": {2: 23, 4: 36, 6: 43},
    "vertical": {2: 25, 4: 40, 6: 45},
    "grid": {2: 23, 4: 36},
    "grid45": {2: 23, 4: 36},
    "salt": {2: 17, 4: 23, 6: 24},
}
PAPER_TABLE4: dict[str, tuple[tuple[int, int], ...]] = {
    "none": ((894, 3071), (1145, 2547), (1296, 1055)),
    "horizontal": ((976, 3032), (1202, 1472), (1349, 285)),
    "vertical": ((1000, 3003), (1258, 1586), (1453, 240)),
    "grid": ((975, 2849), (1217, 890), (1386, 78)),
    "grid45": ((984, 2797), (1233, 1178), (1468, 155)),
    "salt": ((1019, 2182), (1072, 411), (1068, 29)),
}
PAPER_FIG12_MEDIAN: dict[str, dict[str, float]] = {
    "ga": {"near": 1.5, "medium": 3.4, "far": 4.7},
    "subplex": {"near": 2.8, "medium": 5.9, "far": 9.7},
    "direct_l": {"near": 5.8, "medium": 5.3, "far": 6.5},
}
METHOD_TITLES = {
    "ga": "GA",
    "subplex": "Subplex",
    "direct_l": "DIRECT-L",
    "cmaes": "CMA-ES",
    "product": "product",
}


@dataclasses.dataclass(frozen=True)
class Config:
    bundles: tuple[str, ...]
    best_bundle: str
    methods: tuple[str, ...]
    baseline_evaluations: int
    max_generations: int | None
    base_seed: int
    overlay_dir: str | None = None


@dataclasses.dataclass(frozen=True)
class Case:
    distance: str
    noise: str
    rep: int


def case_seeds(base_seed: int, case: Case) -> tuple[int, int, int]:
    """(start seed, noise seed, optimiser seed) of a case; every bundle and method runs on the same.

    As in the paper, every (distance, noise, repetition) gets its own start camera.
    """
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    d = DISTANCES.index(case.distance)
    n = NOISE_TYPES.index(case.noise)
    start = np.random.SeedSequence([base_seed, 1, d, n, case.rep]).generate_state(1)[0]
    noise = np.random.SeedSequence([base_seed, 2, d, n, case.rep]).generate_state(1)[0]
    opt = np.random.SeedSequence([base_seed, 3, d, n, case.rep]).generate_state(1)[0]
    return int(start), int(noise), int(opt)


def run_nlopt(
    method: str,
    objective: Callable[[np.ndarray], float],
    start: np.ndarray,
    max_evaluations: int,
) -> tuple[np.ndarray, float, int, str]:
    """Maximise `objective` from `start` with Subplex or DIRECT-L; (best genome, fitness,
    evaluations, NLopt's stop reason in lower case, e.g. "maxeval_reached", "roundoff_limited")."""
    import nlopt

    from app.calib.synthetic import TABLE3_OFFSETS

    algorithm = {"subplex": nlopt.LN_SBPLX, "direct_l": nlopt.GN_DIRECT_L}[method]
    opt = nlopt.opt(algorithm, len(start))
    opt.set_lower_bounds(start - TABLE3_OFFSETS["far"])
    opt.set_upper_bounds(start + TABLE3_OFFSETS["far"])
    opt.set_maxeval(max_evaluations)
    if method == "subplex":
        opt.set_initial_step(TABLE3_OFFSETS["near"])
    best_x = start.copy()
    best_f = -math.inf
    evaluations = 0

    def wrapped(x: np.ndarray, grad: np.ndarray) -> float:
        nonlocal best_x, best_f, evaluations
        f = objective(x)
        evaluations += 1
        if f > best_f:
            best_f, best_x = f, x.copy()
        return f

    opt.set_max_objective(wrapped)
    # on a round-off stop the best point seen so far is still a valid answer
    stop = "roundoff_limited"
    with contextlib.suppress(nlopt.RoundoffLimited, nlopt.ForcedStop):
        opt.optimize(start.copy())
        stop = NLOPT_RESULTS.get(opt.last_optimize_result(), "other")
    return best_x, best_f, evaluations, stop


def run_product(
    edges: np.ndarray, start: np.ndarray, seed: int
) -> tuple[np.ndarray | None, dict[str, Any]]:
    """The product pipeline on the noisy edge image with the start as its hint: (camera or None
    when refused, fields for the row)."""
    from app.calib import pipeline

    try:
        result = pipeline.calibrate(edges, start_genome=start, seed=seed)
    except pipeline.CourtNotFound as exc:
        return None, {
            "verdict": "not_a_court",
            "refined_from": "",
            "camera_model": "",
            "stop_reason": "court_not_found: " + "; ".join(exc.reasons),
            "rejected_genome": exc.genome,
        }
    return result.genome, {
        "verdict": result.verdict.label,
        "refined_from": result.refined_from,
        "camera_model": result.camera_model,
        "stop_reason": result.stop_reason,
        "rejected_genome": None,
    }


def save_overlay(
    path: str, edges: np.ndarray, target: np.ndarray, start: np.ndarray, result: np.ndarray | None
) -> None:
    """The noisy edge image (dimmed) with the true court (blue), the start (red) and the result
    (green, if any) drawn over it, at half size."""
    import cv2

    from app.calib import court, render

    model = court.court_model()
    picture = cv2.cvtColor(edges // 2, cv2.COLOR_GRAY2BGR)
    picture = render.draw_court(picture, target, model, (255, 128, 0), 3)
    picture = render.draw_court(picture, start, model, (0, 0, 255), 2)
    if result is not None and np.all(np.isfinite(result)):
        picture = render.draw_court(picture, result, model, (0, 255, 0), 2)
    height, width = picture.shape[:2]
    cv2.imwrite(path, cv2.resize(picture, (width // 2, height // 2), interpolation=cv2.INTER_AREA))


def run_case(task: tuple[Case, Config]) -> list[dict[str, Any]]:
    """All bundles and methods on one (distance, noise, repetition) case."""
    case, config = task
    from app.calib import court, synthetic
    from app.calib.fitness import Scorer
    from app.calib.ga import bundle_fitness_map, get_bundle, run_ga
    from bench import cmaes

    start_seed, noise_seed, opt_seed = case_seeds(config.base_seed, case)
    model = court.court_model()
    samples = court.sample_edges(model, court.spacing_for_image(IMAGE_SIZE[0]))
    target = synthetic.typical_target_camera(IMAGE_SIZE)
    start = synthetic.wiggle_camera(target, case.distance, start_seed)
    edges = synthetic.add_noise(
        synthetic.render_edge_image(target, model, IMAGE_SIZE), case.noise, noise_seed
    )
    start_errors = synthetic.protocol_errors(target, start, model)
    common = {
        "distance": case.distance,
        "noise": case.noise,
        "rep": case.rep,
        "start_seed": start_seed,
        "noise_seed": noise_seed,
        "opt_seed": opt_seed,
        "start_G_p": start_errors["G_p"],
    }
    scorers: dict[bool, Scorer] = {}

    def scorer_for(bundle: Any) -> Scorer:
        if bundle.transformed_map not in scorers:
            scorers[bundle.transformed_map] = Scorer(samples, bundle_fitness_map(edges, bundle))
        return scorers[bundle.transformed_map]

    rows = []
    for name in config.bundles:
        bundle = get_bundle(name)
        scorer = scorer_for(bundle)
        kwargs: dict[str, Any] = {}
        if config.max_generations is not None:
            kwargs["max_generations"] = config.max_generations
        result = run_ga(scorer.fmap, samples, start, bundle=bundle, seed=opt_seed, **kwargs)
        errors = synthetic.protocol_errors(target, result.genome, model)
        rows.append(
            {
                **common,
                "method": "ga",
                "bundle": name,
                **errors,
                "fitness": float(result.fitness),
                "target_fitness": float(scorer(target)[0]),
                "generations": int(result.generations),
                "evaluations": int(result.fitness_evaluations),
                "stop_reason": result.stop_reason,
                "elapsed_s": float(result.elapsed_s),
            }
        )

    # the baselines and the product are compared on the best bundle's map (Fig. 12)
    scorer = scorer_for(get_bundle(config.best_bundle))
    target_fitness = float(scorer(target)[0])
    for method in config.methods:
        began = time.perf_counter()
        extra: dict[str, Any] = {}
        if method in NLOPT_METHODS:
            genome, _, evaluations, stop_reason = run_nlopt(
                method, lambda x: float(scorer(x)[0]), start, config.baseline_evaluations
            )
        elif method == "cmaes":
            found = cmaes.maximise(
                scorer,
                start,
                synthetic.TABLE3_OFFSETS[CMAES_STEP_DISTANCE],
                config.baseline_evaluations,
                seed=opt_seed,
            )
            genome, evaluations, stop_reason = found.genome, found.evaluations, found.stop_reason
        else:  # product
            camera, extra = run_product(edges, start, opt_seed)
            genome, evaluations = camera, 0
            stop_reason = extra.pop("stop_reason")
        elapsed = time.perf_counter() - began
        rejected = extra.pop("rejected_genome", None)
        if genome is None:
            errors = {name: math.inf for name in ("G_c", "G_b", "G_p")}
        else:
            errors = synthetic.protocol_errors(target, genome, model)
        if rejected is not None:
            extra["rejected_G_p"] = synthetic.protocol_errors(target, rejected, model)["G_p"]
        rows.append(
            {
                **common,
                "method": method,
                "bundle": config.best_bundle,
                **errors,
                "fitness": math.nan if genome is None else float(scorer(genome)[0]),
                "target_fitness": target_fitness,
                "generations": 0,
                "evaluations": int(evaluations),
                "stop_reason": stop_reason,
                "elapsed_s": elapsed,
                **extra,
            }
        )
        if method == "product" and config.overlay_dir is not None and not errors["G_p"] < SUB_PX:
            name = f"{case.distance}_{case.noise}_{case.rep}.png"
            save_overlay(f"{config.overlay_dir}/{name}", edges, target, start, genome)
    return rows


# ----------------------------------------------------------------------------------------------
# Choosing bundles


def default_bundles() -> list[str]:
    """The paper's best bundle plus bundles that each change one operator of it.

    Each other bundle differs from the best in as few fields as possible, and they are picked so
    that every operator (population, map, selection, crossover, mutation) is varied once.
    """
    from app.calib.ga import BUNDLES, DEFAULT_BUNDLE

    fields = [f.name for f in dataclasses.fields(DEFAULT_BUNDLE) if f.name != "name"]
    by_changed: dict[frozenset[str], list[str]] = defaultdict(list)
    for name, bundle in sorted(BUNDLES.items()):
        changed = frozenset(f for f in fields if getattr(bundle, f) != getattr(DEFAULT_BUNDLE, f))
        if changed:
            by_changed[changed].append(name)
    chosen: list[str] = []
    covered: set[str] = set()
    for changed in sorted(by_changed, key=lambda c: (len(c), sorted(c))):
        if len(chosen) == N_OTHER_BUNDLES:
            break
        if changed & covered:
            continue
        chosen.append(by_changed[changed][0])
        covered |= changed
    return [DEFAULT_BUNDLE.name, *chosen]


# ----------------------------------------------------------------------------------------------
# Tables


def _pct(values: Sequence[float], threshold: float) -> str:
    if not values:
        return "-"
    return f"{100.0 * np.mean(np.asarray(values) < threshold):.0f}"


def _median(values: Iterable[float], digits: int = 1) -> str:
    vals = list(values)
    return f"{np.median(vals):.{digits}f}" if vals else "-"


def fig9_rows(
    groups: dict[str, list[float]], paper: dict[str, dict[int, int]] | None
) -> list[list[object]]:
    rows: list[list[object]] = []
    for key, values in groups.items():
        rows.append([key, len(values), *(_pct(values, t) for t in THRESHOLDS_PX)])
        if paper is not None and key in paper:
            rows.append(["  paper", "", *(str(paper[key].get(t, "")) for t in THRESHOLDS_PX)])
    return rows


def ga_tables(ga: list[dict[str, Any]], config: Config) -> list[str]:
    """Tables (a) to (c): the GA bundles' runs."""
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    out: list[str] = []
    headers = ["", "n", *(f"<{t}px %" for t in THRESHOLDS_PX)]

    by_distance = {d: [r["G_p"] for r in ga if r["distance"] == d] for d in DISTANCES}
    by_noise = {n: [r["G_p"] for r in ga if r["noise"] == n] for n in NOISE_TYPES}
    out.append("(a) Fig. 9: runs with G_p 16x16 MRE under a threshold, all selected bundles pooled")
    out.append(
        format_table(["distance", *headers[1:]], fig9_rows(by_distance, PAPER_FIG9_DISTANCE))
    )
    out.append("")
    out.append(format_table(["noise", *headers[1:]], fig9_rows(by_noise, PAPER_FIG9_NOISE)))
    out.append("")
    per_bundle: dict[str, list[float]] = {}
    for name in config.bundles:
        for d in DISTANCES:
            per_bundle[f"{name} / {d}"] = [
                r["G_p"] for r in ga if r["bundle"] == name and r["distance"] == d
            ]
    out.append("(a') Fig. 9 per bundle and distance")
    out.append(format_table(["bundle / distance", *headers[1:]], fig9_rows(per_bundle, None)))
    out.append("")

    out.append(
        "(b) Table 4: median generations until termination, runs with G_p MRE < 10 px "
        "(n = such runs / all runs); paper in brackets"
    )
    table4 = []
    for noise in NOISE_TYPES:
        cells: list[object] = [noise]
        for k, d in enumerate(DISTANCES):
            group = [r for r in ga if r["noise"] == noise and r["distance"] == d]
            good = [r["generations"] for r in group if r["G_p"] < SUCCESS_PX]
            paper_gen, paper_n = PAPER_TABLE4[noise][k]
            cells.append(
                f"{_median(good, 0)} ({len(good)}/{len(group)}) [{paper_gen} ({paper_n}/3072)]"
            )
        table4.append(cells)
    out.append(format_table(["noise", *DISTANCES], table4))
    out.append("")

    best = [r for r in ga if r["bundle"] == config.best_bundle]
    out.append(f"(c) best bundle {config.best_bundle}: G_p MRE by start distance")
    best_rows = []
    for d in DISTANCES:
        group = [r for r in best if r["distance"] == d]
        mre = [r["G_p"] for r in group]
        good = [m for m in mre if m < SUCCESS_PX]
        best_rows.append(
            [
                d,
                len(group),
                _median(r["start_G_p"] for r in group),
                _median(mre),
                f"{len(good)}",
                _median(good),
                PAPER_FIG12_MEDIAN["ga"][d],
                _pct(mre, 2),
                _median((r["generations"] for r in group), 0),
                _median((1000 * r["elapsed_s"] for r in group), 0),
            ]
        )
    out.append(
        format_table(
            [
                "distance",
                "runs",
                "start MRE",
                "median MRE",
                "n<10px",
                "median<10px",
                "paper",
                "<2px %",
                "generations",
                "ms/run",
            ],
            best_rows,
        )
    )
    out.append("(paper, all 96 bundles pooled: near runs under 2 px = 60 %)")
    out.append("")
    return out


def report(rows: list[dict[str, Any]], config: Config) -> str:
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    ga = [r for r in rows if r["method"] == "ga"]
    best = [r for r in ga if r["bundle"] == config.best_bundle]
    out: list[str] = ga_tables(ga, config) if ga else []

    methods = (("ga",) if best else ()) + config.methods
    comparable = best + [r for r in rows if r["method"] in config.methods]
    if config.methods:
        out.append(
            f"(d) Fig. 12: median G_p MRE of runs < 10 px (n < 10 px / runs); GA = "
            f"{config.best_bundle}; Subplex, DIRECT-L and CMA-ES with "
            f"{config.baseline_evaluations} evaluations on the same map; all from the same starts"
        )

        def cell(group: list[dict[str, Any]]) -> str:
            good = [r["G_p"] for r in group if r["G_p"] < SUCCESS_PX]
            return f"{_median(good)} ({len(good)}/{len(group)})"

        paper_methods = [m for m in methods if m in PAPER_FIG12_MEDIAN]
        fig12 = []
        for d in DISTANCES:
            fig12.append(
                [d]
                + [
                    cell([r for r in comparable if r["method"] == m and r["distance"] == d])
                    for m in methods
                ]
                + [" / ".join(str(PAPER_FIG12_MEDIAN[m][d]) for m in paper_methods)]
            )
        for n in NOISE_TYPES:
            fig12.append(
                [n]
                + [
                    cell([r for r in comparable if r["method"] == m and r["noise"] == n])
                    for m in methods
                ]
                + [""]
            )
        fig12.append(
            ["mean s/run"]
            + [
                f"{np.mean([r['elapsed_s'] for r in comparable if r['method'] == m]):.2f}"
                for m in methods
            ]
            + [""]
        )
        fig12.append(
            ["fitness > target %"]
            + [
                _pct(
                    [
                        r["target_fitness"] - r["fitness"]
                        for r in comparable
                        if r["method"] == m and np.isfinite(r["fitness"])
                    ],
                    0.0,
                )
                for m in methods
            ]
            + [""]
        )
        paper_title = " / ".join(METHOD_TITLES[m] for m in paper_methods)
        headers = ["", *(METHOD_TITLES[m] for m in methods), f"paper {paper_title}"]
        if not paper_methods:
            headers, fig12 = headers[:-1], [line[:-1] for line in fig12]
        out.append(format_table(headers, fig12))
        out.append(
            "(fitness > target: runs that ended at a better fitness than the true camera has on "
            "the best bundle's map, i.e. where the fitness optimum, not the search, sets the error)"
        )
        out.append("")
    out.append(sub_pixel_report(comparable, methods, config.best_bundle))
    return "\n".join(out)


def sub_pixel_cells(
    rows: list[dict[str, Any]], method: str
) -> dict[tuple[str, str], tuple[int, int]]:
    """(distance, noise) -> (runs under SUB_PX G_p MRE, runs) of one method; "all" pools noises."""
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    cells = {}
    for d in DISTANCES:
        for n in (*NOISE_TYPES, "all"):
            group = [
                r["G_p"]
                for r in rows
                if r["method"] == method and r["distance"] == d and n in ("all", r["noise"])
            ]
            cells[(d, n)] = (int(np.sum(np.asarray(group) < SUB_PX)), len(group))
    return cells


def missed_targets(cells: dict[tuple[str, str], tuple[int, int]]) -> list[str]:
    """The (distance, noise) cells whose share under SUB_PX is below the product's target."""
    missed = []
    for (d, n), (good, runs) in cells.items():
        if n != "all" and runs and 100.0 * good / runs < PRODUCT_TARGETS_PCT[d]:
            missed.append(f"{d}/{n} {good}/{runs}")
    return missed


def sub_pixel_report(rows: list[dict[str, Any]], methods: Sequence[str], best_bundle: str) -> str:
    """Table (e): share of runs under SUB_PX per method, distance and noise type."""
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    targets = ", ".join(f"{d} >= {t:.0f}" for d, t in PRODUCT_TARGETS_PCT.items())
    out = [
        f"(e) runs with G_p MRE < {SUB_PX:g} px, % (runs); GA = {best_bundle}; "
        f"product targets: {targets} % in every noise type"
    ]
    table = []
    misses = {}
    for m in methods:
        cells = sub_pixel_cells(rows, m)
        misses[m] = missed_targets(cells)
        for d in DISTANCES:
            line: list[object] = [f"{METHOD_TITLES[m]} / {d}"]
            for n in (*NOISE_TYPES, "all"):
                good, runs = cells[(d, n)]
                line.append(f"{100.0 * good / runs:.0f} ({runs})" if runs else "-")
            table.append(line)
    out.append(format_table(["method / distance", *NOISE_TYPES, "all"], table))
    for m in methods:
        verdict = "met in every cell" if not misses[m] else "missed in " + ", ".join(misses[m])
        out.append(f"{METHOD_TITLES[m]}: targets {verdict}")
    return "\n".join(out)


def write_csv(rows: list[dict[str, Any]], stamp: str) -> str:
    path = out_path(f"protocol_{stamp}.csv")
    with path.open("w", newline="") as fh:
        fields = list(dict.fromkeys(key for row in rows for key in row))
        writer = csv.DictWriter(fh, fieldnames=fields, restval="")
        writer.writeheader()
        writer.writerows(rows)
    return str(path)


def _limit_threads() -> None:
    """One thread per worker process: the pool already keeps every core busy."""
    import cv2

    cv2.setNumThreads(1)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--bundles", nargs="*", help="bundle names (default: best + 5 others; none: no GA runs)"
    )
    parser.add_argument("--all", action="store_true", help="all 96 bundles")
    parser.add_argument(
        "--methods",
        nargs="*",
        choices=METHODS,
        default=list(METHODS),
        help=f"methods beside the GA bundles (default: {' '.join(METHODS)}; none: GA only)",
    )
    parser.add_argument("--reps", type=int, default=DEFAULT_REPS, help="repetitions per case")
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument(
        "--evaluations",
        type=int,
        default=BASELINE_EVALUATIONS,
        help="fitness evaluations of Subplex, DIRECT-L and CMA-ES",
    )
    parser.add_argument("--max-generations", type=int, default=None, help="GA generation cap")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the whole protocol")
    parser.add_argument(
        "--overlays", action="store_true", help="save a picture of every product run >= 1 px"
    )
    args = parser.parse_args(argv)

    from app.calib.ga import BUNDLES, DEFAULT_BUNDLE, get_bundle
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    if args.all:
        bundles = [DEFAULT_BUNDLE.name] + sorted(n for n in BUNDLES if n != DEFAULT_BUNDLE.name)
    elif args.bundles is not None:
        try:
            bundles = [get_bundle(n).name for n in args.bundles]
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    else:
        bundles = default_bundles()
    if args.reps < 1 or args.workers < 1 or args.evaluations < 1:
        print("error: --reps, --workers and --evaluations must be at least 1", file=sys.stderr)
        return 2
    stamp = f"{datetime.now():%Y%m%d_%H%M%S}"
    overlay_dir = None
    if args.overlays:
        overlay_dir = str(out_path(f"protocol_{stamp}_overlays"))
        os.makedirs(overlay_dir, exist_ok=True)
    config = Config(
        bundles=tuple(bundles),
        best_bundle=DEFAULT_BUNDLE.name,
        methods=tuple(m for m in METHODS if m in args.methods),
        baseline_evaluations=args.evaluations,
        max_generations=args.max_generations,
        base_seed=args.seed,
        overlay_dir=overlay_dir,
    )
    # repetition-major order, so an interrupted run still covers every cell evenly
    cases = [Case(d, n, rep) for rep in range(args.reps) for d in DISTANCES for n in NOISE_TYPES]
    print(f"command: {command_line()}")
    print(
        f"bundles ({len(bundles)}): {', '.join(bundles)}; best = {config.best_bundle}; "
        f"methods: {', '.join(config.methods) or 'none'}; {args.reps} repetitions x "
        f"{len(DISTANCES)} distances x {len(NOISE_TYPES)} noise types = {len(cases)} cases; "
        f"image {IMAGE_SIZE[0]}x{IMAGE_SIZE[1]}; {args.workers} workers",
        flush=True,
    )
    began = time.perf_counter()
    rows: list[dict[str, Any]] = []
    tasks = [(case, config) for case in cases]
    context = multiprocessing.get_context("spawn")
    with context.Pool(args.workers, initializer=_limit_threads) as pool:
        for done, case_rows in enumerate(pool.imap_unordered(run_case, tasks), start=1):
            rows.extend(case_rows)
            if done % max(1, len(tasks) // 20) == 0 or done == len(tasks):
                elapsed = time.perf_counter() - began
                eta = elapsed / done * (len(tasks) - done)
                print(
                    f"  {done}/{len(tasks)} cases, {elapsed:.0f} s elapsed, ~{eta:.0f} s left",
                    file=sys.stderr,
                    flush=True,
                )
    wall = time.perf_counter() - began
    csv_path = write_csv(rows, stamp)
    print()
    print(report(rows, config))
    print()
    print(f"raw results: {csv_path}")
    if overlay_dir is not None:
        print(f"overlays of product runs >= {SUB_PX:g} px: {overlay_dir}")
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(
        f"total wall time: {wall:.0f} s ({wall / 60:.1f} min) on {args.workers} workers; "
        f"load average (1, 5, 15 min) at the end: {load}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
