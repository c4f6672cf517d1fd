"""`squashcal run` supervises its children: a dead one comes back (with backoff), only a signal
stops them all."""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest

from app.supervisor import Supervisor
from tests.service.test_e2e import REPO_ROOT, free_port

SLEEPER = [sys.executable, "-c", "import time; time.sleep(120)"]
CRASHER = [sys.executable, "-c", "raise SystemExit(3)"]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def wait_until(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def test_a_killed_child_is_restarted_and_stop_ends_all() -> None:
    said: list[str] = []
    supervisor = Supervisor({"a": SLEEPER, "b": SLEEPER}, backoff_first_s=0.1, say=said.append)
    supervisor.start()
    runner = threading.Thread(target=supervisor.run, kwargs={"poll_s": 0.05})
    runner.start()
    try:
        a, b = supervisor.children
        first_pid = a.pids[0]
        os.kill(first_pid, signal.SIGKILL)
        wait_until(lambda: len(a.pids) == 2, 10, "the killed child to come back")
        assert alive(a.pids[1]) and a.pids[1] != first_pid
        assert b.pids == [b.pids[0]] and alive(b.pids[0])  # the others are left alone
        assert any(f"a (pid {first_pid}) exited with -9" in line for line in said)
    finally:
        supervisor.stop()
        runner.join(10)
        supervisor.terminate_all(timeout_s=10)
    assert not any(alive(pid) for child in supervisor.children for pid in child.pids)


def test_a_child_that_keeps_crashing_is_restarted_with_growing_waits() -> None:
    said: list[str] = []
    supervisor = Supervisor(
        {"crasher": CRASHER}, backoff_first_s=0.1, backoff_max_s=0.4, say=said.append
    )
    supervisor.start()
    runner = threading.Thread(target=supervisor.run, kwargs={"poll_s": 0.02})
    runner.start()
    try:
        wait_until(lambda: len(supervisor.children[0].pids) >= 5, 20, "five starts")
    finally:
        supervisor.stop()
        runner.join(10)
        supervisor.terminate_all(timeout_s=5)
    waits = [float(m) for m in re.findall(r"restarting in ([0-9.]+) s", "\n".join(said))]
    assert waits[:5] == [0.1, 0.2, 0.4, 0.4, 0.4][: len(waits[:5])] and len(waits) >= 4
    assert all("exited with 3" in line for line in said if "exited" in line)


class OutputLines:
    """The lines a process prints, read in a thread (so waiting for one never blocks)."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        assert process.stdout is not None
        self.stdout = process.stdout
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        for line in self.stdout:
            self.lines.put(line)

    def close(self) -> None:
        """After the process has exited: the reader has seen the end; close the pipe."""
        self.reader.join(10)
        self.stdout.close()

    def wait_for(self, pattern: str, timeout_s: float) -> re.Match[str]:
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            assert remaining > 0, f"no line matching {pattern!r}"
            try:
                line = self.lines.get(timeout=remaining)
            except queue.Empty:
                continue
            match = re.search(pattern, line)
            if match:
                return match


def ready(port: int) -> bool:
    try:
        return httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2).status_code == 200
    except httpx.TransportError:
        return False


@pytest.mark.slow
@pytest.mark.e2e
def test_squashcal_run_restarts_a_killed_worker_and_api(tmp_path: Path) -> None:
    port = free_port()
    env = {**os.environ, "SQUASHCAL_DATA_DIR": str(tmp_path / "data")}
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "run", "--port", str(port), "--workers", "2"],
        cwd=REPO_ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    output = OutputLines(process)
    pids: list[int] = []
    try:
        api_pid = int(output.wait_for(r"started api \(pid (\d+)\)", 60)[1])
        worker_pid = int(output.wait_for(r"started worker-1 \(pid (\d+)\)", 10)[1])
        pids += [api_pid, worker_pid]
        wait_until(lambda: ready(port), 60, "the API")

        os.kill(worker_pid, signal.SIGKILL)
        output.wait_for(rf"worker-1 \(pid {worker_pid}\) exited with -9; restarting", 10)
        pids.append(int(output.wait_for(r"started worker-1 \(pid (\d+)\)", 10)[1]))
        assert alive(pids[-1]) and process.poll() is None

        os.kill(api_pid, signal.SIGKILL)
        pids.append(int(output.wait_for(r"started api \(pid (\d+)\)", 10)[1]))
        wait_until(lambda: ready(port), 60, "the restarted API")
    finally:
        process.send_signal(signal.SIGTERM)
        code = process.wait(60)
        output.close()
    assert code == 0
    wait_until(lambda: not any(alive(pid) for pid in pids), 10, "every child to be gone")
