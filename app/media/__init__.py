"""Media of the service, used alike by the API and the worker.

- `store`: where uploads and calibration images live (one interface, a local directory by default);
- `sniff`: what a file is, from its bytes (type, image size from the header);
- `probe`: whether media is usable (limits, decodability), the one set of checks;
- `frames`: a stored upload's images turned into frames for the background estimate (a clip is
  read by the background stage itself, `app.calib.background.video_samples`).
"""

from __future__ import annotations

from app.media.frames import FrameSpool, job_paths, spool_images
from app.media.probe import MediaError, MediaSummary, StoredFile
from app.media.store import MediaStore, calibration_dir, fsync_tree, job_dir, media_store

__all__ = [
    "FrameSpool",
    "MediaError",
    "MediaStore",
    "MediaSummary",
    "StoredFile",
    "calibration_dir",
    "fsync_tree",
    "job_dir",
    "job_paths",
    "media_store",
    "spool_images",
]
