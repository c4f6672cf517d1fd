"""Which background estimator removes the players better? Synthetic clips with a known empty court.

For each clip (court rendered with a known camera, textured, players moving over the floor), the
player-free truth is `render_court_image` with the same seed. By default each frame also gets its
own sensor noise and goes through an MPEG-4 encode/decode, as an uploaded clip would (`--raw`: the
rendered frames as they are, whose static pixels are identical in every frame). Per method: mean absolute error over
all pixels and over the pixels a player or shadow ever touched, the share of touched pixels still
off by more than 10 grey levels, spurious edge pixels (edges of the estimate more than 2 px from any
edge of the truth, i.e. player remnants the edge map would see), the run time, and the mean reprojection error on the 16x16 floor grid (G_p, px) of a camera
calibrated from that background (the number that matters; inf = "court not found").

    .venv/bin/python -m bench.background_methods [--size 1280x720] [--seeds 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from app.calib import background, court, edges, pipeline, scene, synthetic


def _spurious_edges(estimate: np.ndarray, truth: np.ndarray) -> int:
    truth_edges = edges.extract_edges(truth)
    near_truth = cv2.dilate(truth_edges, np.ones((5, 5), np.uint8)) > 0
    return int(np.count_nonzero((edges.extract_edges(estimate) > 0) & ~near_truth))


def _through_camera_and_codec(frames: list[np.ndarray], seed: int) -> list[np.ndarray]:
    """Fresh sensor noise per frame (sigma 2 grey levels), then an MPEG-4 encode/decode round trip."""
    rng = np.random.default_rng(1000 + seed)
    noisy = [np.clip(f + rng.normal(0, 2.0, f.shape), 0, 255).astype(np.uint8) for f in frames]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "clip.mp4"
        scene.write_video(noisy, path)
        capture = cv2.VideoCapture(str(path))
        decoded = []
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            decoded.append(frame)
        capture.release()
    return decoded


def evaluate(
    size: tuple[int, int],
    n_frames: int,
    n_players: int,
    seed: int,
    video: bool,
    calibrate: bool,
) -> list[dict]:
    genome = synthetic.typical_target_camera(size)
    frames = scene.render_clip_frames(genome, size, n_frames, seed, n_players=n_players)
    truth = scene.render_court_image(genome, size, rng=seed)
    touched = np.zeros(truth.shape[:2], bool)
    for frame in frames:
        touched |= cv2.absdiff(frame, truth).max(axis=2) > 0
    candidates: dict[str, tuple[np.ndarray, np.ndarray, float]] = {}
    if video:
        frames = _through_camera_and_codec(frames, seed)
        # what the best estimator could reach: the mean of the same clip without players
        empty = _through_camera_and_codec([truth] * n_frames, seed)
        oracle = np.clip(np.rint(np.mean(empty, axis=0)), 0, 255).astype(np.uint8)
        candidates["oracle: empty clip mean"] = (oracle, np.zeros(oracle.shape[:2], np.uint8), 0.0)
    for method in background.METHODS:
        start = time.perf_counter()
        estimate, moving = background.background_from_frames(frames, method=method)
        candidates[method] = (estimate, moving, time.perf_counter() - start)
    rows = []
    model = court.court_model()
    for method, (estimate, moving, elapsed) in candidates.items():
        fit_px = float("nan")
        if calibrate:
            try:
                # no time budget: the GA's own stopping rules, so the result is reproducible
                result = pipeline.calibrate(estimate, moving_mask=moving if moving.any() else None)
                fit_px = synthetic.protocol_errors(genome, result.genome, model)["G_p"]
            except pipeline.CourtNotFound:
                fit_px = float("inf")
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
                "floor_grid_px": fit_px,
                "seconds": elapsed,
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument(
        "--raw",
        action="store_true",
        help="use the rendered frames as they are (no noise, no codec)",
    )
    parser.add_argument(
        "--no-calibrate",
        action="store_true",
        help="skip calibrating from each background (the G_p column)",
    )
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    configs = [(5, 2), (9, 2), (15, 2), (15, 4)]
    print(
        f"{'frames':>6} {'players':>7} {'method':<24} {'MAE all':>8} {'MAE touched':>11} "
        f"{'touched >10':>11} {'spurious edges':>14} {'mask %':>7} {'time s':>7} "
        f"{'G_p px':>7}"
    )
    for n_frames, n_players in configs:
        per_method: dict[str, list[dict]] = {}
        for seed in range(args.seeds):
            for row in evaluate(
                (width, height), n_frames, n_players, seed, not args.raw, not args.no_calibrate
            ):
                per_method.setdefault(row["method"], []).append(row)
        for method, rows in per_method.items():
            mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "method"}
            print(
                f"{n_frames:>6} {n_players:>7} {method:<24} {mean['mae_all']:>8.3f} "
                f"{mean['mae_touched']:>11.2f} {mean['bad_touched_pct']:>10.2f}% "
                f"{mean['spurious_edges']:>14.0f} {mean['mask_pct']:>7.2f} {mean['seconds']:>7.3f} "
                f"{mean['floor_grid_px']:>7.2f}"
            )
    source = "rendered frames" if args.raw else "frames + sensor noise + MPEG-4 round trip"
    print(f"size {width}x{height}, {source}, mean over seeds 0..{args.seeds - 1}")


if __name__ == "__main__":
    main()
