"""GA speed as the paper reports it (section VII-A4): milliseconds per generation.

    python -m bench.speed [--repeats 5] [--generations 2000] [--use-cache]

For N = 8, 16, 32 at 800x600 and 1920x1080: a whole `run_ga` (all operators, fitness, Python-side
chunking) on a realistic map (the court of a typical camera rendered by `render.rasterize_court`,
plus random false lines and salt), from a Table 3 "medium" start, with termination only by the
generation cap. Reported: the median over repeats of elapsed / generations after a warm-up run,
next to the paper's numbers, and the fitness alone (one compiled call for N genomes).

By default numba's cache is pointed at a fresh temporary directory, so the reported compile time is
a real JIT compile; `--use-cache` keeps the normal on-disk cache (then it is mostly a cache load).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

PAPER_MS = {(800, 600): (5.2, 9.8, 21.8), (1920, 1080): (18.4, 32.9, 66.6)}
POPULATION_SIZES = (8, 16, 32)


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
                result = run_ga(
                    fmap,
                    samples,
                    start,
                    bundle=bundle,
                    seed=args.seed + repeat,
                    stall_generations=10**9,
                    max_generations=args.generations,
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
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(
        f"single-threaded; cpus: {os.cpu_count()}; load average (1, 5, 15 min) at the end: {load}"
    )


if __name__ == "__main__":
    main()
