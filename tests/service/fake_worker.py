"""A real worker process with a stand-in calibration, for the queue's fault tests.

`python -m tests.service.fake_worker WORKER_ID EVENTS_DIR` runs `worker.main.run_worker` (signals,
claims, leases, heartbeats, `process_job`, storing, failure recording: all real) with the pipeline
(and the fsync of the stored images) replaced by a stand-in that takes `SQUASHCAL_FAKE_WORK_S`
seconds, reports progress as it goes (so shutdown and lost leases abort it as they would the real
one) and returns a camera whose first gene is the job's seed (so each result can be matched to its
job).

While a job is being worked on, `EVENTS_DIR/holds/<job id>` holds the worker's pid: a second live
worker on the same job is written to the events file as "double_hold". Events are JSON lines in
`EVENTS_DIR/<worker id>.jsonl`, flushed at once (they survive a SIGKILL).
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

FAKE_WORK_S = float(os.environ.get("SQUASHCAL_FAKE_WORK_S", "0.05"))
# progress (where the worker notices an abort) at least every 0.1 s, and at least 5 times; or,
# with SQUASHCAL_FAKE_SILENT=1, none at all (a long numerical kernel that cannot be interrupted)
SILENT = os.environ.get("SQUASHCAL_FAKE_SILENT") == "1"
PROGRESS_STEPS = 1 if SILENT else max(5, round(FAKE_WORK_S / 0.1))


@dataclass
class FakeResult:
    genome: np.ndarray
    fitness: float
    image_size: tuple[int, int]
    timings_s: dict[str, float]
    job_id: str

    def to_json(self) -> dict[str, Any]:
        return {
            "genome": self.genome.tolist(),
            "opencv": {},
            "quality": {},
            "job_id": self.job_id,
            "worker_pid": os.getpid(),
        }


class FakeCalibration:
    def __init__(self, worker_id: str, events_dir: Path) -> None:
        self.worker_id = worker_id
        self.holds = events_dir / "holds"
        self.holds.mkdir(parents=True, exist_ok=True)
        self.events = (events_dir / f"{worker_id}.jsonl").open("a", buffering=1)
        self.job_id = ""

    def event(self, kind: str, **fields: Any) -> None:
        record = {"event": kind, "worker": self.worker_id, "pid": os.getpid(), "t": time.time()}
        self.events.write(json.dumps({**record, **fields}) + "\n")
        self.events.flush()

    def background(self, settings: Any, job: Any) -> tuple[np.ndarray, np.ndarray, dict]:
        self.job_id = job.id
        self.event("start", job=job.id, attempt=job.attempt)
        image = np.zeros((24, 32, 3), np.uint8)
        return image, np.zeros((24, 32), bool), {}

    def calibrate(
        self, background: np.ndarray, *, progress: Any, seed: int, **_: Any
    ) -> FakeResult:
        self._hold()
        try:
            for step in range(PROGRESS_STEPS):
                time.sleep(FAKE_WORK_S / PROGRESS_STEPS)
                if not SILENT:
                    progress("optimising", (step + 1) / PROGRESS_STEPS, {})
        except BaseException as exc:
            self.event("aborted", job=self.job_id, reason=type(exc).__name__)
            raise
        finally:
            (self.holds / self.job_id).unlink(missing_ok=True)
        self.event("computed", job=self.job_id)
        genome = np.zeros(15)
        genome[0] = seed
        return FakeResult(genome, 1.0, (32, 24), {"fake": FAKE_WORK_S}, self.job_id)

    def _hold(self) -> None:
        path = self.holds / self.job_id
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            holder = int(path.read_text() or 0)
            if holder and _alive(holder):
                self.event("double_hold", job=self.job_id, other_pid=holder)
            path.write_text(str(os.getpid()))  # the other one is dead (SIGKILLed): take over
            return
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def main() -> int:
    from app import media
    from app.calib import pipeline
    from app.settings import get_settings
    from app.viewer import pictures
    from worker import main as worker_main

    worker_id, events_dir = sys.argv[1], Path(sys.argv[2])
    fake = FakeCalibration(worker_id, events_dir)
    worker_main._background = fake.background  # type: ignore[assignment]
    pipeline.calibrate = fake.calibrate  # type: ignore[assignment]
    pipeline.draw_overlay = lambda background, genome, spec: background  # type: ignore[assignment]
    pictures.line_evidence = lambda background, moving: background  # type: ignore[assignment]
    # what is measured here is the queue, not the disk (shared, and slow to fsync, on a test box)
    media.fsync_tree = lambda directory: None  # type: ignore[assignment]
    fake.event("worker_started")
    code = worker_main.run_worker(get_settings(), worker_id=worker_id)
    fake.event("worker_stopped")
    return code


if __name__ == "__main__":
    sys.exit(main())
