"""Removing media nobody needs any more: uploads of failed jobs after the retention period, job
folders without a job (an upload cut off by an API crash or a kill before its job was committed),
and calibration folders without a calibration (a worker writes a calibration's images before the
transaction that stores it, so that a stored calibration always has them: killed in between, or
out of retries, they have no row).

Uploads of queued, running and succeeded jobs are kept. Several API processes may sweep at once:
removing a folder twice is harmless.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.orm import Session, sessionmaker

from app.db import repo
from app.db.models import utcnow
from app.media.store import MediaStore, StoredDir
from app.settings import Settings

log = logging.getLogger("squashcal.media")

ID_QUERY_CHUNK = 500


@dataclass(frozen=True)
class SweepReport:
    failed_uploads_removed: int
    orphans_removed: int  # job folders without a job
    orphan_calibrations_removed: int  # calibration folders without a calibration


def sweep_media(
    store: MediaStore,
    sessions: sessionmaker[Session],
    settings: Settings,
    now: datetime | None = None,
) -> SweepReport:
    now = now or utcnow()
    failed = _remove_failed_uploads(
        store, sessions, now - _seconds(settings.failed_media_retention_s)
    )
    grace_s, now_s = settings.orphan_media_grace_s, now.timestamp()
    orphans = _remove_orphans(
        store.job_dirs(), repo.existing_job_ids, store.remove_job_dir, sessions, grace_s, now_s
    )
    orphan_calibrations = _remove_orphans(
        store.calibration_dirs(),
        repo.existing_calibration_ids,
        store.remove_calibration_dir,
        sessions,
        grace_s,
        now_s,
    )
    if failed or orphans or orphan_calibrations:
        log.info(
            "media sweep: %d failed job upload(s), %d job folder(s) without a job and %d "
            "calibration folder(s) without a calibration removed",
            failed,
            orphans,
            orphan_calibrations,
        )
    return SweepReport(failed, orphans, orphan_calibrations)


def _seconds(value: float) -> timedelta:
    return timedelta(seconds=value)


def _remove_failed_uploads(
    store: MediaStore, sessions: sessionmaker[Session], cutoff: datetime
) -> int:
    with sessions() as session:
        job_ids = repo.failed_job_ids_finished_before(session, cutoff)
    return sum(store.remove_job_dir(job_id) for job_id in job_ids)


def _remove_orphans(
    dirs: Iterable[StoredDir],
    existing_ids: Callable[[Session, Sequence[str]], set[str]],
    remove: Callable[[str], bool],
    sessions: sessionmaker[Session],
    grace_s: float,
    now_s: float,
) -> int:
    """Remove the folders among `dirs` quiet for `grace_s` whose row does not exist."""
    # an upload in progress (here or on another host) has a folder and no job yet, as a
    # calibration being stored has no row yet: the grace period since the last write tells them
    # from folders whose row will never be committed
    quiet = [d for d in dirs if now_s - d.last_modified > grace_s]
    removed = 0
    for i in range(0, len(quiet), ID_QUERY_CHUNK):
        chunk = quiet[i : i + ID_QUERY_CHUNK]
        with sessions() as session:
            known = existing_ids(session, [d.id for d in chunk])
        removed += sum(remove(d.id) for d in chunk if d.id not in known)
    return removed


def sweep_quietly(
    store: MediaStore, sessions: sessionmaker[Session], settings: Settings
) -> SweepReport | None:
    """A sweep whose failure (database down or not migrated yet) is logged, not raised."""
    started = time.monotonic()
    try:
        report = sweep_media(store, sessions, settings)
    except Exception:
        log.exception("media sweep failed; next attempt in %.0f s", settings.media_sweep_interval_s)
        return None
    log.debug("media sweep took %.2f s", time.monotonic() - started)
    return report
