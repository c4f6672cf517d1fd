"""In-memory cameras per court, so /project and /image-points do no database work.

Choice: a refresher task polls the database every `camera_refresh_s` with ONE indexed query over all
cached courts (`SELECT id, active_calibration_id FROM courts WHERE id IN (...)`) and reloads only the
cameras whose active calibration changed. Requests only read the dict. Why not the alternatives:
- a per-request version check is a database round trip on the hot path;
- a TTL alone serves a stale camera for the whole TTL and then makes one unlucky request pay;
- invalidation messages from the worker need a broker (or PostgreSQL LISTEN, unavailable on SQLite),
  and cannot reach other API processes on other machines either.
The price is at most `camera_refresh_s` (default 0.5 s) of staleness after a calibration lands, and
one small query per interval per API process, independent of request rate. If the refresher is not
running (e.g. the app was used without its lifespan) entries older than a few intervals are
revalidated inline, so a request never sees an old camera indefinitely.

Cameras by calibration id (`/calibrations/{id}/project` and `/image-points`, any calibration of a
court's history) are cached apart: a calibration never changes and is never deleted, so such an
entry is never stale and needs no refresh, only a bound on how many are kept.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from sqlalchemy.orm import Session

from app.calib.camera import PreparedCamera
from app.calib.court import get_spec
from app.db import repo
from app.db.models import Calibration, Court

log = logging.getLogger("squashcal.camera_cache")

REFRESH_QUERY_CHUNK = 500
STALE_AFTER_INTERVALS = 4


@dataclass(frozen=True)
class CachedCamera:
    tenant_id: str
    court_id: str
    calibration_id: str | None  # None: the court has no calibration yet
    genome: np.ndarray | None  # (15,)
    # built once per calibration (calibrations never change): a request pays only for its points
    camera: PreparedCamera | None
    image_size: tuple[int, int] | None
    court_width_m: float
    court_length_m: float
    checked_at: float  # time.monotonic() of the last database check


class CameraCache:
    def __init__(self, sessions: Callable[[], Session], refresh_s: float, max_courts: int) -> None:
        self._sessions = sessions
        self.refresh_s = refresh_s
        self.max_courts = max_courts
        self._entries: OrderedDict[str, CachedCamera] = OrderedDict()
        self._by_calibration: OrderedDict[str, CachedCamera] = OrderedDict()
        self._lock = threading.Lock()
        self._refreshing = threading.Lock()  # held while a refresh uses the database

    def get(self, tenant_id: str, court_id: str) -> CachedCamera:
        """The court's camera entry; loads it on a miss. Raises repo.NotFound for other tenants."""
        entry = self.peek(tenant_id, court_id)
        if entry is None:
            entry = self._load(tenant_id, court_id)
            if entry.tenant_id != tenant_id:
                raise repo.NotFound("court", court_id)
        return entry

    def peek(self, tenant_id: str, court_id: str) -> CachedCamera | None:
        """The cached entry if it is fresh, without any database work (safe on the event loop);
        None when `get` would have to load it. Raises repo.NotFound for other tenants' courts."""
        now = time.monotonic()
        with self._lock:
            entry = self._entries.get(court_id)
            if entry is not None:
                self._entries.move_to_end(court_id)
        if entry is None or now - entry.checked_at > STALE_AFTER_INTERVALS * self.refresh_s:
            return None
        if entry.tenant_id != tenant_id:
            raise repo.NotFound("court", court_id)
        return entry

    def peek_calibration(self, tenant_id: str, calibration_id: str) -> CachedCamera | None:
        """The camera of one calibration if cached (no database work: safe on the event loop),
        else None. Raises repo.NotFound for other tenants' calibrations."""
        with self._lock:
            entry = self._by_calibration.get(calibration_id)
            if entry is not None:
                self._by_calibration.move_to_end(calibration_id)
        if entry is not None and entry.tenant_id != tenant_id:
            raise repo.NotFound("calibration", calibration_id)
        return entry

    def calibration(self, tenant_id: str, calibration_id: str) -> CachedCamera:
        """The camera of one calibration (of any court of the tenant, active or not); loads it on
        a miss. Raises repo.NotFound when it does not exist or belongs to another tenant."""
        entry = self.peek_calibration(tenant_id, calibration_id)
        if entry is not None:
            return entry
        with self._sessions() as session:
            cal = repo.get_owned(session, Calibration, tenant_id, calibration_id)
            # the row is in the session now: _entry_for's read of it is no second query
            entry = self._entry_for(session, cal.tenant_id, cal.court_id, cal.spec, cal.id)
        with self._lock:
            self._by_calibration[calibration_id] = entry
            self._by_calibration.move_to_end(calibration_id)
            while len(self._by_calibration) > self.max_courts:
                self._by_calibration.popitem(last=False)
        return entry

    def _load(self, tenant_id: str, court_id: str) -> CachedCamera:
        with self._sessions() as session:
            court = repo.get_owned(session, Court, tenant_id, court_id)
            entry = self._entry_for(
                session, court.tenant_id, court.id, court.spec, court.active_calibration_id
            )
        self._store(entry)
        return entry

    @staticmethod
    def _entry_for(
        session: Session, tenant_id: str, court_id: str, spec: str, calibration_id: str | None
    ) -> CachedCamera:
        court_spec = get_spec(spec)
        genome = None
        prepared = None
        image_size = None
        if calibration_id is not None:
            cal = session.get(Calibration, calibration_id)
            if cal is not None:
                prepared = PreparedCamera(np.asarray(cal.genome, dtype=np.float64))
                genome = prepared.genome  # read-only
                image_size = (cal.image_width, cal.image_height)
            else:
                calibration_id = None
        return CachedCamera(
            tenant_id=tenant_id,
            court_id=court_id,
            calibration_id=calibration_id,
            genome=genome,
            camera=prepared,
            image_size=image_size,
            court_width_m=court_spec.width_m,
            court_length_m=court_spec.length_m,
            checked_at=time.monotonic(),
        )

    def _store(self, entry: CachedCamera) -> None:
        with self._lock:
            self._entries[entry.court_id] = entry
            self._entries.move_to_end(entry.court_id)
            while len(self._entries) > self.max_courts:
                self._entries.popitem(last=False)

    def refresh_once(self) -> int:
        """Check every cached court against the database; returns how many cameras changed."""
        with self._refreshing:
            return self._refresh()

    def wait_idle(self) -> None:
        """Block until no refresh is using the database (before the engine is disposed)."""
        with self._refreshing:
            pass

    def _refresh(self) -> int:
        with self._lock:
            snapshot = dict(self._entries)
        if not snapshot:
            return 0
        court_ids = list(snapshot)
        changed = 0
        checked_at = time.monotonic()
        with self._sessions() as session:
            active: dict[str, str | None] = {}
            for i in range(0, len(court_ids), REFRESH_QUERY_CHUNK):
                active.update(
                    repo.active_calibration_ids(session, court_ids[i : i + REFRESH_QUERY_CHUNK])
                )
            for court_id, entry in snapshot.items():
                if court_id not in active:  # court deleted
                    with self._lock:
                        self._entries.pop(court_id, None)
                    continue
                if active[court_id] != entry.calibration_id:
                    court = session.get(Court, court_id)
                    if court is None:
                        continue
                    fresh = self._entry_for(
                        session, court.tenant_id, court.id, court.spec, active[court_id]
                    )
                    changed += 1
                else:
                    fresh = CachedCamera(**{**entry.__dict__, "checked_at": checked_at})
                with self._lock:
                    if court_id in self._entries:  # not evicted meanwhile
                        self._entries[court_id] = fresh
        return changed

    async def run_refresher(self) -> None:
        """Refresh forever (cancel the task to stop). Database errors are logged and retried."""
        while True:
            await asyncio.sleep(self.refresh_s)
            try:
                changed = await asyncio.to_thread(self.refresh_once)
                if changed:
                    log.info("camera cache: %d court camera(s) updated", changed)
            except Exception:
                log.exception("camera cache refresh failed; retrying")
