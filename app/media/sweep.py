"""Removing uploads nobody needs any more: those of failed jobs after the retention period, and job
folders without a job (an upload cut off by an API crash or a kill before its job was committed).

Uploads of queued, running and succeeded jobs are kept. Several API processes may sweep at once:
removing a folder twice is harmless.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.orm import Session, sessionmaker

from app.db import repo
from app.db.models import utcnow
from app.media.store import MediaStore
from app.settings import Settings

log = logging.getLogger("squashcal.media")

ID_QUERY_CHUNK = 500


@dataclass(frozen=True)
class SweepReport:
    failed_uploads_removed: int
    orphans_removed: int


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
    orphans = _remove_orphans(store, sessions, settings.orphan_media_grace_s, now.timestamp())
    if failed or orphans:
        log.info(
            "media sweep: %d failed job upload(s), %d orphan folder(s) removed", failed, orphans
        )
    return SweepReport(failed, orphans)


def _seconds(value: float) -> timedelta:
    return timedelta(seconds=value)


def _remove_failed_uploads(
    store: MediaStore, sessions: sessionmaker[Session], cutoff: datetime
) -> int:
    with sessions() as session:
        job_ids = repo.failed_job_ids_finished_before(session, cutoff)
    return sum(store.remove_job_dir(job_id) for job_id in job_ids)


def _remove_orphans(
    store: MediaStore, sessions: sessionmaker[Session], grace_s: float, now_s: float
) -> int:
    # an upload in progress (here or on another host) has a folder and no job yet: the grace
    # period since its last write tells it from one that will never be committed
    quiet = [d for d in store.job_dirs() if now_s - d.last_modified > grace_s]
    removed = 0
    for i in range(0, len(quiet), ID_QUERY_CHUNK):
        chunk = quiet[i : i + ID_QUERY_CHUNK]
        with sessions() as session:
            known = repo.existing_job_ids(session, [d.job_id for d in chunk])
        removed += sum(store.remove_job_dir(d.job_id) for d in chunk if d.job_id not in known)
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
