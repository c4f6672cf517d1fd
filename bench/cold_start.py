"""Cold start: the first job and the first /project of a fresh install, without and with warm-up.

    .venv/bin/python -m bench.cold_start [--modes off,on] [--keep-cache]

Per mode: a new data directory and an EMPTY numba cache (NUMBA_CACHE_DIR a new temporary
directory, as on a fresh checkout or in a container without a built cache), then a real API
(`python -m app.cli serve`) and one worker (`python -m worker`) with SQUASHCAL_WARM_UP=0 ("off":
the service as it was before the warm-up) or 1 ("on"). Measured from the processes' spawn:
- API ready: /readyz answers 200 (with warm-up: after the kernels are loaded);
- worker ready: the worker logs that it polls (with warm-up: after the kernels are loaded);
- /project 1st, 2nd: one point, right after /readyz said ready (a camera is seeded in the database);
- job 1st, 2nd: upload of the demo clip (1280x720, 40 frames, two players) to the job's success,
  sent once the worker is ready.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import httpx

from app.api.demo import demo_clip_path
from app.calib import synthetic
from app.db.migrate import upgrade_head
from app.settings import Settings
from bench.common import command_line, format_table
from bench.service_load import SIZE, free_port, seed_database, wait_ready

READY_TIMEOUT_S = 900.0  # an empty cache on a busy 2-core machine compiles for minutes
JOB_TIMEOUT_S = 900.0


@dataclass
class ModeResult:
    mode: str
    api_ready_s: float
    worker_ready_s: float
    project_ms: tuple[float, float]
    job_s: tuple[float, float]


class LineWatcher(threading.Thread):
    """Reads a child's log; `seen` is set when a line containing `needle` arrives."""

    def __init__(self, stream: IO[bytes], needle: str, log_path: Path) -> None:
        super().__init__(daemon=True)
        self.stream, self.needle, self.log_path = stream, needle, log_path
        self.seen = threading.Event()
        self.seen_at = 0.0  # perf_counter() when the line arrived

    def run(self) -> None:
        with self.log_path.open("wb") as log:
            for line in self.stream:
                log.write(line)
                log.flush()
                if not self.seen.is_set() and self.needle in line.decode(errors="replace"):
                    self.seen_at = time.perf_counter()
                    self.seen.set()


def timed_project(client: httpx.Client, court_id: str) -> float:
    began = time.perf_counter()
    client.post("/project", json={"court_id": court_id, "pixels": [[960, 700]]}).raise_for_status()
    return 1000 * (time.perf_counter() - began)


def timed_job(client: httpx.Client, court_id: str, clip: Path) -> float:
    """Seconds from the upload to the job's success (polled every 50 ms)."""
    began = time.perf_counter()
    with clip.open("rb") as f:
        response = client.post(
            f"/courts/{court_id}/calibrations", files={"files": (clip.name, f, "video/mp4")}
        )
    response.raise_for_status()
    job_id = response.json()["job_id"]
    while time.perf_counter() - began < JOB_TIMEOUT_S:
        job = client.get(f"/jobs/{job_id}").json()
        if job["status"] == "succeeded":
            return time.perf_counter() - began
        if job["status"] == "failed":
            raise RuntimeError(f"job failed: {job['error']}")
        time.sleep(0.05)
    raise TimeoutError("job did not finish")


def run_mode(mode: str, clip: Path, work: Path, keep_cache: bool) -> ModeResult:
    data_dir = work / f"data-{mode}"
    cache_dir = work / f"numba-{mode}"
    cache_dir.mkdir()
    settings = Settings(data_dir=data_dir)
    upgrade_head(settings)
    key, court_id = seed_database(settings, synthetic.typical_target_camera(SIZE))
    port = free_port()
    env = {
        **os.environ,
        "SQUASHCAL_DATA_DIR": str(data_dir),
        "SQUASHCAL_WARM_UP": "1" if mode == "on" else "0",
        "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", "") if keep_cache else str(cache_dir),
        "SQUASHCAL_POLL_INTERVAL_S": "0.1",
    }
    began = time.perf_counter()
    api = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = subprocess.Popen(
        [sys.executable, "-m", "worker"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    assert worker.stdout is not None
    watcher = LineWatcher(worker.stdout, " polling ", work / f"worker-{mode}.log")
    watcher.start()
    try:
        url = f"http://127.0.0.1:{port}"
        wait_ready(url, READY_TIMEOUT_S)
        api_ready = time.perf_counter() - began
        headers = {"Authorization": f"Bearer {key}"}
        with httpx.Client(base_url=url, headers=headers, timeout=JOB_TIMEOUT_S) as client:
            project = (timed_project(client, court_id), timed_project(client, court_id))
            if not watcher.seen.wait(max(0.0, began + READY_TIMEOUT_S - time.perf_counter())):
                raise TimeoutError("worker not ready")
            worker_ready = watcher.seen_at - began
            jobs = (timed_job(client, court_id, clip), timed_job(client, court_id, clip))
    finally:
        for process in (api, worker):
            process.terminate()
        for process in (api, worker):
            process.wait(60)
    return ModeResult(mode, api_ready, worker_ready, project, jobs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--modes", default="off,on", help="warm-up off, on, or both (default)")
    parser.add_argument(
        "--keep-cache", action="store_true", help="use the normal numba cache (not an empty one)"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="squashcal-cold-") as tmp:
        work = Path(tmp)
        clip = demo_clip_path(work / "clip")
        results = [run_mode(mode, clip, work, args.keep_cache) for mode in args.modes.split(",")]
    print(command_line())
    cache = "the normal numba cache" if args.keep_cache else "an empty numba cache per mode"
    print(
        f"API + 1 worker from spawn, {cache}; demo clip 1280x720, 40 frames; {os.cpu_count()} CPUs"
    )
    print(
        format_table(
            [
                "warm-up",
                "API ready s",
                "worker ready s",
                "/project 1st ms",
                "/project 2nd ms",
                "job 1st s",
                "job 2nd s",
            ],
            [
                [
                    r.mode,
                    f"{r.api_ready_s:.1f}",
                    f"{r.worker_ready_s:.1f}",
                    f"{r.project_ms[0]:.1f}",
                    f"{r.project_ms[1]:.1f}",
                    f"{r.job_s[0]:.1f}",
                    f"{r.job_s[1]:.1f}",
                ]
                for r in results
            ],
        )
    )


if __name__ == "__main__":
    main()
