"""Clip -> background: time and memory of `background_from_clip`, and how the clip is read.

    python -m bench.clip_background [--sizes 1920x1080,1280x720,640x360] [--seconds 60]
                                    [--repeats 1] [--keep DIR]
    python -m bench.clip_background --clip CLIP [--reference BACKGROUND.png] [--repeats 1]

Synthetic clips (court render with two players, fresh sensor noise per frame, MPEG-4 part 2 via
`write_video`, 25 fps, in a temporary directory), per size:
- static: the main camera for the whole clip;
- cut+zoom: main camera for the first third, a close-up replay (the same position zoomed 2.2x),
  the main camera again until 5/6, a 1 s zoom to 1.12x and the zoomed view to the end. The main
  camera (two time ranges) must make the background.
Each clip is measured in a fresh process, so the peak RSS is that of the clip's processing alone
(after imports, shown apart). `background_from_clip` runs as the worker runs it, with the memory
budget of the default settings (`max_clip_frames_mb`, 1024 MB: it lowers the frames only above
1440p, e.g. 13 for 4K UHD; "frames used" says when it did). Columns: decode (grab every frame,
retrieve the samples), segmentation (signatures, view shifts, keeping frames), background
(`background_from_bands` over the kept frames, a band of rows at a time),
wall total, CPU time of all the process's threads (the decoder runs two; on a shared machine the
wall times grow with the load, the CPU time much less), and how far the background is from the empty-court render (mean absolute difference,
grey levels; the codec alone accounts for ~3). "seek 15" is what the worker did before: 15 frames
by seeking over the whole clip, views mixed.

Then, on the first clip: ways of reading the same samples (decode everything, grab and retrieve
the samples, seek to each sample, seek to 15 frames), the fastest of `--repeats` runs each.

`--keep DIR` writes the synthetic clips there and keeps them (e.g. to transcode them to another
codec and measure them with `--clip`).

`--clip`: any clip, measured the same way: its shots, the frames and time ranges used, and the
background's mean absolute difference to `--reference` (e.g. the dev clip and its annotated
background), next to the worker's former 15 seeks.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from bench.common import command_line, format_table

FPS = 25.0
LOOP_FRAMES = 50  # players run one loop every 2 s; frames repeat with that period
# Fresh sensor noise on every frame (grey levels), as a camera adds: without it the codec sends
# almost nothing for the static court and decoding is unrealistically cheap. Drawn once as a few
# fields cycled over the frames (drawing 1500 1080p fields would take minutes).
NOISE_SIGMA = 2.0
NOISE_FIELDS = 7


def _peak_rss_mb() -> float:
    """This process's peak resident memory (VmHWM; ru_maxrss would include the parent's at fork)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmHWM in /proc/self/status")


class _Clip(Sequence[np.ndarray]):
    """A clip's frames made on demand from looped renders (a 60 s 1080p clip would not fit)."""

    def __init__(self, parts: list[tuple[list[np.ndarray], int, float, float]]) -> None:
        # (looped frames, number of frames, zoom at the start, zoom at the end) per part
        self.parts = parts
        rng = np.random.default_rng(0)
        shape = parts[0][0][0].shape
        noise = [np.rint(rng.normal(0.0, NOISE_SIGMA, shape)) for _ in range(NOISE_FIELDS)]
        # as two saturating uint8 steps: add the positive part, subtract the negative part
        self.noise = [
            (np.clip(n, 0, 255).astype(np.uint8), np.clip(-n, 0, 255).astype(np.uint8))
            for n in noise
        ]

    def __len__(self) -> int:
        return sum(n for _, n, _, _ in self.parts)

    def __getitem__(self, index):  # type: ignore[override]
        from tests.clips import zoomed

        if not 0 <= index < len(self):
            raise IndexError(index)
        plus, minus = self.noise[index % len(self.noise)]
        for frames, n, zoom_start, zoom_end in self.parts:
            if index < n:
                frame = frames[index % len(frames)]
                zoom = zoom_start + (zoom_end - zoom_start) * (index + 1) / n
                if zoom != 1.0:
                    frame = zoomed(frame, zoom)
                return cv2.subtract(cv2.add(frame, plus), minus)
            index -= n
        raise IndexError(index)


def _write_clips(size: tuple[int, int], seconds: float, directory: Path) -> list[dict]:
    from tests.clips import close_up_camera, main_camera, render_clip_frames, write_video

    main = render_clip_frames(main_camera(size), size, LOOP_FRAMES, 1)
    n = round(seconds * FPS)
    third, cut_end, zoom_start = round(n / 3), round(n * 0.43), round(n * 5 / 6)
    zoom_frames = round(FPS)
    clips = []
    static_path = directory / f"static_{size[0]}x{size[1]}.mp4"
    write_video(_Clip([(main, n, 1.0, 1.0)]), static_path, fps=FPS)
    clips.append({"name": "static", "path": static_path, "expected": [[0, n - 1]]})
    close_up = render_clip_frames(close_up_camera(size), size, LOOP_FRAMES, 2)
    cut_path = directory / f"cut_zoom_{size[0]}x{size[1]}.mp4"
    parts = [
        (main, third, 1.0, 1.0),
        (close_up, cut_end - third, 1.0, 1.0),
        (main, zoom_start - cut_end, 1.0, 1.0),
        (main, zoom_frames, 1.0, 1.12),
        (main, n - zoom_start - zoom_frames, 1.12, 1.12),
    ]
    write_video(_Clip(parts), cut_path, fps=FPS)
    expected = [[0, third - 1], [cut_end, zoom_start - 1]]
    clips.append({"name": "cut+zoom", "path": cut_path, "expected": expected})
    return clips


def _measure(path: str, n_frames: int, old: bool, background_out: str) -> dict:
    """Run in a child process: one clip to background; timings, peak RSS and the shots."""
    from app.calib.background import background_from_clip, background_from_frames
    from app.settings import Settings

    rss_after_imports = _peak_rss_mb()
    start = time.perf_counter()
    cpu_start = time.process_time()
    if old:
        frames = _seek_frames(path, n_frames)
        decoded = time.perf_counter()
        background, moving = background_from_frames(frames)
        info = {"timings_s": {"decode": decoded - start, "segmentation": 0.0}}
        info["timings_s"]["background"] = time.perf_counter() - decoded
    else:
        budget = Settings().max_clip_frames_mb * 1_000_000  # as worker.main.clip_background
        background, moving, info = background_from_clip(
            path, n_frames=n_frames, max_frames_bytes=budget
        )
    total = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    cv2.imwrite(background_out, background)
    return {
        "total_s": total,
        "cpu_s": cpu,
        "rss_after_imports_mb": rss_after_imports,
        "peak_rss_mb": _peak_rss_mb(),
        "moving_fraction": float((moving > 0).mean()),
        "info": info,
    }


def _seek_frames(path: str, n_frames: int) -> list[np.ndarray]:
    """What the worker did before: `n_frames` frames spread over the whole clip, by seeking."""
    capture = cv2.VideoCapture(path)
    try:
        n_total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        frames = []
        for index in np.unique(np.round(np.linspace(0, n_total - 1, n_frames)).astype(int)):
            capture.set(cv2.CAP_PROP_POS_FRAMES, float(index))
            ok, frame = capture.read()
            if ok and frame is not None:
                frames.append(frame)
    finally:
        capture.release()
    return frames


def _measure_in_child(path: Path, n_frames: int, old: bool, background_out: Path) -> dict:
    command = [sys.executable, "-m", "bench.clip_background", "--measure", str(path)]
    command += ["--frames", str(n_frames), "--background-out", str(background_out)]
    if old:
        command.append("--old")
    done = subprocess.run(command, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _reading_table(path: Path, n_frames: int, repeats: int) -> str:
    from app.calib.background import video_samples

    capture = cv2.VideoCapture(str(path))
    n_total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    capture.release()
    rows = []

    def timed(name: str, read) -> None:
        seconds = []
        for _ in range(repeats):
            start = time.perf_counter()
            converted = read()
            seconds.append(time.perf_counter() - start)
        rows.append([name, converted, f"{min(seconds):.2f}"])

    def read_all() -> int:
        capture = cv2.VideoCapture(str(path))
        count = 0
        while capture.read()[0]:
            count += 1
        capture.release()
        return count

    def grab_only() -> int:
        capture = cv2.VideoCapture(str(path))
        while capture.grab():
            pass
        capture.release()
        return 0

    sample_indices = [index for index, _, _ in video_samples(path)]

    def seek(indices: Sequence[int]) -> int:
        capture = cv2.VideoCapture(str(path))
        count = 0
        for index in indices:
            capture.set(cv2.CAP_PROP_POS_FRAMES, float(index))
            count += capture.read()[0]
        capture.release()
        return count

    timed("grab every frame, retrieve none", grab_only)
    timed("read (grab + retrieve) every frame", read_all)
    timed("grab every frame, retrieve the samples", lambda: sum(1 for _ in video_samples(path)))
    timed("seek to each sample", lambda: seek(sample_indices))
    spread = np.round(np.linspace(0, n_total - 1, n_frames)).astype(int)
    timed(f"seek to {n_frames} frames (worker before)", lambda: seek(spread))
    return format_table(["reading", "frames converted", "time s"], rows)


def _mean_abs_difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(cv2.absdiff(a, b).mean())


HEADERS = [
    "clip",
    "length",
    "decode s",
    "segment s",
    "background s",
    "total s",
    "CPU s",
    "peak RSS MB (imports)",
    "shots",
    "frames used",
    "MAD",
    "moving %",
]


def _rows(
    name: str,
    path: Path,
    n_frames: int,
    truth: np.ndarray | None,
    directory: Path,
    repeats: int,
) -> tuple[list, dict]:
    """Table rows of one clip: background_from_clip, then the former 15 seeks (the fastest of
    `repeats` runs each: on a shared machine the others measure the other users too), and the
    info of background_from_clip; the backgrounds are left in `directory` as new.png, old.png."""
    capture = cv2.VideoCapture(str(path))
    seconds = capture.get(cv2.CAP_PROP_FRAME_COUNT) / capture.get(cv2.CAP_PROP_FPS)
    capture.release()
    rows = []
    new_info: dict = {}
    for old in (False, True):
        out = directory / ("old.png" if old else "new.png")
        runs = [_measure_in_child(path, n_frames, old, out) for _ in range(repeats)]
        result = min(runs, key=lambda run: run["total_s"])
        background = cv2.imread(str(out))
        info = result["info"]
        new_info = new_info or info
        timings = info["timings_s"]
        ranges = " ".join(f"{a}-{b}" for a, b in info.get("frame_ranges", []))
        used = f"{n_frames} seeks" if old else f"{ranges} ({info['frames_used']} frames)"
        if info.get("frames_limited_by_memory"):
            used += ", memory-limited"
        mad = "-" if truth is None else f"{_mean_abs_difference(background, truth):.2f}"
        rows.append(
            [
                name,
                f"{seconds:.4g} s {path.stat().st_size / 1e6:.0f} MB",
                f"{timings['decode']:.2f}",
                f"{timings['segmentation']:.2f}",
                f"{timings['background']:.2f}",
                f"{result['total_s']:.2f}",
                f"{result['cpu_s']:.2f}",
                f"{result['peak_rss_mb']:.0f} ({result['rss_after_imports_mb']:.0f})",
                info.get("shots", "-"),
                used,
                mad,
                f"{100 * result['moving_fraction']:.1f}",
            ]
        )
    return rows, new_info


def _synthetic(args: argparse.Namespace) -> None:
    from tests.clips import main_camera, render_court_image

    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    rows = []
    with tempfile.TemporaryDirectory(prefix="squashcal-clips-") as tmp:
        directory = Path(args.keep or tmp)
        directory.mkdir(parents=True, exist_ok=True)
        largest = None
        for size in sizes:
            truth = render_court_image(main_camera(size), size, rng=1)
            for clip in _write_clips(size, args.seconds, directory):
                largest = largest or clip["path"]
                expected = " ".join(f"{a}-{b}" for a, b in clip["expected"])
                name = f"{clip['name']} {size[0]}x{size[1]} (main view: {expected})"
                rows += _rows(name, clip["path"], args.frames, truth, Path(tmp), args.repeats)[0]
            print(f"{size[0]}x{size[1]} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr)
        print(format_table(HEADERS, rows))
        print()
        assert largest is not None
        print(f"reading {largest.name}:")
        print(_reading_table(largest, args.frames, args.repeats))


def _real(args: argparse.Namespace) -> None:
    path = Path(args.clip)
    reference = None
    if args.reference:
        reference = cv2.imread(args.reference)
        if reference is None:
            raise SystemExit(f"cannot read {args.reference}")
    with tempfile.TemporaryDirectory(prefix="squashcal-clip-") as tmp:
        rows, info = _rows(path.name, path, args.frames, reference, Path(tmp), args.repeats)
        background = cv2.imread(str(Path(tmp) / "new.png"))
    print(format_table(HEADERS, rows))
    print(json.dumps({k: v for k, v in info.items() if k != "timings_s"}))
    if reference is not None:
        difference = cv2.absdiff(background, reference)
        print(
            f"vs {Path(args.reference).name}: mean abs difference {difference.mean():.2f} grey "
            f"levels; pixels off by more than 10 in a channel: "
            f"{100 * float((difference.max(axis=2) > 10).mean()):.2f} %"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1920x1080,1280x720,640x360")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--frames", type=int, default=15, help="frames for the background")
    parser.add_argument("--repeats", type=int, default=1, help="runs per clip; the fastest counts")
    parser.add_argument("--keep", help="write the synthetic clips to this folder and keep them")
    parser.add_argument("--clip", help="a real clip instead of the synthetic ones")
    parser.add_argument("--reference", help="with --clip: the expected background (PNG)")
    parser.add_argument("--measure", help=argparse.SUPPRESS)
    parser.add_argument("--old", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--background-out", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(_measure(args.measure, args.frames, args.old, args.background_out)))
        return
    load = os.getloadavg()
    print(command_line())
    print(
        f"load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} cores)"
    )
    if args.clip:
        _real(args)
    else:
        _synthetic(args)
    load = os.getloadavg()
    print(f"load average at end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


if __name__ == "__main__":
    main()
