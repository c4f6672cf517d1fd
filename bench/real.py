"""Accuracy on real, hand-annotated court images: `python -m bench.real DATA_DIR [--hint]`.

For every `NAME.json` in DATA_DIR (format: DATA_DIR/KEYPOINTS.md) with its image, this runs
`pipeline.calibrate` from no start camera (the product's path: line evidence, search, polish,
verdict; the pipeline is deterministic) and, with `--hint`, once more with the annotation's
`check_fit` camera given as a start hint (how far the evidence pulls a camera off the
hand-fitted one). It prints, per run, the verdict, the floor error (cm) of the annotated floor
keypoints (their pixels mapped to the floor through the calibrated camera, against their court
positions), the reprojection error (px) of all annotated keypoints, the floor error at the T the
calibration itself reports (one standard deviation), the camera model chosen and the wall time.
An annotation with a `media` clip is calibrated from the clip as an upload is: its background
and moving mask come from the worker's background stage (`worker.main.clip_background`, the
service's default settings), not from the annotated still; that stage runs once per annotation
and its time is printed on a line of its own, apart from each run's. The `check_fit` camera's
own numbers are the limit (it was fitted to these points). A refused calibration (CourtNotFound)
shows the numbers of the camera it refused. The verdict's figures
of every no-start run go to a CSV in bench/out (the verdict is a pure function of them).

A camera is counted RIGHT when its median floor error is at most RIGHT_FLOOR_CM; the summary
gives, over the images: right and accepted (found), wrong but accepted (the failure that
matters: a coach would trust it), and refused; and how many accepted cameras meet issue 6's
target (median floor error <= TARGET_MEDIAN_CM and worst <= TARGET_WORST_CM).

The data are not part of the repository and must stay where they are; nothing here is tuned on
them.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from app.calib import camera, pipeline
from app.calib.court import court_model
from app.settings import Settings
from bench.common import out_path
from worker.main import clip_background


@dataclass(frozen=True)
class Annotation:
    name: str
    image: np.ndarray
    names: list[str]
    pixels: np.ndarray  # (K, 2) annotated pixels
    points: np.ndarray  # (K, 3) court positions of the same keypoints
    check_fit: np.ndarray  # genome
    media: Path | None  # a clip to calibrate from (its background), None for a still


def calibration_input(ann: Annotation) -> tuple[np.ndarray, np.ndarray | None, str]:
    """(picture, moving mask or None, what it is) as the worker would hand them to the pipeline."""
    if ann.media is None:
        return ann.image, None, ""
    background, moving_mask, info = clip_background(ann.media, Settings())
    ranges = ", ".join(f"{a:g}-{b:g}" for a, b in info["time_ranges_s"])
    described = f"clip: {info['shots']} shots, background from {ranges} s"
    return background, (moving_mask if np.any(moving_mask) else None), described


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
        media = data_dir / doc["media"] if doc.get("media") else None
        if media is not None and not media.is_file():
            raise SystemExit(f"cannot read {doc['media']} next to {path}")
        out.append(
            Annotation(
                name=path.stem,
                image=image,
                names=names,
                pixels=np.array([doc["keypoints"][n] for n in names], dtype=np.float64),
                points=np.array([nodes[n] for n in names]),
                check_fit=genome,
                media=media,
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


RIGHT_FLOOR_CM = 10.0
TARGET_MEDIAN_CM = 5.0
TARGET_WORST_CM = 15.0


def _stats(values: np.ndarray) -> str:
    if len(values) == 0:
        return f"{'-':>7} {'-':>7}"
    return f"{np.median(values):7.1f} {np.max(values):7.1f}"


HEADER = (
    f"{'image':<20} {'run':<9} {'verdict':<11} | {'floor cm':^15} | {'reproj px':^15} | "
    f"{'T +-cm':>6} {'model':<20} {'s':>5}\n"
    f"{'':<20} {'':<9} {'':<11} | {'median':>7} {'max':>7} | {'median':>7} {'max':>7} |"
)


def run(data_dir: Path, with_hint: bool) -> None:
    annotations = load_annotations(data_dir)
    if not annotations:
        raise SystemExit(f"no *.json annotations in {data_dir}")
    print(HEADER)
    tally = {"found": 0, "wrong accepted": 0, "refused (right camera)": 0, "refused": 0}
    on_target = 0
    rows: list[dict[str, object]] = []
    for ann in annotations:
        floor_cm, reproj_px = errors(ann.check_fit, ann)
        print(
            f"{ann.name:<20} {'limit':<9} {'check_fit':<11} | {_stats(floor_cm)} | "
            f"{_stats(reproj_px)} | {len(floor_cm)} floor / {len(reproj_px)} keypoints"
        )
        runs = [("no start", None)] + ([("hint", ann.check_fit)] if with_hint else [])
        t0 = time.perf_counter()
        picture, moving_mask, described = calibration_input(ann)
        if described:
            print(f"{ann.name:<20} {'':<9} {described} ({time.perf_counter() - t0:.1f} s)")
        for label, start in runs:
            t0 = time.perf_counter()
            try:
                result = pipeline.calibrate(picture, start_genome=start, moving_mask=moving_mask)
            except pipeline.CourtNotFound as exc:
                line = f"{ann.name:<20} {label:<9} {'REFUSED':<11} | "
                right = False
                if exc.genome is not None:
                    floor_cm, reproj_px = errors(exc.genome, ann)
                    right = bool(np.median(floor_cm) <= RIGHT_FLOOR_CM)
                    line += f"{_stats(floor_cm)} | {_stats(reproj_px)} | "
                if label == "no start":
                    tally["refused (right camera)" if right else "refused"] += 1
                    rows.append(
                        {"image": ann.name, "accepted": 0, "right": int(right)} | exc.quality
                    )
                reasons = "; ".join(exc.reasons) or str(exc)
                print(f"{line}{time.perf_counter() - t0:5.1f} s: {reasons[:160]}")
                continue
            elapsed = time.perf_counter() - t0
            floor_cm, reproj_px = errors(result.genome, ann)
            right = bool(np.median(floor_cm) <= RIGHT_FLOOR_CM)
            if label == "no start":
                tally["found" if right else "wrong accepted"] += 1
                on_target += bool(
                    np.median(floor_cm) <= TARGET_MEDIAN_CM and np.max(floor_cm) <= TARGET_WORST_CM
                )
                rows.append(
                    {"image": ann.name, "accepted": 1, "right": int(right)} | result.quality
                )
            t_cm = result.uncertainty["floor_error_cm"]["T"]
            t_text = f"{t_cm:6.1f}" if t_cm is not None else f"{'-':>6}"
            print(
                f"{ann.name:<20} {label:<9} {result.verdict.label:<11} | {_stats(floor_cm)} | "
                f"{_stats(reproj_px)} | {t_text} {result.camera_model:<20} {elapsed:5.1f}"
            )
        sys.stdout.flush()
    total = len(annotations)
    print(f"\nno start camera, {total} images (right = median floor error <= {RIGHT_FLOOR_CM} cm):")
    for key, count in tally.items():
        print(f"  {key:<24} {count:>3}/{total}")
    print(
        f"  {'accepted on target':<24} {on_target:>3}/{total}"
        f"  (median <= {TARGET_MEDIAN_CM:g} cm and worst <= {TARGET_WORST_CM:g} cm)"
    )
    path = out_path(f"real_{time.strftime('%Y%m%d_%H%M%S')}.csv")
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    print(f"verdict figures per image: {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.real", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "data_dir", type=Path, help="folder of annotated images (NAME.json + image)"
    )
    parser.add_argument(
        "--hint", action="store_true", help="also run with the check_fit camera as a start hint"
    )
    args = parser.parse_args(argv)
    if not args.data_dir.is_dir():
        parser.error(f"not a directory: {args.data_dir}")
    run(args.data_dir, args.hint)
    return 0


if __name__ == "__main__":
    sys.exit(main())
