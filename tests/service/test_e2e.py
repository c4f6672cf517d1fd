"""End to end: the real API (uvicorn) and real worker processes, talking through the database.

Each test gets its own data directory, port and processes. The GA runs with the pipeline's own
stopping rules (no time budget), so results do not depend on how busy the machine is.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from app.calib import camera, synthetic
from tests.service.helpers import court_clip_bytes, files

pytestmark = pytest.mark.e2e

REPO_ROOT = Path(__file__).resolve().parents[2]
SIZE = (1280, 720)
MID_COURT_M = np.array([[3.2, 5.44], [2.4, 5.0], [4.0, 6.0], [3.2, 4.5], [3.2, 6.5]])


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LiveService:
    def __init__(self, data_dir: Path, **settings: object) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.env = {
            **os.environ,
            "SQUASHCAL_DATA_DIR": str(data_dir),
            "SQUASHCAL_BACKGROUND_FRAMES": "9",
            "SQUASHCAL_POLL_INTERVAL_S": "0.2",
            "SQUASHCAL_PROGRESS_INTERVAL_S": "0.2",
            "SQUASHCAL_CAMERA_REFRESH_S": "0.2",
            # (None: the setting's default, e.g. database_url=None for SQLite in data_dir)
            **{f"SQUASHCAL_{k.upper()}": str(v) for k, v in settings.items() if v is not None},
        }
        self.processes: list[subprocess.Popen[bytes]] = []
        self.logs: list = []
        self.log_dir = data_dir.parent

    def cli(self, *args: str) -> str:
        done = subprocess.run(
            [sys.executable, "-m", "app.cli", *args],
            cwd=REPO_ROOT,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0, done.stderr
        return done.stdout

    def spawn(self, name: str, *args: str) -> subprocess.Popen[bytes]:
        log = (self.log_dir / f"{name}-{len(self.processes)}.log").open("wb")
        self.logs.append(log)
        process = subprocess.Popen(
            [sys.executable, *args], cwd=REPO_ROOT, env=self.env, stdout=log, stderr=log
        )
        self.processes.append(process)
        return process

    def start_api(self) -> None:
        self.cli("migrate")
        self.spawn("api", "-m", "app.cli", "serve", "--port", str(self.port))
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{self.url}/readyz", timeout=2).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        raise AssertionError(f"API did not become ready; see {self.log_dir}")

    def start_worker(self) -> subprocess.Popen[bytes]:
        return self.spawn("worker", "-m", "worker")

    def new_key(self) -> dict[str, str]:
        key = self.cli("keys", "create", "--name", "e2e").strip().splitlines()[-1]
        return {"Authorization": f"Bearer {key}"}

    def stop(self) -> None:
        for p in self.processes:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in self.processes:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for log in self.logs:
            log.close()


@pytest.fixture
def live_factory(tmp_path: Path) -> Iterator:
    services: list[LiveService] = []

    def make(**settings: object) -> LiveService:
        service = LiveService(tmp_path / "data", **settings)
        services.append(service)
        service.start_api()
        return service

    yield make
    for service in services:
        service.stop()


def poll_job(
    client: httpx.Client,
    job_url: str,
    auth: dict[str, str],
    until: set[str],
    timeout_s: float = 180,
) -> list[dict]:
    """Job snapshots until its status is in `until`."""
    seen = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(job_url, headers=auth).json()
        seen.append(job)
        if job["status"] in until:
            return seen
        time.sleep(0.1)
    raise AssertionError(f"job never reached {until}: last {seen[-1]}")


def upload_clip(
    client: httpx.Client, auth: dict[str, str], tmp_path: Path, genome: np.ndarray, seed: int
) -> tuple[str, str]:
    court_id = client.post("/courts", json={"name": "e2e"}, headers=auth).json()["id"]
    clip = court_clip_bytes(tmp_path, genome, SIZE, n_frames=40, seed=seed, n_players=2)
    response = client.post(f"/courts/{court_id}/calibrations", files=files(clip), headers=auth)
    assert response.status_code == 202, response.text
    return court_id, response.headers["location"]


def mid_court_error_cm(
    client: httpx.Client, auth: dict[str, str], court_id: str, genome: np.ndarray
) -> np.ndarray:
    pixels = camera.floor_to_pixel(genome, MID_COURT_M)
    body = client.post(
        "/project", json={"court_id": court_id, "pixels": pixels.tolist()}, headers=auth
    ).json()
    assert all(p is not None for p in body["points"]), body
    return 100 * np.linalg.norm(np.array(body["points"]) - MID_COURT_M, axis=1)


@pytest.mark.slow
def test_clip_upload_to_camera_to_project(live_factory, tmp_path: Path) -> None:
    live = live_factory()
    live.start_worker()
    auth = live.new_key()
    genome = synthetic.typical_target_camera(SIZE)
    with httpx.Client(base_url=live.url, timeout=30) as client:
        assert client.get("/courts").status_code == 401
        court_id, job_url = upload_clip(client, auth, tmp_path, genome, seed=21)
        snapshots = poll_job(client, job_url, auth, {"succeeded", "failed"})
        job = snapshots[-1]
        assert job["status"] == "succeeded", job
        assert job["attempts"] == 1
        progress = [s["progress"] for s in snapshots]
        assert progress == sorted(progress)  # never goes backwards
        assert {s["stage"] for s in snapshots} & {"background", "edges", "optimising", "refining"}
        cam = client.get(f"/courts/{court_id}/camera", headers=auth).json()
        assert cam["id"] == job["calibration_id"] and cam["job_id"] == job_url.split("/")[-1]
        error_cm = mid_court_error_cm(client, auth, court_id, genome)
        assert error_cm.max() < 2.0, error_cm
        # another tenant sees none of it
        other = live.new_key()
        assert client.get(job_url, headers=other).status_code == 404
        assert client.get(f"/courts/{court_id}/camera", headers=other).status_code == 404
        overlay = client.get(f"/calibrations/{cam['id']}/overlay.png", headers=auth)
        assert overlay.status_code == 200 and overlay.content.startswith(b"\x89PNG")


@pytest.mark.slow
def test_killed_worker_job_is_reclaimed_and_succeeds(live_factory, tmp_path: Path) -> None:
    live = live_factory(lease_s=2, heartbeat_s=0.5)
    first = live.start_worker()
    auth = live.new_key()
    genome = synthetic.typical_target_camera(SIZE)
    with httpx.Client(base_url=live.url, timeout=30) as client:
        court_id, job_url = upload_clip(client, auth, tmp_path, genome, seed=22)
        running = poll_job(client, job_url, auth, {"running", "succeeded", "failed"})[-1]
        assert running["status"] == "running", running
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        live.start_worker()
        job = poll_job(client, job_url, auth, {"succeeded", "failed"})[-1]
        assert job["status"] == "succeeded", job
        assert job["attempts"] == 2
        assert mid_court_error_cm(client, auth, court_id, genome).max() < 2.0


@pytest.mark.slow
def test_sigterm_finishes_or_releases_the_current_job(live_factory, tmp_path: Path) -> None:
    # grace 0: the job is given back at once (attempt not counted), and another worker finishes it
    live = live_factory(shutdown_grace_s=0)
    worker = live.start_worker()
    auth = live.new_key()
    genome = synthetic.typical_target_camera(SIZE)
    with httpx.Client(base_url=live.url, timeout=30) as client:
        _, job_url = upload_clip(client, auth, tmp_path, genome, seed=23)
        assert poll_job(client, job_url, auth, {"running"})[-1]["status"] == "running"
        worker.send_signal(signal.SIGTERM)
        assert worker.wait(30) == 0
        job = client.get(job_url, headers=auth).json()
        assert (job["status"], job["attempts"]) == ("queued", 0), job
        # a generous grace period: SIGTERM lets the job finish, then the worker exits
        live.env["SQUASHCAL_SHUTDOWN_GRACE_S"] = "120"
        worker = live.start_worker()
        assert poll_job(client, job_url, auth, {"running"})[-1]["status"] == "running"
        worker.send_signal(signal.SIGTERM)
        assert worker.wait(120) == 0
        job = client.get(job_url, headers=auth).json()
        assert (job["status"], job["attempts"]) == ("succeeded", 1), job


def test_squashcal_run_starts_everything_and_says_how(tmp_path: Path) -> None:
    port = free_port()
    env = {**os.environ, "SQUASHCAL_DATA_DIR": str(tmp_path / "data")}
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "run", "--port", str(port)],
        cwd=REPO_ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert process.stdout is not None
        lines = []
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = process.stdout.readline()
            lines.append(line)
            if "Authorization: Bearer" in line:
                break
        output = "".join(lines)
        assert f"http://127.0.0.1:{port}" in output
        assert "keys create" in output
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.2)
        assert httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2).json()["status"] == "ready"
    finally:
        process.send_signal(signal.SIGTERM)
        code = process.wait(60)
        assert process.stdout is not None
        process.stdout.close()
    assert code == 0
    with pytest.raises(httpx.TransportError):
        httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=2)
