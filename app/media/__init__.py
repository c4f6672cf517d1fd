"""Media of the service, used alike by the API and the worker.

- `store`: where uploads and calibration images live (one interface, a local directory by default);
- `sniff`: what a file is, from its bytes (type, image size from the header);
- `probe`: whether media is usable (limits, decodability), the one set of checks;
- `frames`: a stored upload turned into frames for the pipeline.
"""

from __future__ import annotations

from app.media.frames import FrameSpool, job_paths, load_frames, spool_images
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
    "load_frames",
    "media_store",
    "spool_images",
]
