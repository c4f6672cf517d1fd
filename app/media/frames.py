"""A job's stored upload -> frames for the background estimate (the worker's side of media)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from types import TracebackType

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


class FrameSpool:
    """Decoded frames of one size, written one by one to an anonymous temporary file and read
    back a band of rows at a time (`read_rows`, for `background_from_bands`): a job's memory is
    one decoded frame plus one band of all of them, whatever the number and size of its images.

    The file lives in the system's temporary directory (TMPDIR), local to the worker (not the
    shared media store), and disappears when the spool is closed or the process dies.
    """

    def __init__(self, width: int, height: int) -> None:
        self.width = width
        self.height = height
        self.n_frames = 0
        self._row_bytes = width * 3
        self._frame_bytes = height * self._row_bytes
        # closed by close() / the spool's own context manager
        self._file = tempfile.TemporaryFile(prefix="squashcal-frames-")  # noqa: SIM115

    def append(self, frame: np.ndarray) -> None:
        if frame.shape != (self.height, self.width, 3) or frame.dtype != np.uint8:
            raise ValueError(
                f"frame {frame.dtype} {frame.shape} is not uint8 ({self.height}, {self.width}, 3)"
            )
        self._file.seek(self.n_frames * self._frame_bytes)
        self._file.write(np.ascontiguousarray(frame).data)
        self.n_frames += 1

    def read_rows(self, top: int, bottom: int) -> np.ndarray:
        """uint8 (n_frames, bottom - top, width, 3): rows top..bottom-1 of every frame."""
        if not 0 <= top < bottom <= self.height:
            raise ValueError(f"rows {top}..{bottom} outside 0..{self.height}")
        out = np.empty((self.n_frames, bottom - top, self.width, 3), np.uint8)
        want = (bottom - top) * self._row_bytes
        for i in range(self.n_frames):
            self._file.seek(i * self._frame_bytes + top * self._row_bytes)
            got = self._file.readinto(memoryview(out[i]).cast("B"))
            if got != want:
                raise OSError(f"frame spool: read {got} of {want} bytes")
        return out

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> FrameSpool:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def spool_images(paths: list[Path], settings: Settings) -> FrameSpool:
    """`load_images` into a FrameSpool: the same checks, one decoded image in memory at a time."""
    sizes = probe.checked_image_sizes(paths, settings)
    width, height = sizes[0]
    spool = FrameSpool(width, height)
    try:
        for i, path in enumerate(paths):
            image = probe.decode_image(path, i)
            if image.shape[:2] != (height, width):
                raise MediaError("corrupt_image", f"image #{i + 1} does not match its header")
            spool.append(np.asarray(image))
            del image
    except BaseException:
        spool.close()
        raise
    return spool


def job_paths(settings: Settings, job_id: str, files: list[str]) -> list[Path]:
    """The stored files of a job's upload (MediaError if any is missing)."""
    directory = store.job_dir(settings, job_id)
    paths = [directory / name for name in files]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise MediaError("media_missing", f"the uploaded files are missing from storage: {missing}")
    return paths


def load_frames(settings: Settings, job_id: str, kind: str, files: list[str]) -> list[np.ndarray]:
    """The job's frames: every uploaded image, or frames sampled over the clip."""
    paths = job_paths(settings, job_id, files)
    if kind == "video":
        return sample_video_frames(
            paths[0],
            settings.background_frames,
            settings.max_video_duration_s,
            (settings.max_video_width_px, settings.max_video_height_px),
        )
    return load_images(paths, settings)
