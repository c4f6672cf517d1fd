"""How long a calibration keeps other Python threads from running (the worker's heartbeat).

    .venv/bin/python -m bench.heartbeat_gap [--cases broadcast_glass:1001 club:1004]

A worker renews its job's lease from a thread while the calibration runs; compiled code that
holds the GIL stops that thread for as long as one call lasts, and a worker whose lease runs
out loses its job to another. For each synthetic case (app.calib.cases), after one calibration
to load the compiled code, a thread that sleeps 20 ms at a time runs beside a second calibration:
the table has its longest gap between ticks and how many gaps exceeded 0.5 s.
"""

from __future__ import annotations

import argparse
import contextlib
import threading
import time

from bench.common import command_line, format_table

TICK_S = 0.02
LONG_GAP_S = 0.5


def longest_gaps(image, spec: str) -> tuple[float, float, int]:
    """(calibration seconds, longest tick gap seconds, gaps over LONG_GAP_S) of one calibration."""
    from app.calib import pipeline

    def calibrate() -> None:
        # a refusal takes the same path through the compiled code
        with contextlib.suppress(pipeline.CourtNotFound):
            pipeline.calibrate(image, spec=spec)

    calibrate()
    gaps: list[float] = []
    stop = threading.Event()

    def tick() -> None:
        last = time.perf_counter()
        while not stop.is_set():
            time.sleep(TICK_S)
            now = time.perf_counter()
            gaps.append(now - last)
            last = now

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    t0 = time.perf_counter()
    calibrate()
    seconds = time.perf_counter() - t0
    stop.set()
    ticker.join()
    return seconds, max(gaps, default=0.0), sum(g > LONG_GAP_S for g in gaps)


def main(argv: list[str] | None = None) -> int:
    from app.calib import cases

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cases",
        nargs="*",
        default=["broadcast_glass:1001", "club:1004"],
        help="synthetic cases as class:seed",
    )
    args = parser.parse_args(argv)
    rows = []
    for name in args.cases:
        kind, seed = name.split(":")
        case = cases.make_case(kind, int(seed))
        seconds, longest, long_count = longest_gaps(case.image, case.spec)
        height, width = case.image.shape[:2]
        rows.append(
            [name, f"{width}x{height}", f"{seconds:.1f}", f"{longest:.2f}", str(long_count)]
        )
    print(command_line())
    print(
        format_table(
            ["case", "size", "calibration s", "longest tick gap s", f"gaps > {LONG_GAP_S} s"],
            rows,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
