"""A job's stored upload -> frames for the background estimate (the worker's side of media)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from app.media import probe, store
from app.media.probe import MediaError
from app.settings import Settings

# Without a usable frame count (some WebM/MKV files), read sequentially but keep memory bounded:
# keep every `stride`-th frame and double the stride whenever the buffer fills.
SEQUENTIAL_READ_CAP_FRAMES = 100_000


def frame_indices(n_frames: int, n_samples: int) -> np.ndarray:
    """`n_samples` frame indices spread evenly over a clip of `n_frames`, first and last included."""
    if n_frames < 1 or n_samples < 1:
        raise ValueError("n_frames and n_samples must be positive")
    return np.unique(np.round(np.linspace(0, n_frames - 1, min(n_samples, n_frames))).astype(int))


def sample_video_frames(
    path: Path, n_samples: int, max_duration_s: float, max_size: tuple[int, int]
) -> list[np.ndarray]:
    """Up to `n_samples` frames spread over the whole clip, by seeking (not decoding every frame)."""
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise MediaError(
                "corrupt_video", "the video could not be opened (corrupt or truncated)"
            )
        fps = capture.get(cv2.CAP_PROP_FPS)
        n_frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if fps > 0 and n_frames > 0:
            n_frames = min(n_frames, int(max_duration_s * fps) + 1)
            frames = []
            for index in frame_indices(n_frames, n_samples):
                capture.set(cv2.CAP_PROP_POS_FRAMES, float(index))
                ok, frame = capture.read()
                if ok and frame is not None:
                    frames.append(frame)
            if not frames:  # seeking failed on this container: fall back to reading in order
                capture.release()
                capture = cv2.VideoCapture(str(path))
                frames = _read_sequentially(capture, n_samples, max_duration_s, fps)
        else:
            frames = _read_sequentially(capture, n_samples, max_duration_s, fps)
    finally:
        capture.release()
    if not frames:
        raise MediaError("video_no_frames", "the video has no decodable frame")
    height, width = frames[0].shape[:2]
    if width > max_size[0] or height > max_size[1]:
        raise MediaError(
            "video_frame_too_large",
            f"video frames are {width}x{height}; the limit is {max_size[0]}x{max_size[1]}",
        )
    frames = [f for f in frames if f.shape == frames[0].shape]
    return frames


def _read_sequentially(
    capture: cv2.VideoCapture, n_samples: int, max_duration_s: float, fps: float
) -> list[np.ndarray]:
    limit = int(max_duration_s * fps) + 1 if fps > 0 else SEQUENTIAL_READ_CAP_FRAMES
    kept: list[np.ndarray] = []
    stride = 1
    index = 0
    while index < limit:
        ok, frame = capture.read()
        if not ok or frame is None:
            break
        if index % stride == 0:
            kept.append(frame)
            if len(kept) >= 2 * n_samples:
                kept = kept[::2]
                stride *= 2
        index += 1
    if len(kept) > n_samples:
        picks = np.round(np.linspace(0, len(kept) - 1, n_samples)).astype(int)
        kept = [kept[i] for i in picks]
    return kept


def load_images(paths: list[Path], settings: Settings) -> list[np.ndarray]:
    """Every image of an upload, after the same header checks as at upload (sizes, pixel budget):
    nothing is decoded until the whole upload is known to fit, then one image at a time."""
    sizes = probe.checked_image_sizes(paths, settings)
    frames = []
    for i, path in enumerate(paths):
        image = probe.decode_image(path, i)
        if image.shape[:2] != (sizes[i][1], sizes[i][0]):
            raise MediaError("corrupt_image", f"image #{i + 1} does not match its header")
        frames.append(image)
    return frames


def load_frames(settings: Settings, job_id: str, kind: str, files: list[str]) -> list[np.ndarray]:
    """The job's frames: every uploaded image, or frames sampled over the clip."""
    directory = store.job_dir(settings, job_id)
    paths = [directory / name for name in files]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise MediaError("media_missing", f"the uploaded files are missing from storage: {missing}")
    if kind == "video":
        return sample_video_frames(
            paths[0],
            settings.background_frames,
            settings.max_video_duration_s,
            (settings.max_video_width_px, settings.max_video_height_px),
        )
    return load_images(paths, settings)
