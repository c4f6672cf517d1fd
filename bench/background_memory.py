"""Peak memory of a job's background from uploaded images: all decoded at once vs streamed.

    .venv/bin/python -m bench.background_memory [--frames 16] [--size 4096x2304]

Renders an upload (PNG frames of a court with two players moving, app.calib.scene), then in a
fresh process each runs the worker's background step on it:
- whole: every image decoded into memory (after the same checks), then `background_from_frames`;
- streamed: images decoded one at a time into a FrameSpool (a temporary file), then
  `background_from_bands` (a band of rows of every frame at a time): what the worker does.
Prints each one's peak RSS (VmHWM), its RSS before decoding (imports), the time, and whether the
two results are identical.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2

from bench.common import command_line, format_table


def _size(text: str) -> tuple[int, int]:
    width, height = text.lower().split("x")
    return int(width), int(height)


def _status_mb(field: str) -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def child(mode: str, directory: Path) -> None:
    """Run one mode in this (fresh) process and print a JSON line of what it measured."""
    import numpy as np

    from app.calib import background
    from app.media import frames, probe
    from app.settings import Settings

    paths = sorted(directory.glob("*.png"))
    settings = Settings(data_dir=directory / "data", max_upload_pixels=10**10)
    before = _status_mb("VmRSS")
    began = time.perf_counter()
    if mode == "whole":
        probe.checked_image_sizes(paths, settings)
        images = [probe.decode_image(path, i) for i, path in enumerate(paths)]
        bg, mask = background.background_from_frames(images)
        del images
    else:
        with frames.spool_images(paths, settings) as spool:
            bg, mask = background.background_from_bands(
                spool.n_frames, spool.height, spool.width, spool.read_rows
            )
    seconds = time.perf_counter() - began
    digest = hashlib.sha256(np.ascontiguousarray(bg).data)
    digest.update(np.ascontiguousarray(mask).data)
    print(
        json.dumps(
            {
                "mode": mode,
                "rss_before_mb": before,
                "peak_mb": _status_mb("VmHWM"),
                "seconds": seconds,
                "digest": digest.hexdigest(),
            }
        )
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--size", type=_size, default=(4096, 2304))
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], Path(args.child[1]))
        return
    from app.calib import scene, synthetic

    genome = synthetic.typical_target_camera(args.size)
    with tempfile.TemporaryDirectory(prefix="squashcal-bgmem-") as tmp:
        directory = Path(tmp)
        for i, frame in enumerate(
            scene.render_clip_frames(genome, args.size, args.frames, 3, n_players=2)
        ):
            cv2.imwrite(str(directory / f"{i:03d}.png"), frame)
        upload_mb = sum(p.stat().st_size for p in directory.glob("*.png")) / 1e6
        results = []
        for mode in ("whole", "streamed"):
            done = subprocess.run(
                [sys.executable, "-m", "bench.background_memory", "--child", mode, tmp],
                check=True,
                capture_output=True,
                text=True,
                env=os.environ.copy(),
            )
            results.append(json.loads(done.stdout.strip().splitlines()[-1]))
    decoded_mb = args.frames * args.size[0] * args.size[1] * 3 / 2**20
    print(command_line())
    print(
        f"{args.frames} PNG frames {args.size[0]}x{args.size[1]} ({upload_mb:.0f} MB on disk, "
        f"{decoded_mb:.0f} MiB decoded); one fresh process per row"
    )
    same = len({r["digest"] for r in results}) == 1
    rows = [
        [
            r["mode"],
            f"{r['rss_before_mb']:.0f}",
            f"{r['peak_mb']:.0f}",
            f"{r['peak_mb'] - r['rss_before_mb']:.0f}",
            f"{r['seconds']:.1f}",
        ]
        for r in results
    ]
    headers = ["background", "RSS before MiB", "peak RSS MiB", "peak - before", "seconds"]
    print(format_table(headers, rows))
    print(f"identical background and mask: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
