"""Accuracy on real, hand-annotated court images: `python -m bench.real DATA_DIR [--seeds 3]`.

For every `NAME.json` in DATA_DIR (format: DATA_DIR/KEYPOINTS.md) with its image, this runs
`pipeline.calibrate`
  (a) "default": from no start camera, i.e. the full pipeline (start search, GA, refinement);
  (b) "at check_fit": started exactly at the annotation's `check_fit` camera, to see how far the
      edge fitness pulls a camera off the hand-fitted one (drift);
and prints, per run, the floor error (cm) of the annotated floor keypoints (their pixels mapped
to the floor through the calibrated camera, against their court positions) and the reprojection
error (px) of all annotated keypoints, for the refined camera and for the GA's own camera before
refinement; then the quality's inlier excess, which camera the refinement started from ("ga",
"ga_simple_lens" or "start") and the wall time. The `check_fit` camera's own numbers are the
limit (it was fitted to these points). A refused calibration (CourtNotFound) shows the numbers
of the camera it refused.

The data are not part of the repository and must stay where they are; nothing here is tuned on
them.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from app.calib import camera, pipeline
from app.calib.court import court_model


@dataclass(frozen=True)
class Annotation:
    name: str
    image: np.ndarray
    names: list[str]
    pixels: np.ndarray  # (K, 2) annotated pixels
    points: np.ndarray  # (K, 3) court positions of the same keypoints
    check_fit: np.ndarray  # genome


def load_annotations(data_dir: Path) -> list[Annotation]:
    model = court_model()
    nodes = model.keypoints()
    out = []
    for path in sorted(data_dir.glob("*.json")):
        doc = json.loads(path.read_text())
        image = cv2.imread(str(data_dir / doc["image"]), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise SystemExit(f"cannot read {doc['image']} next to {path}")
        names = [n for n in doc["keypoints"] if n in nodes]
        unknown = set(doc["keypoints"]) - set(names)
        if unknown:
            print(f"{path.name}: ignoring keypoints not in the court model: {sorted(unknown)}")
        genome, _ = camera.camera_from_json(doc["check_fit"])
        out.append(
            Annotation(
                name=path.stem,
                image=image,
                names=names,
                pixels=np.array([doc["keypoints"][n] for n in names], dtype=np.float64),
                points=np.array([nodes[n] for n in names]),
                check_fit=genome,
            )
        )
    return out


def errors(genome: np.ndarray, ann: Annotation) -> tuple[np.ndarray, np.ndarray]:
    """Floor errors (cm) of the floor keypoints and reprojection errors (px) of all keypoints."""
    on_floor = ann.points[:, 2] == 0.0
    floor, status = camera.pixel_to_floor(genome, ann.pixels[on_floor])
    floor_cm = np.where(
        status == camera.RAY_OK,
        100.0 * np.linalg.norm(floor - ann.points[on_floor, :2], axis=1),
        np.inf,
    )
    projected = camera.project_visible(genome, ann.points)
    reprojection_px = np.linalg.norm(projected - ann.pixels, axis=1)
    reprojection_px[~np.isfinite(reprojection_px)] = np.inf
    return floor_cm, reprojection_px


def _stats(values: np.ndarray) -> str:
    if len(values) == 0:
        return f"{'-':>7} {'-':>7}"
    return f"{np.median(values):7.1f} {np.max(values):7.1f}"


HEADER = (
    f"{'image':<14} {'run':<13} {'seed':>4} | {'floor cm':^15} | {'reproj px':^15} | "
    f"{'GA floor cm':^15} | {'GA reproj px':^15} | {'excess':>6} {'from':<14} {'s':>5}\n"
    f"{'':<14} {'':<13} {'':>4} | {'median':>7} {'max':>7} | {'median':>7} {'max':>7} | "
    f"{'median':>7} {'max':>7} | {'median':>7} {'max':>7} |"
)


def run(data_dir: Path, seeds: int, time_budget_s: float | None) -> None:
    annotations = load_annotations(data_dir)
    if not annotations:
        raise SystemExit(f"no *.json annotations in {data_dir}")
    print(HEADER)
    for ann in annotations:
        floor_cm, reproj_px = errors(ann.check_fit, ann)
        n_floor = len(floor_cm)
        print(
            f"{ann.name:<14} {'check_fit':<13} {'':>4} | {_stats(floor_cm)} | "
            f"{_stats(reproj_px)} | {'(the limit; fitted to these points)':<33} | "
            f"{n_floor} floor / {len(reproj_px)} keypoints"
        )
        for label, start in (("default", None), ("at check_fit", ann.check_fit)):
            for seed in range(seeds):
                t0 = time.perf_counter()
                try:
                    result = pipeline.calibrate(
                        ann.image, start_genome=start, seed=seed, time_budget_s=time_budget_s
                    )
                except pipeline.CourtNotFound as exc:
                    # what the refused camera would have been, so refusals can be judged too
                    line = f"{ann.name:<14} {label:<13} {seed:>4} | "
                    if exc.genome is not None:
                        floor_cm, reproj_px = errors(exc.genome, ann)
                        line += f"{_stats(floor_cm)} | {_stats(reproj_px)} | "
                    print(f"{line}REFUSED: {exc} ({time.perf_counter() - t0:.1f} s)")
                    continue
                elapsed = time.perf_counter() - t0
                floor_cm, reproj_px = errors(result.genome, ann)
                ga_floor_cm, ga_reproj_px = errors(result.ga_genome, ann)
                print(
                    f"{ann.name:<14} {label:<13} {seed:>4} | {_stats(floor_cm)} | "
                    f"{_stats(reproj_px)} | {_stats(ga_floor_cm)} | {_stats(ga_reproj_px)} | "
                    f"{result.quality['inlier_excess']:6.2f} {result.refined_from:<14} "
                    f"{elapsed:5.1f}"
                )
        sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.real", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "data_dir", type=Path, help="folder of annotated images (NAME.json + image)"
    )
    parser.add_argument("--seeds", type=int, default=3, help="seeds per run (default 3)")
    parser.add_argument(
        "--time-budget", type=float, default=None, help="calibrate's time budget (s), default none"
    )
    args = parser.parse_args(argv)
    if not args.data_dir.is_dir():
        parser.error(f"not a directory: {args.data_dir}")
    run(args.data_dir, args.seeds, args.time_budget)
    return 0


if __name__ == "__main__":
    sys.exit(main())
