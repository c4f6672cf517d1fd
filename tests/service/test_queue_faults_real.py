"""The queue under SIGKILL with the real thing, on SQLite and PostgreSQL: the product's own worker
processes (`python -m worker`, what `squashcal run` starts) running the real calibration on small
court pictures rendered with known cameras, uploaded through the API.

test_queue_faults.py drives the queue at scale (200 jobs) with a stand-in calibration; this test
proves the real path with a few jobs. What it can observe of the real workers is what they record:
the jobs and calibrations tables, and each worker's log, the one record of every attempt (the
database keeps only a job's last one): "job J claimed (attempt k/m)" opens a hold of J, the
worker's last line about J (or its death) ends it.
"""

from __future__ import annotations

import itertools
import random
import re
import signal
import time
from collections import defaultdict
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import cv2
import numpy as np
import pytest
import sqlalchemy as sa
from sqlalchemy import select

from app.calib import camera, scene, search, synthetic
from app.calib.court import floor_grid
from app.db.models import Job, JobStage, JobStatus
from app.db.session import make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, new_key
from tests.service.helpers import files
from tests.service.test_api import make_court
from tests.service.test_queue_faults import (
    Workers,
    jobs_each_succeeded_once,
    statuses,
    wait_until_all_finished,
)

# Small enough to calibrate in a few seconds, large enough that every camera below calibrates to a
# fraction of a pixel (at 160 x 90 the search misses some courts).
SIZE = (320, 180)
# A lease that outlasts the longest stretch a calibration holds the GIL on a loaded 2-core box
# (the heartbeat thread waits for it: ~2 s at this size), so that no live worker loses its job and
# the holds must be strictly exclusive; a killed worker's job is claimable again within it.
REAL_QUEUE = {"lease_s": 8.0, "heartbeat_s": 1.0, "poll_interval_s": 0.2}
FLOOR = floor_grid("wsf", 16, 16)

LOG_LINE = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) \w+ squashcal\.worker (.*)$")
POLLING = re.compile(r"worker (\S+) polling ")
CLAIMED = re.compile(r"job (\w+) claimed \(attempt (\d+)/\d+\)")
SUCCEEDED = re.compile(r"job (\w+) succeeded: calibration (\w+)")


def known_camera(i: int) -> np.ndarray:
    """Job i's camera (i < 12): behind the back wall, at one of 6 places between the side walls and
    one of 2 heights (3.2 and 4 m), looking at the middle of the court, rolled a little, barrel
    distortion."""
    centre = [1.7 + 0.6 * (i % 6), 10.4 + 0.4 * (i // 6), -3.2 - 0.8 * (i // 6)]
    target = [3.2 + 0.3 * (i % 3 - 1), 4.2, 0.0]
    genome = search.look_at_genomes(
        np.array([centre]),
        np.array([target]),
        np.deg2rad([0.5 * (i % 5 - 2)]),
        np.array([530.0 * SIZE[0] / 1280]),
        SIZE,
    )[0]
    genome[camera.GENE["k1"]] = -0.08
    return genome


def floor_error_px(truth: np.ndarray, result: np.ndarray) -> float:
    """Mean pixel distance between the floor grid seen by the two cameras."""
    return synthetic.mean_reprojection_error(truth, result, FLOOR)


def upload_jobs(settings: Settings, cameras: list[np.ndarray]) -> list[str]:
    """One upload (a PNG of the court seen by the camera) per camera, through the API; -> job ids."""
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, auth)
        job_ids = []
        for i, genome in enumerate(cameras):
            ok, png = cv2.imencode(".png", scene.render_court_image(genome, SIZE, rng=i))
            assert ok
            response = client.post(
                f"/courts/{court_id}/calibrations", files=files(png.tobytes()), headers=auth
            )
            assert response.status_code == 202, response.text
            job_ids.append(response.json()["job_id"])
    return job_ids


@dataclass
class Hold:
    """One attempt at a job, from a worker's log: from its claim to the worker's next claim or its
    death (the attempt itself ends earlier, so the hold is, if anything, too long). `end` None: it
    may still hold the job."""

    job_id: str
    attempt: int
    worker_id: str
    start: datetime
    end: datetime | None = None
    stored: str | None = None  # the calibration it says it stored
    killed: bool = False  # SIGKILLed while it held the job


def read_log(path: Path, killed_at: datetime | None = None) -> tuple[str | None, list[Hold]]:
    """(the worker's id, its holds) from one worker process's log."""
    worker_id = None
    holds: list[Hold] = []
    for line in path.read_text(errors="replace").splitlines():
        if not (m := LOG_LINE.match(line)):
            continue  # other loggers, tracebacks
        at, message = datetime.strptime(m[1], "%Y-%m-%d %H:%M:%S,%f"), m[2]
        if polling := POLLING.match(message):
            worker_id = polling[1]
        elif claimed := CLAIMED.match(message):
            assert worker_id is not None, line
            if holds:
                holds[-1].end = at
            holds.append(Hold(claimed[1], int(claimed[2]), worker_id, at))
        elif holds and (succeeded := SUCCEEDED.match(message)):
            assert succeeded[1] == holds[-1].job_id, line
            holds[-1].stored = succeeded[2]
    if holds and killed_at is not None:
        holds[-1].end, holds[-1].killed = killed_at, holds[-1].stored is None
    return worker_id, holds


class RealWorkers(Workers):
    """`python -m worker` processes; knows when it SIGKILLed which."""

    def __init__(self, settings: Settings, tmp_path: Path) -> None:
        super().__init__(settings, tmp_path, **REAL_QUEUE)
        self.killed_at: dict[int, datetime] = {}  # by pid

    def worker_ids(self) -> dict[str, str]:
        """Live processes' worker ids (once they are polling) -> their names."""
        ids = {}
        for name, process in self.processes.items():
            if process.poll() is None:
                worker_id, _ = read_log(self.log_paths[process.pid])
                if worker_id is not None:
                    ids[worker_id] = name
        return ids

    def wait_until_up(self, timeout_s: float) -> None:
        """Until every live worker polls (the kernels loaded from numba's on-disk cache take
        seconds; minutes when the cache is empty)."""
        deadline = time.monotonic() + timeout_s
        while len(self.worker_ids()) < len(self.processes):
            assert time.monotonic() < deadline, f"workers did not start; see {self.log_dir}"
            assert all(p.poll() is None for p in self.processes.values()), self.log_dir
            time.sleep(0.2)

    def kill_and_restart(self, name: str) -> None:
        process = self.processes[name]
        process.send_signal(signal.SIGKILL)
        process.wait(10)
        self.killed_at[process.pid] = datetime.now()
        self.start(name)

    def holds(self) -> list[Hold]:
        """Every attempt of every worker process started."""
        return [
            hold
            for pid, path in self.log_paths.items()
            for hold in read_log(path, self.killed_at.get(pid))[1]
        ]


def busy_workers(engine: sa.Engine, workers: RealWorkers) -> list[str]:
    """Names of the live workers in the middle of a calibration (searching for the camera or
    refining it: past the start, not yet storing)."""
    with make_sessionmaker(engine)() as session:
        running = set(
            session.scalars(
                select(Job.worker_id).where(
                    Job.status == JobStatus.RUNNING,
                    Job.stage.in_([JobStage.OPTIMISING, JobStage.REFINING]),
                )
            )
        )
    return sorted(name for worker_id, name in workers.worker_ids().items() if worker_id in running)


@pytest.mark.slow
def test_real_workers_sigkilled_and_restarted_each_job_succeeds_once_with_its_own_camera(
    engine: sa.Engine, any_db_settings: Settings, tmp_path: Path
) -> None:
    """N = 8 jobs on 4 workers, 3 SIGKILLs of a worker in the middle of a calibration, each worker
    restarted at once.

    Why N = 8: the test costs ~80 CPU-seconds: a worker's start ~6 (imports, then the kernels
    loaded from numba's on-disk cache; 7 starts), one calibration of a 320 x 180 picture 3-5 (the
    camera search dominates: smaller pictures are hardly quicker) for 8 jobs and the work the kills
    throw away, the test's own renders and uploads ~5. That is ~35 s per database on 2 free cores
    (~80 s next to another benchmark), with every worker computing jobs and the kills landing
    while jobs are being worked on. The queue's scale (200 jobs) is test_queue_faults.py's, with a
    stand-in calibration."""
    n_jobs, n_kills = 8, 3
    cameras = [known_camera(i) for i in range(n_jobs)]
    # a result stored for the wrong job could not pass for that job's own camera
    apart = [floor_error_px(a, b) for i, a in enumerate(cameras) for b in cameras[i + 1 :]]
    assert min(apart) > 3.0
    job_ids = upload_jobs(any_db_settings.model_copy(update={"max_attempts": 10}), cameras)
    camera_of = dict(zip(job_ids, cameras, strict=True))

    workers = RealWorkers(any_db_settings, tmp_path)
    try:
        names = [f"w{i}" for i in range(4)]
        for name in names:
            workers.start(name)
        workers.wait_until_up(timeout_s=300)
        rng = random.Random(8)
        kills = 0
        deadline = time.monotonic() + 240
        while kills < n_kills:
            assert statuses(engine)[JobStatus.SUCCEEDED] < n_jobs, f"only {kills} kills"
            assert time.monotonic() < deadline
            time.sleep(rng.uniform(0.5, 2.0))
            if busy := busy_workers(engine, workers):
                workers.kill_and_restart(rng.choice(busy))
                kills += 1
        wait_until_all_finished(engine, n_jobs, timeout_s=deadline - time.monotonic())
        assert all(p.poll() is None for p in workers.processes.values()), "a worker died"
        holds = workers.holds()
        assert set(workers.stop_all().values()) == {0}
    finally:
        workers.stop_all()

    # every job succeeded, exactly once, with the camera that made its picture
    jobs, calibrations = jobs_each_succeeded_once(engine, job_ids)
    for cal in calibrations:
        job = jobs[str(cal.job_id)]
        assert job.calibration_id == cal.id
        assert (cal.image_width, cal.image_height) == SIZE
        error_px = floor_error_px(camera_of[job.id], np.array(cal.genome))
        assert error_px < 1.0, f"job {job.id}: its result is {error_px:.1f} px off its camera"

    # No job held by two workers at once; every attempt counted in the jobs table; a job tried
    # again only after its worker was killed; the result stored by the last attempt, which said so
    # (unless its worker was killed just after).
    by_job: dict[str, list[Hold]] = defaultdict(list)
    for hold in holds:
        by_job[hold.job_id].append(hold)
    for job_id, job in jobs.items():
        attempts = sorted(by_job[job_id], key=lambda h: h.start)
        for before, after in itertools.pairwise(attempts):
            assert before.end is not None and before.end < after.start, (
                f"job {job_id} held by two workers at once: {before} and {after}"
            )
        assert [h.attempt for h in attempts] == list(range(1, job.attempts + 1)), attempts
        assert all(h.killed for h in attempts[:-1]), f"tried again, no kill: {attempts}"
        last = attempts[-1]
        assert last.worker_id == job.worker_id, attempts
        assert last.stored == job.calibration_id or last.killed, attempts
    # the kills interrupted jobs (one may have come as its job was stored), which were taken again
    interrupted = [h for h in holds if h.killed and h.worker_id != jobs[h.job_id].worker_id]
    assert len(interrupted) >= n_kills - 1, holds
    assert all(jobs[h.job_id].attempts > h.attempt for h in interrupted)
