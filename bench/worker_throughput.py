"""Calibrations per minute with 1, 2 and 4 worker processes, on SQLite and PostgreSQL; and a soak.

    .venv/bin/python -m bench.worker_throughput [--jobs 12] [--workers 1 2 4] [--db sqlite postgres]
        [--size 960x540] [--frames 6]
    .venv/bin/python -m bench.worker_throughput --soak-minutes 10 [--soak-workers 2]

Throughput: for each database and worker count, a fresh database (SQLite file, or a throwaway
PostgreSQL schema at 127.0.0.1:5432/test, dropped afterwards) and a real `squashcal serve`;
K jobs are uploaded through the API first (each a few synthetic frames of a court with two
players moving, rendered by app.calib.scene from a known camera: what the real pipeline
calibrates), then N `python -m worker` processes start. The rate is K over the time from the
first job's start to the last job's end (the workers' start-up and warm-up are not counted).
Each job is checked against its camera (the court centre through /project, in cm).

Soak: one API process and `--soak-workers` workers on SQLite for the given minutes; uploads keep
workers + 2 jobs queued or running while a client sends /project requests of 1 to 1000 points without pause.
Prints the API's and the workers' RSS when ready, after the first minute and at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import httpx
import numpy as np
import sqlalchemy as sa

from app.calib import camera, scene, synthetic
from app.db.migrate import upgrade_head
from app.db.models import Job
from app.settings import Settings
from bench.common import command_line, format_table
from bench.service_load import free_port, wait_ready

POSTGRES_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
REPO_ROOT = Path(__file__).resolve().parents[1]
CENTRE_M = np.array([[3.2, 5.44]])


@contextlib.contextmanager
def database(kind: str, data_dir: Path) -> Iterator[dict[str, str]]:
    """Environment for a fresh, migrated database of `kind` (cleaned up afterwards)."""
    # one key uploads everything here: the per-tenant upload rate would measure itself, not the
    # workers
    env = {
        "SQUASHCAL_DATA_DIR": str(data_dir),
        "SQUASHCAL_MAX_UPLOADS_PER_HOUR_PER_TENANT": "100000",
    }
    if kind == "sqlite":
        upgrade_head(Settings(data_dir=data_dir))
        yield env
        return
    schema = f"squashcal_bench_{uuid.uuid4().hex[:12]}"
    admin = sa.create_engine(POSTGRES_URL, connect_args={"connect_timeout": 5})
    with admin.begin() as conn:
        conn.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
    try:
        url = f"{POSTGRES_URL}?options=-csearch_path%3D{schema}"
        env["SQUASHCAL_DATABASE_URL"] = url
        upgrade_head(Settings(data_dir=data_dir, database_url=url))
        yield env
    finally:
        with admin.begin() as conn:
            conn.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


def render_upload(
    genome: np.ndarray, size: tuple[int, int], n_frames: int, seed: int
) -> list[bytes]:
    """PNG frames of the court seen by `genome`, two players moving (one upload)."""
    frames = scene.render_clip_frames(genome, size, n_frames, seed, n_players=2)
    return [cv2.imencode(".png", frame)[1].tobytes() for frame in frames]


def as_files(pngs: list[bytes]) -> list[tuple[str, tuple[str, bytes, str]]]:
    return [("files", (f"frame{i}.png", data, "image/png")) for i, data in enumerate(pngs)]


@dataclass
class Service:
    """A `squashcal serve` plus workers, started as the product starts them."""

    env: dict[str, str]
    log_dir: Path
    port: int = field(default_factory=free_port)
    api: subprocess.Popen[bytes] | None = None
    workers: list[subprocess.Popen[bytes]] = field(default_factory=list)
    logs: list[io.BufferedWriter] = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def _spawn(self, name: str, argv: list[str]) -> subprocess.Popen[bytes]:
        log = (self.log_dir / f"{name}.log").open("wb")
        self.logs.append(log)
        return subprocess.Popen(
            [sys.executable, *argv],
            cwd=REPO_ROOT,
            env={**os.environ, **self.env},
            stdout=log,
            stderr=log,
        )

    def start_api(self) -> None:
        argv = ["-m", "app.cli", "serve", "--port", str(self.port), "--no-access-log"]
        self.api = self._spawn("api", argv + ["--log-level", "warning"])
        wait_ready(self.url, 600)

    def start_workers(self, n: int) -> None:
        for _ in range(n):
            name = f"bench-worker-{len(self.workers) + 1}"
            self.workers.append(self._spawn(name, ["-m", "worker", "--worker-id", name]))

    def key(self) -> dict[str, str]:
        done = subprocess.run(
            [sys.executable, "-m", "app.cli", "keys", "create", "--name", "bench"],
            cwd=REPO_ROOT,
            env={**os.environ, **self.env},
            capture_output=True,
            text=True,
            check=True,
        )
        return {"Authorization": f"Bearer {done.stdout.strip().splitlines()[-1]}"}

    def stop(self) -> None:
        processes = [p for p in [self.api, *self.workers] if p is not None]
        for p in processes:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in processes:
            try:
                p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for log in self.logs:
            log.close()


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def hwm_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def centre_error_cm(
    client: httpx.Client, auth: dict[str, str], court_id: str, genome: np.ndarray
) -> float:
    pixel = camera.floor_to_pixel(genome, CENTRE_M)
    body = client.post(
        "/project", json={"court_id": court_id, "pixels": pixel.tolist()}, headers=auth
    ).json()
    point = body["points"][0]
    return float("inf") if point is None else 100 * float(np.linalg.norm(point - CENTRE_M[0]))


def load_average() -> float:
    return os.getloadavg()[0]


def throughput_row(
    kind: str,
    n_workers: int,
    uploads: list[list[bytes]],
    genome: np.ndarray,
    args: argparse.Namespace,
) -> list[object]:
    load_before = load_average()
    with tempfile.TemporaryDirectory(prefix="squashcal-tput-") as tmp:
        data_dir = Path(tmp) / "data"
        with database(kind, data_dir) as env:
            service = Service(env, Path(tmp))
            try:
                service.start_api()
                auth = service.key()
                courts: list[str] = []
                with httpx.Client(base_url=service.url, timeout=120) as client:
                    for i in range(args.jobs):
                        court = client.post("/courts", json={"name": f"c{i}"}, headers=auth)
                        court_id = court.json()["id"]
                        files = as_files(uploads[i % len(uploads)])
                        response = client.post(
                            f"/courts/{court_id}/calibrations", files=files, headers=auth
                        )
                        assert response.status_code == 202, response.text
                        courts.append(court_id)
                    service.start_workers(n_workers)
                    engine = sa.create_engine(
                        env.get("SQUASHCAL_DATABASE_URL")
                        or f"sqlite:///{data_dir / 'squashcal.sqlite3'}"
                    )
                    try:
                        pids = [w.pid for w in service.workers]
                        jobs, worker_cpu_s = wait_finished(
                            engine, args.jobs, timeout_s=60 * args.jobs, pids=pids
                        )
                    finally:
                        engine.dispose()
                    time.sleep(1.0)  # the API's camera cache refreshes every 0.5 s
                    errors = [centre_error_cm(client, auth, c, genome) for c in courts]
            finally:
                service.stop()
    succeeded = [j for j in jobs if j.status == "succeeded"]
    first = min(j.started_at for j in jobs if j.started_at)
    last = max(j.finished_at for j in jobs if j.finished_at)
    wall_s = (last - first).total_seconds()
    per_job = [
        (j.finished_at - j.started_at).total_seconds()
        for j in succeeded
        if j.finished_at and j.started_at
    ]
    return [
        kind,
        n_workers,
        args.jobs,
        len(succeeded),
        f"{wall_s:.1f}",
        f"{60 * len(succeeded) / wall_s:.1f}",
        f"{np.mean(per_job):.1f}" if per_job else "-",
        f"{worker_cpu_s / max(1, len(succeeded)):.1f}",
        f"{max(errors):.2f}",
        f"{load_before:.1f} / {load_average():.1f}",
    ]


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_finished(
    engine: sa.Engine, n: int, timeout_s: float, pids: list[int]
) -> tuple[list[Job], float]:
    """The jobs once `n` have finished, and the CPU seconds the processes `pids` spent from
    the first job's start (workers claim only once warmed up) to then."""
    deadline = time.monotonic() + timeout_s
    cpu_at_first_start: float | None = None
    while True:
        with sa.orm.Session(engine) as session:
            jobs = list(session.scalars(sa.select(Job)))
            session.expunge_all()
        if cpu_at_first_start is None and any(j.started_at for j in jobs):
            cpu_at_first_start = sum(cpu_s(pid) for pid in pids)
        if sum(j.status in ("succeeded", "failed") for j in jobs) >= n:
            return jobs, sum(cpu_s(pid) for pid in pids) - (cpu_at_first_start or 0.0)
        if time.monotonic() > deadline:
            raise TimeoutError(f"{n} jobs not finished after {timeout_s} s")
        time.sleep(0.5)


def throughput(args: argparse.Namespace) -> None:
    genome = synthetic.typical_target_camera(args.size)
    uploads = [render_upload(genome, args.size, args.frames, seed) for seed in range(4)]
    rows = []
    for kind in args.db:
        for n_workers in args.workers:
            rows.append(throughput_row(kind, n_workers, uploads, genome, args))
            print(f"  {rows[-1]}", file=sys.stderr, flush=True)
    print(command_line())
    mb = sum(len(p) for p in uploads[0]) / 1e6
    print(
        f"{args.jobs} jobs of {args.frames} PNG frames {args.size[0]}x{args.size[1]} "
        f"({mb:.1f} MB each); {os.cpu_count()} CPUs; rate = succeeded jobs over first start to "
        "last finish; CPU s/job = the workers' CPU time from the first start to the end, per job; "
        "error = worst court-centre error through /project; load = 1-min load average of the "
        "machine (other work shares it)"
    )
    headers = [
        "database",
        "workers",
        "jobs",
        "succeeded",
        "wall s",
        "calib/min",
        "mean job s",
        "CPU s/job",
        "max err cm",
        "load before/after",
    ]
    print(format_table(headers, rows))


@dataclass
class SoakCounts:
    project_requests: int = 0
    project_errors: int = 0
    uploads: int = 0
    upload_refused: int = 0
    # "status code: error code" of each refused upload, to tell throttling from a fault
    refusals: Counter[str] = field(default_factory=Counter)
    stop: threading.Event = field(default_factory=threading.Event)


def _refusal_of(response: httpx.Response) -> str:
    try:
        code = response.json().get("error", {}).get("code", "?")
    except ValueError:
        code = "not JSON"
    return f"{response.status_code}: {code}"


def _project_traffic(url: str, auth: dict[str, str], court_id: str, counts: SoakCounts) -> None:
    rng = np.random.default_rng(1)
    with httpx.Client(base_url=url, timeout=30) as client:
        while not counts.stop.is_set():
            n = int(rng.choice([1, 10, 100, 1000]))
            pixels = rng.uniform([0, 0], [960, 540], (n, 2)).round(2).tolist()
            try:
                response = client.post(
                    "/project", json={"court_id": court_id, "pixels": pixels}, headers=auth
                )
                ok = response.status_code == 200
            except httpx.HTTPError:
                ok = False
            counts.project_requests += 1
            counts.project_errors += not ok


def soak(args: argparse.Namespace) -> None:
    genome = synthetic.typical_target_camera(args.size)
    uploads = [render_upload(genome, args.size, args.frames, seed) for seed in range(4)]
    counts = SoakCounts()
    snapshots: list[tuple[str, float, list[float]]] = []
    with tempfile.TemporaryDirectory(prefix="squashcal-soak-") as tmp:
        data_dir = Path(tmp) / "data"
        with database("sqlite", data_dir) as env:
            service = Service(env, Path(tmp))
            try:
                service.start_api()
                service.start_workers(args.soak_workers)
                auth = service.key()
                assert service.api is not None

                def snapshot(label: str) -> None:
                    assert service.api is not None
                    workers = [rss_mb(w.pid) for w in service.workers]
                    snapshots.append((label, rss_mb(service.api.pid), workers))
                    print(
                        f"  {label}: api {snapshots[-1][1]:.0f} MB, workers {workers}",
                        file=sys.stderr,
                        flush=True,
                    )

                with httpx.Client(base_url=service.url, timeout=120) as client:
                    target = client.post("/courts", json={"name": "traffic"}, headers=auth)
                    traffic_court = target.json()["id"]
                    first = client.post(
                        f"/courts/{traffic_court}/calibrations",
                        files=as_files(uploads[0]),
                        headers=auth,
                    )
                    job_url = first.headers["location"]
                    while client.get(job_url, headers=auth).json()["status"] not in (
                        "succeeded",
                        "failed",
                    ):
                        time.sleep(0.5)
                    time.sleep(1.0)
                    snapshot("ready (one job done)")
                    traffic = threading.Thread(
                        target=_project_traffic,
                        args=(service.url, auth, traffic_court, counts),
                        daemon=True,
                    )
                    traffic.start()
                    started = time.monotonic()
                    end = started + 60 * args.soak_minutes
                    minute_snapshot = False
                    i = 0
                    outstanding: list[str] = []
                    while time.monotonic() < end:
                        outstanding = [
                            url
                            for url in outstanding
                            if client.get(url, headers=auth).json()["status"]
                            not in ("succeeded", "failed")
                        ]
                        if len(outstanding) < args.soak_workers + 2:
                            court = client.post("/courts", json={"name": f"s{i}"}, headers=auth)
                            response = client.post(
                                f"/courts/{court.json()['id']}/calibrations",
                                files=as_files(uploads[i % len(uploads)]),
                                headers=auth,
                            )
                            if response.status_code == 202:
                                counts.uploads += 1
                                outstanding.append(response.headers["location"])
                            else:
                                counts.upload_refused += 1
                                counts.refusals[_refusal_of(response)] += 1
                            i += 1
                        if not minute_snapshot and time.monotonic() - started > 60:
                            snapshot("after 1 minute")
                            minute_snapshot = True
                        time.sleep(2.0)
                    counts.stop.set()
                    traffic.join(60)
                    snapshot(f"after {args.soak_minutes} minutes")
                    api_peak = hwm_mb(service.api.pid)
                    worker_peaks = [hwm_mb(w.pid) for w in service.workers]
                    engine = sa.create_engine(f"sqlite:///{data_dir / 'squashcal.sqlite3'}")
                    with sa.orm.Session(engine) as session:
                        done = {
                            str(getattr(status, "value", status)): count
                            for status, count in session.execute(
                                sa.select(Job.status, sa.func.count()).group_by(Job.status)
                            ).all()
                        }
                    engine.dispose()
            finally:
                service.stop()
    print(command_line())
    print(
        f"{args.soak_minutes} min on SQLite: 1 API process, {args.soak_workers} workers; uploads "
        f"of {args.frames} PNG frames {args.size[0]}x{args.size[1]} keeping "
        f"{args.soak_workers + 2} jobs queued or running; "
        "/project of 1, 10, 100 or 1000 points back to back from one client"
    )
    print(
        f"jobs by status: {done}; uploads accepted {counts.uploads}, refused "
        f"{counts.upload_refused} {dict(counts.refusals)}; /project requests "
        f"{counts.project_requests}, "
        f"non-200 {counts.project_errors}"
    )
    n = args.soak_workers
    headers = ["when", "API RSS MB", *[f"worker {i + 1} RSS MB" for i in range(n)]]
    rows = [
        [label, f"{api:.0f}", *(f"{w:.0f}" for w in workers)] for label, api, workers in snapshots
    ]
    rows.append(["peak (VmHWM)", f"{api_peak:.0f}", *(f"{w:.0f}" for w in worker_peaks)])
    print(format_table(headers, rows))


def _size(text: str) -> tuple[int, int]:
    width, height = text.lower().split("x")
    return int(width), int(height)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--jobs", type=int, default=12, help="jobs per row")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument(
        "--db", nargs="+", default=["sqlite", "postgres"], choices=["sqlite", "postgres"]
    )
    parser.add_argument("--size", type=_size, default=(960, 540), help="frame size WxH")
    parser.add_argument("--frames", type=int, default=6, help="frames per upload")
    parser.add_argument("--soak-minutes", type=float, default=None, help="run the soak instead")
    parser.add_argument("--soak-workers", type=int, default=2)
    args = parser.parse_args()
    if args.soak_minutes:
        soak(args)
    else:
        throughput(args)


if __name__ == "__main__":
    main()
