"""`squashcal calibrate IMAGE --out RESULT.json`: calibrate a camera from one image.

Top-level imports stay light (argparse only): numba and OpenCV load when the command runs.
Every expected failure (unreadable image, bad camera JSON, unknown bundle, no court found,
unwritable output) ends with exit status 1 or 2 and ONE line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

EXIT_BAD_INPUT = 2
EXIT_COURT_NOT_FOUND = 3


class CliError(Exception):
    """An expected failure: its message is printed as the one line on stderr."""

    def __init__(self, message: str, status: int = EXIT_BAD_INPUT) -> None:
        super().__init__(message)
        self.status = status


def add_arguments(command: str, parser: argparse.ArgumentParser) -> None:
    parser.add_argument("image", metavar="IMAGE", help="court image (PNG/JPEG) or edge image")
    parser.add_argument(
        "--start",
        metavar="CAMERA.json",
        default=None,
        help="start camera: a genome (15 numbers), {'genome': [...]} or the OpenCV form "
        "(default: search typical camera placements)",
    )
    parser.add_argument(
        "--bundle",
        default=None,
        help="run the paper's GA with this strategy bundle between search and refinement, e.g. "
        "n16-tdm-roulette-single-dist (default: no GA)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--max-generations", type=int, default=None, help="GA generation cap (default: pipeline's)"
    )
    parser.add_argument(
        "--time-budget",
        type=float,
        default=None,
        metavar="S",
        help="the GA's wall-time budget in seconds (with --bundle)",
    )
    parser.add_argument(
        "--spec", default="wsf", help="court spec: wsf, psa or doubles (default wsf)"
    )
    parser.add_argument(
        "--out", required=True, metavar="RESULT.json", help="where to write the result"
    )
    parser.add_argument(
        "--overlay", default=None, metavar="OVERLAY.png", help="also draw the fitted court"
    )


def _read_image(path: str) -> Any:
    import cv2
    import numpy as np

    file = Path(path)
    if not file.is_file():
        raise CliError(f"image not found: {path}")
    try:
        data = np.fromfile(file, dtype=np.uint8)
    except OSError as exc:
        raise CliError(f"cannot read image {path}: {exc.strerror or exc}") from None
    # OpenCV logs decoder complaints to stderr itself; the one-line error below says it all
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        raise CliError(f"not a readable image (corrupt or unsupported format): {path}")
    if image.dtype == np.uint16:
        image = (image // 256).astype(np.uint8)  # 16-bit PNGs: the top 8 bits are what shows
    if image.dtype != np.uint8:
        raise CliError(f"unsupported image sample type {image.dtype} in {path} (need 8 or 16 bit)")
    return image


def _read_start(path: str) -> Any:
    from app.calib.camera import camera_from_json

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise CliError(f"cannot read start camera {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise CliError(f"start camera {path} is not UTF-8 text") from None
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CliError(
            f"start camera {path} is not valid JSON: {exc.msg} (line {exc.lineno})"
        ) from None
    try:
        genome, _ = camera_from_json(obj)
    except ValueError as exc:
        raise CliError(f"bad start camera in {path}: {exc}") from None
    return genome


def _write_bytes(path: str, data: bytes, what: str) -> None:
    try:
        Path(path).write_bytes(data)
    except OSError as exc:
        raise CliError(f"cannot write {what} {path}: {exc.strerror or exc}") from None


def _check_writable(path: str, what: str) -> None:
    """Fail before the optimisation, not after it, when an output cannot be written."""
    parent = Path(path).resolve().parent
    if not parent.is_dir():
        raise CliError(f"cannot write {what} {path}: directory {parent} does not exist")
    if Path(path).is_dir():
        raise CliError(f"cannot write {what} {path}: it is a directory")


def _calibrate(args: argparse.Namespace) -> None:
    import cv2

    from app.calib import pipeline
    from app.calib.court import get_spec
    from app.calib.ga import get_bundle

    _check_writable(args.out, "result")
    if args.overlay is not None:
        _check_writable(args.overlay, "overlay")
    bundle_name = args.bundle
    try:
        if bundle_name is not None:
            get_bundle(bundle_name)
        get_spec(args.spec)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if args.max_generations is not None and args.max_generations < 1:
        raise CliError("--max-generations must be at least 1")
    if args.time_budget is not None and not args.time_budget > 0:
        raise CliError("--time-budget must be positive")
    image = _read_image(args.image)
    start = _read_start(args.start) if args.start is not None else None
    options: dict[str, Any] = {}
    if args.max_generations is not None:
        options["max_generations"] = args.max_generations
    try:
        result = pipeline.calibrate(
            image,
            start_genome=start,
            bundle=bundle_name,
            seed=args.seed,
            time_budget_s=args.time_budget,
            spec=args.spec,
            **options,
        )
    except pipeline.CourtNotFound as exc:
        raise CliError(str(exc), EXIT_COURT_NOT_FOUND) from None
    except ValueError as exc:
        raise CliError(f"bad input: {exc}") from None
    text = json.dumps(result.to_json(), indent=2) + "\n"
    _write_bytes(args.out, text.encode("utf-8"), "result")
    if args.overlay is not None:
        overlay = pipeline.draw_overlay(image, result.genome, args.spec)
        ok, png = cv2.imencode(".png", overlay)
        if not ok:
            raise CliError(f"cannot encode the overlay for {args.overlay}")
        _write_bytes(args.overlay, png.tobytes(), "overlay")
    floor_t = result.uncertainty["floor_error_cm"]["T"]
    print(
        f"calibrated {args.image}: {result.verdict.label} ({'; '.join(result.verdict.reasons)}), "
        f"{result.camera_model}, expected floor error at the T "
        f"{'unknown' if floor_t is None else f'{floor_t:.1f} cm'}, "
        f"{result.timings_s['total']:.2f} s -> {args.out}"
    )


def run(command: str, args: argparse.Namespace) -> int:
    try:
        _calibrate(args)
    except CliError as exc:
        print(f"squashcal calibrate: error: {exc}", file=sys.stderr)
        return exc.status
    except KeyboardInterrupt:
        print("squashcal calibrate: interrupted", file=sys.stderr)
        return 130
    return 0
