"""/project under load: a real uvicorn on loopback driven by `wrk`, beside a bare endpoint.

    .venv/bin/python -m bench.project_wrk [--duration 10] [--connections 8] [--threads 2]
        [--api-workers 1 2]

`squashcal serve --workers N` (N API processes on one port, SO_REUSEPORT) serves the service's
app plus `GET /bench/bare` (an `async def` that returns a constant JSON body: what the server,
FastAPI's routing and the loopback cost alone). For each N in `--api-workers`, in the same run,
`wrk --latency` drives, one after the other: the bare endpoint, `POST /project` with 1 point and
with 1000 points per request (random pixels of a 1920x1080 camera seeded in SQLite, the kernels
warmed up before /readyz says ready). Prints requests per second (and as a share of the bare
endpoint's at the same N) and wrk's latency percentiles. Needs `wrk` (Debian package wrk).

Issue 8's targets at 8 connections: 1 point >= 60% of the bare rate and p99 <= 10 ms; 1000 points
p99 <= 25 ms. wrk and the server share the machine's cores.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
from fastapi import FastAPI
from fastapi.responses import Response

from app.calib import synthetic
from app.db.migrate import upgrade_head
from app.main import create_app
from app.settings import Settings
from bench.common import command_line, format_table
from bench.service_load import SIZE, free_port, seed_database, wait_ready

BARE_PATH = "/bench/bare"
BARE_BODY = b'{"status":"ok"}'


def bench_app() -> FastAPI:
    """The service's app (settings from the environment, kernels warmed up) plus the bare
    endpoint; `uvicorn --factory bench.project_wrk:bench_app`."""
    app = create_app(warm_up=True)

    async def bare() -> Response:
        return Response(BARE_BODY, media_type="application/json")

    app.add_api_route(BARE_PATH, bare, methods=["GET"], include_in_schema=False)
    return app


@dataclass
class WrkResult:
    requests_per_s: float
    latency_ms: dict[str, float]  # "50%", "75%", "90%", "99%"
    errors: int  # non-2xx answers and socket errors


_UNIT_MS = {"us": 1e-3, "ms": 1.0, "s": 1000.0}


def parse_wrk(output: str) -> WrkResult:
    """Requests/sec, the --latency distribution and the error counts of wrk's report."""
    rate = float(re.search(r"Requests/sec:\s+([\d.]+)", output).group(1))  # type: ignore[union-attr]
    latency = {
        pct: float(value) * _UNIT_MS[unit]
        for pct, value, unit in re.findall(r"^\s+(\d+%)\s+([\d.]+)(us|ms|s)\s*$", output, re.M)
    }
    errors = sum(int(n) for n in re.findall(r"Non-2xx or 3xx responses:\s+(\d+)", output))
    socket = re.search(
        r"Socket errors: connect (\d+), read (\d+), write (\d+), timeout (\d+)", output
    )
    if socket:
        errors += sum(int(n) for n in socket.groups())
    return WrkResult(rate, latency, errors)


def lua_post(path: Path, body: dict[str, object], key: str) -> Path:
    """A wrk script that sends `body` as JSON with the API key on every request."""
    path.write_text(
        'wrk.method = "POST"\n'
        f"wrk.body = {json.dumps(json.dumps(body))}\n"
        'wrk.headers["Content-Type"] = "application/json"\n'
        f'wrk.headers["Authorization"] = "Bearer {key}"\n'
    )
    return path


def run_wrk(
    url: str, args: argparse.Namespace, script: Path | None = None, duration_s: int | None = None
) -> WrkResult:
    command = ["wrk", "--latency", f"-t{args.threads}", f"-c{args.connections}"]
    command += [f"-d{duration_s or args.duration}s"]
    if script is not None:
        command += ["-s", str(script)]
    done = subprocess.run([*command, url], check=True, capture_output=True, text=True)
    return parse_wrk(done.stdout)


def _parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=int, default=10, help="seconds per row")
    parser.add_argument("--connections", type=int, default=8)
    parser.add_argument("--threads", type=int, default=2, help="wrk threads")
    parser.add_argument(
        "--api-workers",
        type=int,
        nargs="+",
        default=[1],
        help="API process counts to measure, one server each (e.g. 1 2)",
    )
    return parser.parse_args()


def wait_all_ready(url: str, timeout_s: float, in_a_row: int = 30) -> None:
    """Until /readyz answers 200 on `in_a_row` fresh connections in a row: with several API
    processes each connection lands on one of them, so this waits for all (very likely)."""
    wait_ready(url, timeout_s)
    deadline = time.monotonic() + timeout_s
    streak = 0
    while streak < in_a_row:
        if time.monotonic() > deadline:
            raise TimeoutError(f"{url}: not every API process ready after {timeout_s} s")
        try:
            ok = httpx.get(f"{url}/readyz", timeout=5).status_code == 200
        except httpx.TransportError:
            ok = False
        streak = streak + 1 if ok else 0
        if not ok:
            time.sleep(0.05)


def measure(
    n_api: int, args: argparse.Namespace, work: Path, scripts: dict[int, Path]
) -> list[tuple[str, WrkResult]]:
    """Start `serve --workers n_api`, drive it with wrk, stop it."""
    port = free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--workers", str(n_api), "--port", str(port)]
        + ["--app-factory", "bench.project_wrk:bench_app"]
        + ["--log-level", "warning", "--no-access-log"],
        env={**os.environ, "SQUASHCAL_DATA_DIR": str(work)},
        stdout=subprocess.DEVNULL,
    )
    rows: list[tuple[str, WrkResult]] = []
    try:
        url = f"http://127.0.0.1:{port}"
        wait_all_ready(url, 600)
        run_wrk(url + BARE_PATH, args, duration_s=2)  # warm the connections and caches
        run_wrk(url + "/project", args, scripts[1], duration_s=2)
        rows.append((f"GET {BARE_PATH} (bare)", run_wrk(url + BARE_PATH, args)))
        for n in (1, 1000):
            label = f"POST /project, {n} point{'s' if n > 1 else ''}"
            rows.append((label, run_wrk(url + "/project", args, scripts[n])))
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(60)
    return rows


def main() -> None:
    args = _parse_args()
    if shutil.which("wrk") is None:
        raise SystemExit("wrk is missing: apt-get install -y wrk")
    rng = np.random.default_rng(0)
    results: dict[int, list[tuple[str, WrkResult]]] = {}
    with tempfile.TemporaryDirectory(prefix="squashcal-wrk-") as tmp:
        work = Path(tmp)
        settings = Settings(data_dir=work)
        upgrade_head(settings)
        key, court_id = seed_database(settings, synthetic.typical_target_camera(SIZE))
        scripts = {}
        for n in (1, 1000):
            pixels = rng.uniform([0, 0], SIZE, (n, 2)).round(2).tolist()
            body = {"court_id": court_id, "pixels": pixels}
            scripts[n] = lua_post(work / f"project-{n}.lua", body, key)
        for n_api in args.api_workers:
            results[n_api] = measure(n_api, args, work, scripts)
    print(command_line())
    print(
        f"`squashcal serve --workers N`, wrk -t{args.threads} -c{args.connections} "
        f"-d{args.duration}s each; {os.cpu_count()} CPUs shared by wrk and the server"
    )
    table = []
    for n_api, rows in results.items():
        bare_rate = rows[0][1].requests_per_s
        table += [
            [
                n_api,
                name,
                f"{r.requests_per_s:.0f}",
                f"{100 * r.requests_per_s / bare_rate:.0f}%",
                *(f"{r.latency_ms.get(p, float('nan')):.2f}" for p in ("50%", "90%", "99%")),
                r.errors,
            ]
            for name, r in rows
        ]
    headers = ["API procs", "endpoint", "req/s", "of bare", "p50 ms", "p90 ms", "p99 ms", "errors"]
    print(format_table(headers, table))


if __name__ == "__main__":
    main()
