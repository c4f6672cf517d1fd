"""Time of one calibration per stage, with the scoring kernels on one thread and split over the
machine's threads (`app.calib.parallel`), in the same run:

    python -m bench.calibration_speed [--cases 6] [--threads 2]

Cases are seeded synthetic 1080p frames of several classes (`app.calib.cases`), calibrated with no
start camera, as an upload is. Each case runs with one thread and with `--threads`, alternately,
after a warm-up calibration (compiled code loaded); the camera must be the same bit for bit (the
split changes who computes a row, not how). Printed: per stage (`timings_s`: edges, search,
refine, total) the median seconds for each thread count and their ratio.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from bench.common import command_line, format_table

CLASSES = ("broadcast_glass", "club", "tripod_phone", "corner_side", "zoomed", "wide_angle")
STAGES = ("edges", "search", "refine", "total")


def calibrate_timed(image: np.ndarray, spec: str) -> tuple[dict[str, float], np.ndarray | None]:
    from app.calib import pipeline

    t0 = time.perf_counter()
    try:
        result = pipeline.calibrate(image, spec=spec)
        timings, genome = dict(result.timings_s), result.genome
    except pipeline.CourtNotFound as exc:
        # refused cameras cost the same stages; their timings are not reported by the exception
        timings, genome = {}, exc.genome
    timings["total"] = time.perf_counter() - t0
    return timings, genome


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=6, help="cases (1080p frames) to time")
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--first-seed", type=int, default=1000)
    args = parser.parse_args()

    from app.calib import cases, parallel

    frames = []
    seed = args.first_seed
    while len(frames) < args.cases:
        for name in CLASSES:
            plan = cases.plan_case(name, seed)
            if plan.size == (1920, 1080) and len(frames) < args.cases:
                case = cases.make_case(name, seed)
                frames.append((f"{name} {seed}", case.image, case.spec))
        seed += 1
    calibrate_timed(frames[0][1], frames[0][2])  # warm-up: load the compiled code

    per_threads: dict[int, list[dict[str, float]]] = {1: [], args.threads: []}
    rows = []
    for label, image, spec in frames:
        genomes = {}
        for threads in (1, args.threads):
            os.environ["SQUASHCAL_KERNEL_THREADS"] = str(threads)
            timings, genomes[threads] = calibrate_timed(image, spec)
            per_threads[threads].append(timings)
        same = (genomes[1] is None and genomes[args.threads] is None) or (
            genomes[1] is not None
            and genomes[args.threads] is not None
            and np.array_equal(genomes[1], genomes[args.threads])
        )
        rows.append(
            [
                label,
                f"{per_threads[1][-1]['total']:.2f}",
                f"{per_threads[args.threads][-1]['total']:.2f}",
                "yes" if same else "NO",
            ]
        )
    os.environ.pop("SQUASHCAL_KERNEL_THREADS", None)
    print(f"command: {command_line()}")
    print(f"threads available to this process: {parallel.thread_count()}")
    print(
        format_table(
            ["case (1920x1080)", "1 thread s", f"{args.threads} threads s", "same camera"], rows
        )
    )
    print()
    stage_rows = []
    for stage in STAGES:
        one = [t[stage] for t in per_threads[1] if stage in t]
        many = [t[stage] for t in per_threads[args.threads] if stage in t]
        if not one or not many:
            continue
        m1, mn = statistics.median(one), statistics.median(many)
        stage_rows.append([stage, len(one), f"{m1:.2f}", f"{mn:.2f}", f"{m1 / mn:.2f}"])
    print(
        format_table(
            ["stage", "n", "median s, 1 thread", f"median s, {args.threads} threads", "speed-up"],
            stage_rows,
        )
    )


if __name__ == "__main__":
    main()
