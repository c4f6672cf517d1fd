"""The worker process: claim a job, run the calibration, store the result; repeat.

Leases: a heartbeat thread renews the job's lease at least every `heartbeat_s` (and writes
progress, at most every `progress_interval_s`) while the main thread computes. If the lease is lost
(the worker stalled past it and another worker took the job) the result is discarded.
SIGTERM/SIGINT: stop claiming, let the current job finish within `shutdown_grace_s`, otherwise give
it back to the queue; during the start-up warm-up, stop at once.

The database may be away for a while: every write the worker makes is retried or left to the lease
(an unrecorded job is reclaimed when its lease runs out), and nothing that goes wrong with one job
ends the process.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import socket
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np
from sqlalchemy import Engine

from app import media
from app.calib import warmup
from app.calib.background import ClipError, background_from_bands, background_from_clip
from app.db import queue
from app.db.models import Calibration, JobStage, new_id
from app.db.session import make_engine
from app.media import MediaError, job_paths, spool_images
from app.settings import Settings
from worker.errors import Failure, classify

log = logging.getLogger("squashcal.worker")
T = TypeVar("T")

# Overall job progress at the start of each stage; the stage's own fraction fills its span.
STAGE_SPANS: dict[JobStage, tuple[float, float]] = {
    JobStage.BACKGROUND: (0.0, 0.05),
    JobStage.EDGES: (0.05, 0.1),
    JobStage.OPTIMISING: (0.1, 0.9),
    JobStage.REFINING: (0.9, 0.95),
    JobStage.STORING: (0.95, 1.0),
}
# After the grace period, the main thread gets this long to notice the abort before the process
# gives the job back and exits on its own.
HARD_EXIT_AFTER_S = 10.0
# Waits between tries of a database write that failed (doubling up to the last).
DB_RETRY_FIRST_S = 0.2
DB_RETRY_MAX_S = 5.0


class StoppedWhileWarmingUp(BaseException):
    """SIGTERM/SIGINT during the warm-up: no job is held, so the worker stops at once instead of
    compiling its kernels first (tens of seconds with an empty cache on a busy machine). A
    BaseException, so that the warm-up's own "log and go on" does not swallow it."""


class JobAborted(Exception):
    """Raised inside the calibration (from its progress callback) to stop work on a job."""


@dataclass
class Shutdown:
    """Set by SIGTERM/SIGINT; `deadline` is when the current job must be given up."""

    requested: threading.Event
    deadline: float | None = None

    def request(self, grace_s: float) -> None:
        if not self.requested.is_set():
            self.deadline = time.monotonic() + grace_s
            self.requested.set()


class Heartbeat(threading.Thread):
    """Renews the lease and writes progress; tells the main thread when to abort."""

    def __init__(
        self,
        engine: Engine,
        job: queue.ClaimedJob,
        worker_id: str,
        settings: Settings,
        shutdown: Shutdown,
    ) -> None:
        super().__init__(name=f"heartbeat-{job.id[:8]}", daemon=True)
        self.engine = engine
        self.job = job
        self.worker_id = worker_id
        self.lease_s = settings.lease_s
        self.heartbeat_s = settings.heartbeat_s
        self.interval_s = min(settings.progress_interval_s, settings.heartbeat_s)
        self.shutdown = shutdown
        self._lock = threading.Lock()
        self._latest = queue.Progress(stage=JobStage.BACKGROUND, progress=0.0)
        self._dirty = True
        self._stop_event = threading.Event()
        self.abort_reason: str | None = None  # "lease_lost" | "shutdown"
        self.released = False

    # -- called from the main thread
    def report(
        self,
        stage: JobStage,
        fraction: float,
        generation: int | None = None,
        best_fitness: float | None = None,
    ) -> None:
        lo, hi = STAGE_SPANS.get(stage, (0.0, 1.0))
        overall = lo + (hi - lo) * min(max(fraction, 0.0), 1.0)
        with self._lock:
            previous = self._latest
            self._latest = queue.Progress(
                stage=stage,
                progress=max(previous.progress, overall),
                generation=generation if generation is not None else previous.generation,
                best_fitness=best_fitness if best_fitness is not None else previous.best_fitness,
            )
            self._dirty = True
        self.check()

    def pipeline_progress(self, stage: str, fraction: float, info: dict[str, Any]) -> None:
        try:
            job_stage = JobStage(stage)
        except ValueError:  # a pipeline stage the jobs table does not know: keep the last one
            job_stage = self._latest.stage
        generation = info.get("generation")
        best = info.get("best_fitness")
        self.report(
            job_stage,
            fraction,
            int(generation) if generation is not None else None,
            float(best) if best is not None and np.isfinite(best) else None,
        )

    def check(self) -> None:
        if self.abort_reason is not None:
            raise JobAborted(self.abort_reason)

    def stop(self) -> None:
        self._stop_event.set()
        self.join(timeout=5 * self.interval_s + 5)

    # -- the thread
    def run(self) -> None:
        last_write = 0.0
        while not self._stop_event.wait(self.interval_s):
            now = time.monotonic()
            if (
                self.shutdown.deadline is not None
                and now > self.shutdown.deadline
                and self.abort_reason is None
            ):
                self.abort_reason = "shutdown"
                self.released = release_job(self.engine, self.job.id, self.worker_id)
                threading.Thread(target=self._hard_exit, daemon=True).start()
                return
            with self._lock:
                dirty = self._dirty
                latest = self._latest
                self._dirty = False
            if not dirty and now - last_write < self.heartbeat_s:
                continue
            try:
                ours = queue.heartbeat(
                    self.engine,
                    self.job.id,
                    self.worker_id,
                    self.lease_s,
                    latest if dirty else None,
                )
            except Exception:  # the database may be briefly unavailable; the lease has slack
                log.exception("heartbeat for job %s failed", self.job.id)
                with self._lock:
                    self._dirty = self._dirty or dirty
                continue
            last_write = now
            if not ours:
                self.abort_reason = "lease_lost"
                log.warning("job %s: lease lost, another worker owns it now", self.job.id)
                return

    def _hard_exit(self) -> None:
        if not self._stop_event.wait(HARD_EXIT_AFTER_S):
            log.error("job %s did not stop after the grace period; exiting", self.job.id)
            os._exit(0)


def _write_png(path: Any, image: np.ndarray) -> None:
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")


def process_job(
    engine: Engine,
    settings: Settings,
    job: queue.ClaimedJob,
    worker_id: str,
    shutdown: Shutdown,
) -> str:
    """Run one claimed job to its end. Returns the job's new status (or "released"/"lost")."""
    from app.calib import pipeline
    from app.viewer.pictures import line_evidence

    heartbeat = Heartbeat(engine, job, worker_id, settings, shutdown)
    heartbeat.start()
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    cal_dir = None
    try:
        heartbeat.report(JobStage.BACKGROUND, 0.0)
        t0 = time.perf_counter()
        background, moving_mask, background_info = _background(settings, job)
        timings["background"] = time.perf_counter() - t0
        for stage, seconds in background_info.get("timings_s", {}).items():
            timings[f"background.{stage}"] = float(seconds)
        heartbeat.report(JobStage.BACKGROUND, 1.0)

        kwargs: dict[str, Any] = {"seed": int(job.params.get("seed") or 0), "spec": job.spec}
        if job.params.get("start_genome") is not None:
            kwargs["start_genome"] = np.asarray(job.params["start_genome"], dtype=np.float64)
        if job.params.get("bundle"):
            kwargs["bundle"] = job.params["bundle"]
        if settings.ga_max_generations is not None:
            kwargs["max_generations"] = settings.ga_max_generations
        if settings.ga_time_budget_s is not None:
            kwargs["time_budget_s"] = settings.ga_time_budget_s
        t0 = time.perf_counter()
        moving_or_none = moving_mask if np.any(moving_mask) else None
        result = pipeline.calibrate(
            background,
            moving_mask=moving_or_none,
            progress=heartbeat.pipeline_progress,
            **kwargs,
        )
        timings["calibrate"] = time.perf_counter() - t0
        for stage, seconds in result.timings_s.items():
            timings[f"calibrate.{stage}"] = float(seconds)

        heartbeat.report(JobStage.STORING, 0.0)
        t0 = time.perf_counter()
        calibration_id = new_id()
        cal_dir = media.calibration_dir(settings, calibration_id)
        cal_dir.mkdir(parents=True, exist_ok=True)
        _write_png(cal_dir / "background.png", background)
        _write_png(
            cal_dir / "overlay.png", pipeline.draw_overlay(background, result.genome, job.spec)
        )
        # the line evidence the fit used (players masked out), for GET .../edges.png
        _write_png(cal_dir / "edges.png", line_evidence(background, moving_or_none))
        media.fsync_tree(cal_dir)
        heartbeat.check()
        result_json = result.to_json()
        result_json["background"] = background_info
        timings["storing"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_start
        calibration = Calibration(
            id=calibration_id,
            tenant_id=job.tenant_id,
            court_id=job.court_id,
            job_id=job.id,
            spec=job.spec,
            genome=result_json["genome"],
            opencv=result_json["opencv"],
            fitness=float(result.fitness),
            quality=result_json["quality"],
            result=result_json,
            image_width=int(result.image_size[0]),
            image_height=int(result.image_size[1]),
        )
        # no renewals past here: one landing after the final write would report a lost lease
        heartbeat.stop()
        _store_success(engine, settings, job, worker_id, calibration, _rounded(timings))
        cal_dir = None  # committed: keep the images
        log.info("job %s succeeded: calibration %s", job.id, calibration_id)
        return "succeeded"
    except JobAborted as exc:
        if str(exc) == "shutdown" and not heartbeat.released:
            heartbeat.released = release_job(engine, job.id, worker_id)
        log.warning("job %s stopped: %s", job.id, exc)
        return "released" if str(exc) == "shutdown" else "lost"
    except queue.LeaseLost:
        log.warning("job %s: lease lost before the result was stored; discarded", job.id)
        return "lost"
    except Exception as exc:
        heartbeat.stop()
        failure = classify(exc)
        if failure.log_traceback:
            log.error("job %s failed on attempt %d", job.id, job.attempt, exc_info=exc)
        return _fail(engine, settings, job, worker_id, failure, timings, t_start)
    finally:
        heartbeat.stop()
        if cal_dir is not None:  # not committed: leave no orphaned images behind
            shutil.rmtree(cal_dir, ignore_errors=True)


def clip_background(
    path: Path, settings: Settings
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """A clip's background stage as a job runs it (`background_from_clip` with the service's
    settings: its frames, duration and memory budget); raises ClipError."""
    return background_from_clip(
        path,
        n_frames=settings.background_frames,
        max_duration_s=settings.max_video_duration_s,
        max_frames_bytes=settings.max_clip_frames_mb * 1_000_000,
    )


def _background(
    settings: Settings, job: queue.ClaimedJob
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """The upload's player-free background, its moving mask, and what it was made from.

    A clip: from its longest static view (`background_from_clip`); the info records the shots
    and the time ranges used. Images: decoded one at a time into a FrameSpool (a temporary file)
    and estimated a band of rows at a time, so memory does not grow with the upload.
    """
    if job.media_kind == "video":
        path = media.job_dir(settings, job.id) / job.media_files[0]
        if not path.is_file():
            raise MediaError(
                "media_missing", f"the uploaded file is missing from storage: {path.name}"
            )
        try:
            return clip_background(path, settings)
        except ClipError as exc:
            raise MediaError(exc.code, str(exc)) from exc
    paths = job_paths(settings, job.id, job.media_files)
    with spool_images(paths, settings) as spool:
        background, moving_mask = background_from_bands(
            spool.n_frames, spool.height, spool.width, spool.read_rows
        )
        return background, moving_mask, {"frames_used": spool.n_frames}


def _rounded(timings: dict[str, float]) -> dict[str, float]:
    return {k: round(float(v), 4) for k, v in timings.items()}


def _store_success(
    engine: Engine,
    settings: Settings,
    job: queue.ClaimedJob,
    worker_id: str,
    calibration: Calibration,
    timings: dict[str, float],
) -> None:
    """Store the finished calibration, retried while the database is away (as a failure is):
    the work is done, and a dropped connection must not throw it away and burn the attempt.
    Raises LeaseLost, or the last error once a lease has passed (the job is then failed as a
    database error, or claimed again when its lease has run out)."""
    retry_db_write(
        lambda: queue.finish_success(engine, job, worker_id, calibration, timings),
        f"storing the calibration of job {job.id}",
        # past the lease another worker may claim the job: our result would be refused anyway
        give_up_after_s=settings.lease_s,
    )


def _fail(
    engine: Engine,
    settings: Settings,
    job: queue.ClaimedJob,
    worker_id: str,
    failure: Failure,
    timings: dict[str, float],
    t_start: float,
) -> str:
    """Record the failure (retried while the database is away, as a success is). Returns the
    job's new status, or
    "lost" (another worker owns it now) or "unrecorded" (gave up: the lease will expire and the
    job be claimed again)."""
    timings["total"] = time.perf_counter() - t_start
    delay_s = queue.retry_delay_s(
        job.attempt, settings.retry_backoff_s, settings.retry_backoff_max_s
    )
    try:
        status = retry_db_write(
            lambda: queue.finish_failure(
                engine,
                job.id,
                worker_id,
                failure.code,
                failure.message,
                failure.retryable,
                _rounded(timings),
                retry_delay_s=delay_s,
            ),
            f"recording the failure of job {job.id}",
            # past the lease another worker may claim the job: our record would be refused anyway
            give_up_after_s=settings.lease_s,
        )
    except queue.LeaseLost:
        return "lost"
    except Exception:
        log.error(
            "job %s: could not record its failure; it is retried when its lease expires", job.id
        )
        return "unrecorded"
    log.warning("job %s: %s (%s): %s", job.id, status, failure.code, failure.message)
    return status


def retry_db_write(write: Callable[[], T], what: str, give_up_after_s: float) -> T:
    """`write()`, tried again with growing waits while it raises anything but LeaseLost, until
    `give_up_after_s` have passed (then the last error is raised)."""
    deadline = time.monotonic() + give_up_after_s
    wait_s = DB_RETRY_FIRST_S
    while True:
        try:
            return write()
        except queue.LeaseLost:
            raise
        except Exception as exc:
            if time.monotonic() + wait_s > deadline:
                raise
            log.warning(
                "%s failed (%s: %s); retrying in %.1f s", what, type(exc).__name__, exc, wait_s
            )
        time.sleep(wait_s)
        wait_s = min(2 * wait_s, DB_RETRY_MAX_S)


def release_job(engine: Engine, job_id: str, worker_id: str) -> bool:
    """Give the job back to the queue; on a database error leave it to the lease (False)."""
    try:
        released = retry_db_write(
            lambda: queue.release(engine, job_id, worker_id),
            f"releasing job {job_id}",
            give_up_after_s=2.0,  # shutting down: do not hold the exit for long
        )
    except Exception:
        log.exception(
            "job %s: could not give it back; it is claimable when its lease expires", job_id
        )
        return False
    if released:
        log.warning("job %s given back to the queue", job_id)
    return released


def default_worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}"


def run_worker(settings: Settings, once: bool = False, worker_id: str | None = None) -> int:
    """Claim and process jobs until SIGTERM/SIGINT (or after one job with `once`)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    worker_id = worker_id or default_worker_id()
    shutdown = Shutdown(threading.Event())

    warming_up = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        log.info("signal %d: no new jobs; finishing the current one", signum)
        first = not shutdown.requested.is_set()
        shutdown.request(settings.shutdown_grace_s)
        if first and warming_up.is_set():
            raise StoppedWhileWarmingUp

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    if settings.warm_up:  # before the first claim, so that no job pays the kernels' compile
        try:
            warming_up.set()
            warmup.warm_up_best_effort(warmup.WORKER_PARTS)
            warming_up.clear()
        except StoppedWhileWarmingUp:
            log.info("worker %s stopped during the warm-up", worker_id)
            return 0
    engine = make_engine(settings)
    log.info("worker %s polling %s", worker_id, engine.url.render_as_string(hide_password=True))
    try:
        while not shutdown.requested.is_set():
            try:
                job = queue.claim(engine, worker_id, settings.lease_s)
            except Exception:
                log.exception("claim failed; retrying")
                job = None
            if job is None:
                if once:
                    return 0
                shutdown.requested.wait(settings.poll_interval_s)
                continue
            log.info("job %s claimed (attempt %d/%d)", job.id, job.attempt, job.max_attempts)
            try:
                process_job(engine, settings, job, worker_id, shutdown)
            except Exception:  # a bug in the bookkeeping: the lease brings the job back
                log.exception("job %s: the worker failed around it; going on", job.id)
            if once:
                return 0
    finally:
        engine.dispose()
    log.info("worker %s stopped", worker_id)
    return 0
