"""GA speed as the paper reports it (section VII-A4): milliseconds per generation.

    python -m bench.speed [--repeats 5] [--generations 2000] [--use-cache]

For N = 8, 16, 32 at 800x600 and 1920x1080: a whole `run_ga` (all operators, fitness, Python-side
chunking) on a realistic map (the court of a typical camera rendered by `render.rasterize_court`,
plus random false lines and salt), from a Table 3 "medium" start, with termination only by the
generation cap. Reported: the median over repeats of elapsed / generations after a warm-up run,
next to the paper's numbers, and the fitness alone (one compiled call for N genomes).

Then the GA inside a real calibration, in the same run: `pipeline.calibrate(image, start_genome=
start, bundle=<N = 16 default bundle>)` on a 1080p edge image (the typical camera's court with
salt), its per-generation time as the product reports it (`timings_s["ga_per_generation_ms"]`),
beside `run_ga` alone replayed on exactly the inputs the calibration gave it (same map, start,
seed and bundle: the same generations, bit for bit) and beside the run_ga row above; the ratios
say what the calibration adds per generation. The standard row is run again between the
calibrations (the machine is shared: load changes over a minute). Once-per-process costs (loading
the compiled code) are measured in a fresh process and printed apart.

By default numba's cache is pointed at a fresh temporary directory, so the reported compile time is
a real JIT compile; `--use-cache` keeps the normal on-disk cache (then it is mostly a cache load).
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from typing import Any
from unittest import mock

PAPER_MS = {(800, 600): (5.2, 9.8, 21.8), (1920, 1080): (18.4, 32.9, 66.6)}
POPULATION_SIZES = (8, 16, 32)
CALIBRATION_SIZE = (1920, 1080)
TARGET_RATIO = 1.2  # issue 6: GA per generation inside a calibration vs run_ga alone


def capped_run(
    fmap: Any, samples: Any, start: Any, bundle: Any, seed: int, generations: int
) -> Any:
    """run_ga stopped by the generation cap alone (the rows' setting): a GAResult."""
    from app.calib.ga import run_ga

    return run_ga(
        fmap,
        samples,
        start,
        bundle=bundle,
        seed=seed,
        stall_generations=10**9,
        max_generations=generations,
    )


def calibration_case() -> tuple[Any, Any]:
    """(1080p edge image, start camera) of the in-calibration row: the typical camera's court
    with salt, and a Table 3 medium start (fixed seeds: every run measures the same case)."""
    from app.calib import court, synthetic

    target = synthetic.typical_target_camera(CALIBRATION_SIZE)
    image = synthetic.add_noise(
        synthetic.render_edge_image(target, court.court_model(), CALIBRATION_SIZE), "salt", 0
    )
    return image, synthetic.wiggle_camera(target, "medium", 0)


@dataclasses.dataclass(frozen=True)
class GACall:
    """What the pipeline passed to run_ga and what it got back."""

    args: tuple[Any, ...]
    kwargs: dict[str, Any]
    result: Any  # GAResult


def calibrate_with_ga(
    image: Any, start: Any, seed: int, max_generations: int | None = None
) -> tuple[Any, GACall]:
    """`pipeline.calibrate` with the default (N = 16) bundle: (its result, its run_ga call).
    `max_generations` None keeps the pipeline's default."""
    from app.calib import pipeline
    from app.calib.ga import DEFAULT_BUNDLE, run_ga

    calls: list[GACall] = []

    def recording_run_ga(*args: Any, **kwargs: Any) -> Any:
        result = run_ga(*args, **kwargs)
        calls.append(GACall(args, dict(kwargs), result))
        return result

    with mock.patch.object(pipeline, "run_ga", recording_run_ga):
        limit = {} if max_generations is None else {"max_generations": max_generations}
        result = pipeline.calibrate(
            image, start_genome=start, bundle=DEFAULT_BUNDLE.name, seed=seed, **limit
        )
    (call,) = calls
    return result, call


def fresh_process_calibration() -> dict[str, float]:
    """One calibration with the GA in a fresh process (what `squashcal calibrate` pays): its
    timings_s, the GA's own code load and run time per generation."""
    image, start = calibration_case()
    result, call = calibrate_with_ga(image, start, 0)
    ga = call.result
    return {
        **{f"timings_s.{k}": v for k, v in result.timings_s.items()},
        "run_ga code_load_s": ga.code_load_s,
        "run_ga ms/gen": 1e3 * ga.elapsed_s / ga.generations,
        "generations": float(ga.generations),
    }


def ga_in_calibration_rows(
    repeats: int, standard_run: Callable[[int], tuple[float, int]]
) -> list[tuple[str, float, float]]:
    """(row, ms per generation, generations) medians over `repeats` calibrations: the product's
    own figure (the whole GA stage over its generations), the run_ga call's own elapsed_s (the
    run inside the calibration, progress callback included), run_ga alone replayed on the
    calibration's inputs without the progress callback, and `standard_run(repeat)` (ms per
    generation and generations of one run of the standard run_ga row) measured between them,
    so that the shared machine's load weighs on all rows alike."""
    from app.calib.ga import run_ga

    image, start = calibration_case()
    calibrate_with_ga(image, start, 0)  # warm-up: every stage's compiled code loaded
    in_calibration, own, replayed, standard, generations = [], [], [], [], []
    standard_generations = []
    for repeat in range(repeats):
        ms, count = standard_run(repeat)
        standard.append(ms)
        standard_generations.append(count)
        result, call = calibrate_with_ga(image, start, repeat)
        in_calibration.append(result.timings_s["ga_per_generation_ms"])
        own.append(1e3 * call.result.elapsed_s / call.result.generations)
        kwargs = {k: v for k, v in call.kwargs.items() if k != "progress"}
        alone = run_ga(*call.args, **kwargs)
        if alone.generations != result.generations:
            raise RuntimeError("the replay did not repeat the calibration's GA run")
        replayed.append(1e3 * alone.elapsed_s / alone.generations)
        generations.append(result.generations)
    n = statistics.median(generations)
    return [
        ("inside calibrate (timings_s)", statistics.median(in_calibration), n),
        ("its run_ga call (elapsed_s)", statistics.median(own), n),
        ("run_ga alone, same inputs", statistics.median(replayed), n),
        (
            "standard run_ga row, interleaved",
            statistics.median(standard),
            statistics.median(standard_generations),
        ),
    ]


def _parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per configuration")
    parser.add_argument("--generations", type=int, default=2000, help="generations per run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--use-cache", action="store_true", help="keep numba's on-disk cache")
    return parser.parse_args()


def main() -> None:
    args = _parse_args()
    if not args.use_cache:
        os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="squashcal-bench-numba-")

    # numba reads NUMBA_CACHE_DIR when it is imported: import after setting it
    import cv2
    import numpy as np

    from app.calib import court, fitness, render, synthetic
    from app.calib.ga import Bundle, bundle_fitness_map, run_ga

    def realistic_edges(genome: np.ndarray, size: tuple[int, int], rng: np.random.Generator):
        edges = render.rasterize_court(genome, model, size)
        for _ in range(20):
            p, q = rng.integers(0, size, 2), rng.integers(0, size, 2)
            cv2.line(edges, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), 255, 1)
        return synthetic.add_noise(edges, "salt", rng)

    model = court.court_model()
    rng = np.random.default_rng(args.seed)

    compile_started = time.perf_counter()
    warm_size = (800, 600)
    warm_target = synthetic.typical_target_camera(warm_size)
    warm_map = bundle_fitness_map(realistic_edges(warm_target, warm_size, rng))
    warm_samples = court.sample_edges(model, court.spacing_for_image(warm_size[0]))
    run_ga(warm_map, warm_samples, warm_target, max_generations=2)
    compile_s = time.perf_counter() - compile_started

    rows = []
    for size, paper in PAPER_MS.items():
        target = synthetic.typical_target_camera(size)
        start = synthetic.wiggle_camera(target, "medium", rng)
        samples = court.sample_edges(model, court.spacing_for_image(size[0]))
        arrays = fitness.sample_arrays(samples)
        for n, paper_ms in zip(POPULATION_SIZES, paper, strict=True):
            bundle = Bundle(population_size=n)
            fmap = bundle_fitness_map(realistic_edges(target, size, rng), bundle)
            run_ga(fmap, samples, start, bundle=bundle, max_generations=50)  # warm-up
            per_generation_ms = []
            cpu_ms = []
            reused = []
            for repeat in range(args.repeats):
                cpu_started = time.thread_time()
                result = capped_run(
                    fmap, samples, start, bundle, args.seed + repeat, args.generations
                )
                cpu_ms.append(1e3 * (time.thread_time() - cpu_started) / result.generations)
                per_generation_ms.append(1e3 * result.elapsed_s / result.generations)
                children = n + (result.generations - 1) * (n - 2)
                reused.append(1.0 - result.fitness_evaluations / children)
            # the fitness alone: one compiled call scoring the N genomes of a population
            pop = result.population
            out = np.empty(n)
            ws = fitness.make_workspace(samples.n_points)
            calls = 500
            fitness_ms = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                for _ in range(calls):
                    fitness.population_fitness_njit(
                        pop, arrays.xyz, arrays.joins_next, fmap, ws, out, 0
                    )
                fitness_ms.append(1e3 * (time.perf_counter() - t0) / calls)
            if size == CALIBRATION_SIZE and n == 16:
                standard_case = (fmap, samples, start, bundle)
            rows.append(
                (
                    f"{size[0]}x{size[1]}",
                    n,
                    samples.n_points,
                    statistics.median(per_generation_ms),
                    min(per_generation_ms),
                    statistics.median(cpu_ms),
                    paper_ms,
                    statistics.median(fitness_ms),
                    statistics.median(reused),
                )
            )

    print(
        f"GA speed, ms per generation: median (and min) of {args.repeats} runs x "
        f"{args.generations} generations, whole run_ga included"
    )
    header = (
        f"{'image':>10} {'N':>3} {'samples':>7} {'ours ms/gen':>12} {'(min)':>7} {'cpu':>6} "
        f"{'paper ms/gen':>13} {'speed-up':>9} {'fitness ms/call':>16} {'reused':>7}"
    )
    print(header)
    print("-" * len(header))
    for image, n, m, ours, ours_min, cpu, paper_ms, fit_ms, reuse in rows:
        print(
            f"{image:>10} {n:>3} {m:>7} {ours:>12.3f} {ours_min:>7.3f} {cpu:>6.3f} {paper_ms:>13.1f} "
            f"{paper_ms / ours:>8.0f}x {fit_ms:>16.3f} {reuse:>7.0%}"
        )
    print(
        "cpu: median thread CPU time per generation (what the code costs when it has a core to "
        "itself; wall time also holds waiting for a shared core)"
    )
    print(
        "fitness ms/call: one compiled call scoring all N genomes (no reuse); reused: share of "
        "children whose fitness was copied from an identical known genome"
    )
    cache_note = "on-disk cache" if args.use_cache else "fresh cache: full JIT compile"
    print(f"first run_ga call (JIT, {cache_note}): {compile_s:.1f} s, not included above")

    # the GA inside a real calibration, same process and run as the rows above
    def standard_run(repeat: int) -> tuple[float, int]:
        """One run of the 1920x1080, N = 16 row above (same map, start, bundle, cap)."""
        result = capped_run(*standard_case, args.seed + repeat, args.generations)
        return 1e3 * result.elapsed_s / result.generations, result.generations

    in_rows = ga_in_calibration_rows(args.repeats, standard_run)
    print()
    print(
        f"GA inside a calibration: 1920x1080, N = 16, from a medium start; median of "
        f"{args.repeats} repeats, each a run of the standard 1920x1080 N = 16 row, a "
        f"calibration and its replay in turn; target <= {TARGET_RATIO}x"
    )
    header = f"{'':>32} {'ms/gen':>7} {'generations':>11} {'/ same inputs':>14} {'/ standard':>11}"
    print(header)
    print("-" * len(header))
    same_inputs, standard = in_rows[2][1], in_rows[3][1]
    for name, ms, generations in in_rows:
        print(
            f"{name:>32} {ms:>7.3f} {generations:>11.0f} {ms / same_inputs:>13.2f}x "
            f"{ms / standard:>10.2f}x"
        )
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        fresh = pool.apply(fresh_process_calibration)
    print(
        "one calibration in a fresh process (what `squashcal calibrate` pays): "
        + ", ".join(f"{k} {v:.3f}" for k, v in fresh.items())
    )
    fresh_ratio = fresh["timings_s.ga_per_generation_ms"] / fresh["run_ga ms/gen"]
    print(
        f"  its timings_s per generation / its run_ga call's own: {fresh_ratio:.2f}x "
        f"(the difference is what the stage counts besides the generations)"
    )
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(
        f"single-threaded; cpus: {os.cpu_count()}; load average (1, 5, 15 min) at the end: {load}"
    )


if __name__ == "__main__":
    main()
