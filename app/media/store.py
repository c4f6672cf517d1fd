"""Where media lives: one interface for the API and the worker, a local directory by default.

Layout under the store's root (`settings.media_dir`, i.e. SQUASHCAL_MEDIA_ROOT or
`<data_dir>/media`):

    jobs/<job id>/<n>.<ext>                      an upload, as received (kept while the job lives)
    calibrations/<calibration id>/<name>.png     the images a calibration was made from and of

The interface hands out local directories because the decoders (OpenCV, FFmpeg) read files by path.
Several hosts share media by mounting one volume (NFS, CephFS, a cloud file share) at the same path
on every API and worker host: uploads are written under a fresh job id, fsynced, and only then is
the job committed to the database, so a worker on another host never sees a job whose files are not
complete. See the README ("Several machines").
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from app.settings import Settings


@dataclass(frozen=True)
class StoredDir:
    """A job's or a calibration's folder in the store."""

    id: str  # the job's or the calibration's
    path: Path
    last_modified: float  # newest mtime of the folder and its files (seconds since the epoch)


class MediaStore(Protocol):
    def job_dir(self, job_id: str) -> Path: ...

    def calibration_dir(self, calibration_id: str) -> Path: ...

    def create_job_dir(self, job_id: str) -> Path: ...

    def remove_job_dir(self, job_id: str) -> bool: ...

    def remove_calibration_dir(self, calibration_id: str) -> bool: ...

    def job_dirs(self) -> Iterator[StoredDir]: ...

    def calibration_dirs(self) -> Iterator[StoredDir]: ...

    def persist(self, directory: Path) -> None: ...


class LocalMediaStore:
    """Media in a directory of this host's filesystem (local disk or a mounted shared volume)."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def job_dir(self, job_id: str) -> Path:
        return self.root / "jobs" / _safe_id(job_id)

    def calibration_dir(self, calibration_id: str) -> Path:
        return self.root / "calibrations" / _safe_id(calibration_id)

    def create_job_dir(self, job_id: str) -> Path:
        """A new, empty folder for an upload (fails if the id is already taken)."""
        path = self.job_dir(job_id)
        path.mkdir(parents=True)
        return path

    def remove_job_dir(self, job_id: str) -> bool:
        return _remove(self.job_dir(job_id))

    def remove_calibration_dir(self, calibration_id: str) -> bool:
        return _remove(self.calibration_dir(calibration_id))

    def job_dirs(self) -> Iterator[StoredDir]:
        return _dirs(self.root / "jobs")

    def calibration_dirs(self) -> Iterator[StoredDir]:
        return _dirs(self.root / "calibrations")

    def persist(self, directory: Path) -> None:
        fsync_tree(directory)


def _safe_id(resource_id: str) -> str:
    # ids are generated hex strings; refuse anything that could step out of the store
    if not resource_id.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"not a media id: {resource_id!r}")
    return resource_id


def _remove(path: Path) -> bool:
    if not path.exists():
        return False
    shutil.rmtree(path, ignore_errors=True)
    return True


def _dirs(root: Path) -> Iterator[StoredDir]:
    if not root.is_dir():
        return
    for path in root.iterdir():
        if path.is_dir():
            yield StoredDir(path.name, path, _newest_mtime(path))


def _newest_mtime(directory: Path) -> float:
    newest = directory.stat().st_mtime
    for child in directory.iterdir():
        try:
            newest = max(newest, child.stat().st_mtime)
        except FileNotFoundError:  # removed meanwhile (an upload's temporary part renamed)
            continue
    return newest


def media_store(settings: Settings) -> MediaStore:
    return LocalMediaStore(settings.media_dir)


def job_dir(settings: Settings, job_id: str) -> Path:
    return media_store(settings).job_dir(job_id)


def calibration_dir(settings: Settings, calibration_id: str) -> Path:
    return media_store(settings).calibration_dir(calibration_id)


def fsync_tree(directory: Path) -> None:
    """Flush the files of `directory` and the directory entries themselves to stable storage."""
    for path in directory.iterdir():
        if path.is_file():
            with path.open("rb") as f:
                os.fsync(f.fileno())
    for d in (directory, directory.parent):
        fd = os.open(d, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def age_s(stored: StoredDir, now: float | None = None) -> float:
    return (time.time() if now is None else now) - stored.last_modified
