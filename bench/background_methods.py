"""Which background estimator removes the players better? Synthetic clips with a known empty court.

For each clip (court rendered with a known camera, textured, players moving over the floor), the
player-free truth is `render_court_image` with the same seed. Per method: mean absolute error over
all pixels and over the pixels a player or shadow ever touched, the share of touched pixels still
off by more than 10 grey levels, spurious edge pixels (edges of the estimate more than 2 px from any
edge of the truth, i.e. player remnants the edge map would see), and the run time.

    .venv/bin/python -m bench.background_methods [--size 1280x720] [--seeds 3]
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from app.calib import background, edges, synthetic


def _spurious_edges(estimate: np.ndarray, truth: np.ndarray) -> int:
    truth_edges = edges.extract_edges(truth)
    near_truth = cv2.dilate(truth_edges, np.ones((5, 5), np.uint8)) > 0
    return int(np.count_nonzero((edges.extract_edges(estimate) > 0) & ~near_truth))


def evaluate(size: tuple[int, int], n_frames: int, n_players: int, seed: int) -> list[dict]:
    genome = synthetic.typical_target_camera(size)
    frames = synthetic.render_clip_frames(genome, size, n_frames, seed, n_players=n_players)
    truth = synthetic.render_court_image(genome, size, rng=seed)
    touched = np.zeros(truth.shape[:2], bool)
    for frame in frames:
        touched |= cv2.absdiff(frame, truth).max(axis=2) > 0
    rows = []
    for method in background.METHODS:
        start = time.perf_counter()
        estimate, moving = background.background_from_frames(frames, method=method)
        elapsed = time.perf_counter() - start
        error = cv2.absdiff(estimate, truth).max(axis=2).astype(np.float64)
        rows.append(
            {
                "method": method,
                "mae_all": float(error.mean()),
                "mae_touched": float(error[touched].mean()) if touched.any() else 0.0,
                "bad_touched_pct": 100.0 * float((error[touched] > 10).mean())
                if touched.any()
                else 0.0,
                "spurious_edges": _spurious_edges(estimate, truth),
                "mask_pct": 100.0 * float((moving > 0).mean()),
                "seconds": elapsed,
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    configs = [(5, 2), (9, 2), (15, 2), (15, 4)]
    print(
        f"{'frames':>6} {'players':>7} {'method':<22} {'MAE all':>8} {'MAE touched':>11} "
        f"{'touched >10':>11} {'spurious edges':>14} {'mask %':>7} {'time s':>7}"
    )
    for n_frames, n_players in configs:
        per_method: dict[str, list[dict]] = {}
        for seed in range(args.seeds):
            for row in evaluate((width, height), n_frames, n_players, seed):
                per_method.setdefault(row["method"], []).append(row)
        for method, rows in per_method.items():
            mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "method"}
            print(
                f"{n_frames:>6} {n_players:>7} {method:<22} {mean['mae_all']:>8.3f} "
                f"{mean['mae_touched']:>11.2f} {mean['bad_touched_pct']:>10.2f}% "
                f"{mean['spurious_edges']:>14.0f} {mean['mask_pct']:>7.2f} {mean['seconds']:>7.3f}"
            )
    print(f"size {width}x{height}, mean over seeds 0..{args.seeds - 1}")


if __name__ == "__main__":
    main()
