"""/project latency through the real HTTP server (uvicorn subprocess, SQLite, one known camera).

    .venv/bin/python -m bench.service_load [--repeats 30]

Prints, per request size, the median and 95th percentile latency and the points per second.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from app.calib import camera, synthetic
from app.db import queue, repo
from app.db.migrate import upgrade_head
from app.db.models import Calibration, new_id
from app.db.session import make_engine, make_sessionmaker
from app.settings import Settings

SIZE = (1920, 1080)


def seed_database(settings: Settings, genome: np.ndarray) -> tuple[str, str]:
    """A tenant, a court and a calibration of `genome`; -> (api key, court id)."""
    engine = make_engine(settings)
    with make_sessionmaker(engine).begin() as session:
        key_row, key = repo.create_api_key(session, name="bench")
        court = repo.create_court(session, key_row.tenant_id, "bench", "wsf")
        tenant_id, court_id = key_row.tenant_id, court.id
        repo.new_job(
            session,
            job_id=new_id(),
            tenant_id=tenant_id,
            court_id=court_id,
            media_kind="images",
            media_files=[],
            params={},
            max_attempts=1,
        )
    job = queue.claim(engine, "bench", 60)
    assert job is not None
    calibration = Calibration(
        id=new_id(),
        tenant_id=tenant_id,
        court_id=court_id,
        job_id=job.id,
        spec="wsf",
        genome=[float(v) for v in genome],
        opencv=camera.to_opencv(genome, SIZE),
        fitness=0.0,
        quality={},
        result={},
        image_width=SIZE[0],
        image_height=SIZE[1],
    )
    queue.finish_success(engine, job, "bench", calibration, {})
    engine.dispose()
    return key, court_id


def free_port() -> int:
    """A loopback port free right now (for a server started next)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_ready(url: str, timeout_s: float) -> None:
    """Until GET {url}/readyz answers 200 (the server started, migrated, its kernels loaded)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/readyz", timeout=5).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.05)
    raise TimeoutError(f"{url} not ready after {timeout_s} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    genome = synthetic.typical_target_camera(SIZE)
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(data_dir=Path(tmp))
        upgrade_head(settings)
        key, court_id = seed_database(settings, genome)
        port = free_port()
        env = {**os.environ, "SQUASHCAL_DATA_DIR": tmp}
        server = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            url = f"http://127.0.0.1:{port}"
            wait_ready(url, 120)
            rng = np.random.default_rng(0)
            headers = {"Authorization": f"Bearer {key}"}
            print(f"{'points':>8} {'median ms':>10} {'p95 ms':>8} {'points/s':>12}")
            with httpx.Client(base_url=url, headers=headers, timeout=60) as client:
                for n in (1, 100, 10_000, 100_000):
                    pixels = rng.uniform([0, 0], SIZE, (n, 2)).round(2).tolist()
                    body = {"court_id": court_id, "pixels": pixels}
                    client.post("/project", json=body).raise_for_status()  # warm the cache
                    times = []
                    for _ in range(args.repeats if n < 100_000 else max(3, args.repeats // 5)):
                        t0 = time.perf_counter()
                        client.post("/project", json=body).raise_for_status()
                        times.append(time.perf_counter() - t0)
                    ms = 1000 * np.array(times)
                    median = float(np.median(ms))
                    print(
                        f"{n:>8} {median:>10.2f} {float(np.percentile(ms, 95)):>8.2f} "
                        f"{n / (median / 1000):>12.0f}"
                    )
        finally:
            server.terminate()
            server.wait(30)
    print(f"camera {SIZE[0]}x{SIZE[1]}, one uvicorn process, SQLite, warm caches")


if __name__ == "__main__":
    main()
