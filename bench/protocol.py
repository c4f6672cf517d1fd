"""The paper's synthetic accuracy protocol (section VII) for a set of GA bundles, plus NLopt baselines.

For every start distance (Table 3: near, medium, far), noise type (Fig. 8) and repetition, the
typical target camera's court is rasterised at 1920 x 1080 (`synthetic.render_edge_image`), noise is
added, and a start camera is made by the wiggle operator (7 genes moved by +- the Table 3 offset).
Each selected bundle runs `run_ga` from that start; the result is scored by the mean reprojection
error (MRE) on the 16 x 16 floor grid G_p (and G_c, G_b). Each (distance, noise, repetition) has
its own seeded start and noise, shared by all bundles and methods, so they meet the same cases.

Tables printed:
  (a) Fig. 9: percentage of runs with G_p MRE under 2, 4, 6, 8, 10, 50 px by distance, by noise
      type, and per bundle; the paper's values where it states them.
  (b) Table 4: median generations until termination of runs under 10 px, noise x distance (n).
  (c) The best bundle (the default): median G_p MRE of runs under 10 px per distance.
  (d) Fig. 12: the best bundle against NLopt Subplex (LN_SBPLX) and DIRECT-L (GN_DIRECT_L), 100 000
      evaluations each, maximising the same fitness (`population_fitness` of a 1-row population on
      the best bundle's map) from the same starts. DIRECT-L needs a box: the start +- the far offsets
      of Table 3 (which always contains the target, since every wiggle is at most that far). Subplex
      gets the same box and the near offsets as its initial step.

Raw per-run results go to bench/out/protocol_<time>.csv.

    python -m bench.protocol                       # default bundles, default repetitions
    python -m bench.protocol --reps 32 --all       # the paper's full protocol (days on 2 cores)
    python -m bench.protocol --bundles NAME ... --reps 2 --no-nlopt
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import math
import multiprocessing
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
DEFAULT_REPS = 5
N_OTHER_BUNDLES = 5
NLOPT_EVALUATIONS = 100_000
NLOPT_METHODS = ("subplex", "direct_l")

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


@dataclasses.dataclass(frozen=True)
class Config:
    bundles: tuple[str, ...]
    best_bundle: str
    nlopt: bool
    nlopt_evaluations: int
    max_generations: int | None
    base_seed: int


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
) -> tuple[np.ndarray, float, int]:
    """Maximise `objective` from `start` with Subplex or DIRECT-L; (best genome, fitness, evals)."""
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
    with contextlib.suppress(nlopt.RoundoffLimited, nlopt.ForcedStop):
        opt.optimize(start.copy())
    return best_x, best_f, evaluations


def run_case(task: tuple[Case, Config]) -> list[dict[str, Any]]:
    """All bundles (and the NLopt methods) on one (distance, noise, repetition) case."""
    case, config = task
    from app.calib import court, synthetic
    from app.calib.fitness import population_fitness
    from app.calib.ga import bundle_fitness_map, get_bundle, run_ga

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
    maps: dict[bool, np.ndarray] = {}

    def fitness_map_for(bundle: Any) -> np.ndarray:
        if bundle.transformed_map not in maps:
            maps[bundle.transformed_map] = bundle_fitness_map(edges, bundle)
        return maps[bundle.transformed_map]

    rows = []
    for name in config.bundles:
        bundle = get_bundle(name)
        fmap = fitness_map_for(bundle)
        kwargs: dict[str, Any] = {}
        if config.max_generations is not None:
            kwargs["max_generations"] = config.max_generations
        result = run_ga(fmap, samples, start, bundle=bundle, seed=opt_seed, **kwargs)
        errors = synthetic.protocol_errors(target, result.genome, model)
        rows.append(
            {
                **common,
                "method": "ga",
                "bundle": name,
                **errors,
                "fitness": float(result.fitness),
                "target_fitness": float(population_fitness(target, samples, fmap)[0]),
                "generations": int(result.generations),
                "evaluations": int(result.generations) * bundle.population_size,
                "stop_reason": result.stop_reason,
                "elapsed_s": float(result.elapsed_s),
            }
        )
    if config.nlopt:
        fmap = fitness_map_for(get_bundle(config.best_bundle))

        def objective(x: np.ndarray) -> float:
            return float(population_fitness(x[None, :], samples, fmap)[0])

        for method in NLOPT_METHODS:
            began = time.perf_counter()
            genome, fitness, evaluations = run_nlopt(
                method, objective, start, config.nlopt_evaluations
            )
            errors = synthetic.protocol_errors(target, genome, model)
            rows.append(
                {
                    **common,
                    "method": method,
                    "bundle": config.best_bundle,
                    **errors,
                    "fitness": fitness,
                    "target_fitness": objective(target),
                    "generations": 0,
                    "evaluations": evaluations,
                    "stop_reason": "max_evaluations",
                    "elapsed_s": time.perf_counter() - began,
                }
            )
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


def report(rows: list[dict[str, Any]], config: Config) -> str:
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    ga = [r for r in rows if r["method"] == "ga"]
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

    if config.nlopt:
        out.append(
            f"(d) Fig. 12: median G_p MRE of runs < 10 px (n < 10 px / runs); GA = {config.best_bundle}, "
            f"NLopt with {config.nlopt_evaluations} evaluations on the same map and starts"
        )
        methods = ("ga", *NLOPT_METHODS)
        comparable = best + [r for r in rows if r["method"] in NLOPT_METHODS]

        def cell(group: list[dict[str, Any]]) -> str:
            good = [r["G_p"] for r in group if r["G_p"] < SUCCESS_PX]
            return f"{_median(good)} ({len(good)}/{len(group)})"

        fig12 = []
        for d in DISTANCES:
            fig12.append(
                [d]
                + [
                    cell([r for r in comparable if r["method"] == m and r["distance"] == d])
                    for m in methods
                ]
                + [" / ".join(str(PAPER_FIG12_MEDIAN[m][d]) for m in methods)]
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
                    [r["target_fitness"] - r["fitness"] for r in comparable if r["method"] == m],
                    0.0,
                )
                for m in methods
            ]
            + [""]
        )
        out.append(
            format_table(["", "GA", "Subplex", "DIRECT-L", "paper GA / Sbplx / DIRECT-L"], fig12)
        )
        out.append(
            "(fitness > target: runs that ended at a better fitness than the true camera has, "
            "i.e. where the fitness optimum, not the search, sets the error)"
        )
    return "\n".join(out)


def write_csv(rows: list[dict[str, Any]]) -> str:
    path = out_path(f"protocol_{datetime.now():%Y%m%d_%H%M%S}.csv")
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return str(path)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bundles", nargs="+", help="bundle names (default: best + 5 others)")
    parser.add_argument("--all", action="store_true", help="all 96 bundles")
    parser.add_argument("--reps", type=int, default=DEFAULT_REPS, help="repetitions per case")
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument("--no-nlopt", action="store_true", help="skip the NLopt comparison")
    parser.add_argument("--nlopt-evaluations", type=int, default=NLOPT_EVALUATIONS)
    parser.add_argument("--max-generations", type=int, default=None, help="GA generation cap")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the whole protocol")
    args = parser.parse_args(argv)

    from app.calib.ga import BUNDLES, DEFAULT_BUNDLE, get_bundle
    from app.calib.synthetic import DISTANCES, NOISE_TYPES

    if args.all:
        bundles = [DEFAULT_BUNDLE.name] + sorted(n for n in BUNDLES if n != DEFAULT_BUNDLE.name)
    elif args.bundles:
        try:
            bundles = [get_bundle(n).name for n in args.bundles]
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    else:
        bundles = default_bundles()
    if args.reps < 1 or args.workers < 1:
        print("error: --reps and --workers must be at least 1", file=sys.stderr)
        return 2
    config = Config(
        bundles=tuple(bundles),
        best_bundle=DEFAULT_BUNDLE.name,
        nlopt=not args.no_nlopt,
        nlopt_evaluations=args.nlopt_evaluations,
        max_generations=args.max_generations,
        base_seed=args.seed,
    )
    # repetition-major order, so an interrupted run still covers every cell evenly
    cases = [Case(d, n, rep) for rep in range(args.reps) for d in DISTANCES for n in NOISE_TYPES]
    print(f"command: {command_line()}")
    print(
        f"bundles ({len(bundles)}): {', '.join(bundles)}; best = {config.best_bundle}; "
        f"{len(cases)} cases x {len(bundles)} bundles = {len(cases) * len(bundles)} GA runs"
        + (f" + {len(cases) * len(NLOPT_METHODS)} NLopt runs" if config.nlopt else "")
        + f"; image {IMAGE_SIZE[0]}x{IMAGE_SIZE[1]}; {args.workers} workers",
        flush=True,
    )
    began = time.perf_counter()
    rows: list[dict[str, Any]] = []
    tasks = [(case, config) for case in cases]
    context = multiprocessing.get_context("spawn")
    with context.Pool(args.workers) as pool:
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
    csv_path = write_csv(rows)
    print()
    print(report(rows, config))
    print()
    print(f"raw results: {csv_path}")
    print(f"total wall time: {wall:.0f} s ({wall / 60:.1f} min) on {args.workers} workers")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
