"""Compile (or load from numba's on-disk cache) the numerical kernels before a process takes work.

Every kernel is `numba.njit(cache=True)`: the first call in a process compiles it (seconds per
kernel with an empty cache, ~12 s for a whole calibration) or loads it from the cache. Without a
warm-up the first job of a worker and the first `/project` of an API process pay that. So the
service runs these at start, before it says it is ready, and the Docker image runs them at build
time so that its cache is full.

The warm-ups go through the same public functions as real work, on small inputs, so that numba
sees the argument types of real work (a kernel called with other types would compile again).
`compiled_signatures` lists what is compiled, so a test can check that a real job after a warm-up
compiles nothing new.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import pkgutil
import time
from collections.abc import Callable

import numpy as np

log = logging.getLogger("squashcal.warmup")

# Small enough to be quick, large enough that the search finds the court (at 96x54 it does not),
# so that refinement and the verdict run too.
_SIZE = (128, 72)


def _court_pictures() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(genome, photo-like BGR picture, white-on-black line picture) of a typical camera."""
    from app.calib import render, synthetic
    from app.calib.court import court_model

    genome = synthetic.typical_target_camera(_SIZE)
    lines = render.rasterize_court(genome, court_model("wsf"), _SIZE)
    photo = np.full((_SIZE[1], _SIZE[0], 3), (60, 90, 120), np.uint8)
    photo[lines > 0] = (235, 235, 235)
    return genome, photo, lines


def warm_projection() -> None:
    """The API's kernels: pixels <-> floor (`/project`, `/image-points`) and the court drawing of
    its pictures. Not the line evidence: the API only extracts it for calibrations stored before
    the worker kept it (`edges.png`); compiling it would delay readiness when the cache is empty."""
    from app.calib import camera, render
    from app.calib.court import court_model

    genome, _, _ = _court_pictures()
    # the API's camera cache hands out read-only genomes, which numba compiles apart from
    # writable ones (the pictures' genomes come from the database, writable)
    read_only = genome.copy()
    read_only.setflags(write=False)
    for g in (genome, read_only):
        camera.pixel_to_floor(g, np.array([[10.0, 20.0], [64.0, 60.0]]))
        camera.floor_to_pixel(g, np.array([[3.2, 5.0]]))
        camera.floor_to_image_pixel(g, np.array([[3.2, 5.0]]))  # /image-points: also the fold
    render.court_polylines(genome, court_model("wsf"))


def warm_calibration() -> None:
    """The worker's kernels: line evidence of photos and of edge images (with and without a mask
    of moving pixels), the camera search, refinement and the verdict, the GA of the bundles, the
    overlay."""
    from app.calib import pipeline
    from app.calib.ga.engine import load_compiled_code

    genome, photo, lines = _court_pictures()
    moving = np.zeros(photo.shape[:2], bool)
    moving[:8, :8] = True
    # the photo-like picture is too coarse for the court to be found at this size; the line
    # evidence and search kernels of photos are what it is for
    with contextlib.suppress(pipeline.CourtNotFound):
        pipeline.calibrate(photo, moving_mask=moving)
    result = pipeline.calibrate(lines)
    pipeline.draw_overlay(photo, result.genome)
    load_compiled_code()


def warm_renderer() -> None:
    """The scene renderer behind the demo clip (`GET /demo/clip.mp4`): two tiny frames."""
    from app.calib import scene

    genome, _, _ = _court_pictures()
    scene.render_clip_frames(genome, (64, 48), 2, 0, n_players=1)


WARM_UPS: dict[str, Callable[[], None]] = {
    "projection": warm_projection,
    "calibration": warm_calibration,
    "renderer": warm_renderer,
}
# what each process runs at start ("image": the Docker build fills the cache for all of them)
API_PARTS = ("projection",)
WORKER_PARTS = ("calibration",)
IMAGE_PARTS = ("projection", "calibration", "renderer")


def warm_up(parts: tuple[str, ...]) -> dict[str, float]:
    """Run the named warm-ups; seconds spent by each."""
    seconds = {}
    for name in parts:
        began = time.perf_counter()
        WARM_UPS[name]()
        seconds[name] = round(time.perf_counter() - began, 3)
    log.info("numerical kernels ready: %s (seconds)", seconds)
    return seconds


def warm_up_best_effort(parts: tuple[str, ...]) -> None:
    """`warm_up` for a service starting: a failure is logged, not raised (then the first request
    or job compiles what is missing; the service still serves)."""
    try:
        warm_up(parts)
    except Exception:
        log.exception("warm-up of the numerical kernels failed")


def compiled_signatures() -> dict[str, set[str]]:
    """Every numba kernel of app.calib -> the argument types it has been compiled for here."""
    from numba.core.registry import CPUDispatcher

    import app.calib

    out: dict[str, set[str]] = {}
    for info in pkgutil.walk_packages(app.calib.__path__, "app.calib."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.__module__ == module.__name__:
                out[f"{module.__name__}.{name}"] = {str(sig) for sig in value.signatures}
    return out


def main() -> None:
    """`python -m app.calib.warmup [PART ...]` (default: all): the Docker build runs this."""
    import sys

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    parts = tuple(sys.argv[1:]) or IMAGE_PARTS
    unknown = [p for p in parts if p not in WARM_UPS]
    if unknown:
        raise SystemExit(f"unknown warm-up {unknown}; known: {sorted(WARM_UPS)}")
    warm_up(parts)


if __name__ == "__main__":
    main()
