"""A job's stored images -> frames for the background estimate (the worker's side of media).

A clip is read by the background stage itself (`app.calib.background.video_samples`, through
`worker.main.clip_background`): it picks its frames by shot, as it decodes.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from types import TracebackType

import numpy as np

from app.media import probe, store
from app.media.probe import MediaError
from app.settings import Settings


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
    """Every image of an upload, decoded into a FrameSpool one at a time, after the same header
    checks as at upload (sizes, pixel budget): nothing is decoded until the whole upload is known
    to fit."""
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
