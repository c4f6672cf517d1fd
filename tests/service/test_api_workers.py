"""`squashcal serve --workers N`: N API processes share one port (SO_REUSEPORT), each answers."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.db.migrate import upgrade_head
from tests.service.conftest import make_settings
from tests.service.test_e2e import REPO_ROOT, free_port
from tests.service.test_supervisor import OutputLines, alive, wait_until


def _server_side_inode(server_port: int, client_port: int) -> str | None:
    """The socket inode of the server's end of a loopback connection, from /proc/net/tcp."""
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not os.path.exists(table):
            continue
        with open(table) as f:
            for line in f.readlines()[1:]:
                fields = line.split()
                local_port = int(fields[1].rsplit(":", 1)[1], 16)
                remote_port = int(fields[2].rsplit(":", 1)[1], 16)
                if local_port == server_port and remote_port == client_port:
                    return fields[9]
    return None


def _owner(inode: str, pids: list[int]) -> int | None:
    target = f"socket:[{inode}]"
    for pid in pids:
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                try:
                    if os.readlink(f"/proc/{pid}/fd/{fd}") == target:
                        return pid
                except OSError:
                    continue
        except OSError:
            continue
    return None


def answering_process(port: int, pids: list[int]) -> int | None:
    """Ask GET /healthz on a fresh connection; the pid (among `pids`) that holds the server's
    end of it once the answer has come back, or None if no answer."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: test\r\n\r\n")
        try:
            answer = sock.recv(4096)
        except OSError:
            return None
        if not answer.startswith(b"HTTP/1.1 200"):
            return None
        inode = _server_side_inode(port, sock.getsockname()[1])
        return _owner(inode, pids) if inode else None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_two_api_processes_share_the_port_and_both_answer(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "data")
    upgrade_head(settings)
    port = free_port()
    env = {**os.environ, "SQUASHCAL_DATA_DIR": str(settings.data_dir), "SQUASHCAL_WARM_UP": "0"}
    argv = [sys.executable, "-m", "app.cli", "serve", "--workers", "2", "--port", str(port)]
    process = subprocess.Popen(
        argv + ["--log-level", "warning"],
        cwd=REPO_ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    output = OutputLines(process)
    pids: list[int] = []
    try:
        pids.append(int(output.wait_for(r"started api-1 \(pid (\d+)\)", 60)[1]))
        pids.append(int(output.wait_for(r"started api-2 \(pid (\d+)\)", 10)[1]))
        seen: set[int] = set()
        deadline = time.monotonic() + 90
        # each new connection goes to one of the processes by a hash of the client's port:
        # keep connecting until both have answered (they start at their own pace)
        while seen != set(pids):
            assert time.monotonic() < deadline, f"only {seen} of {pids} answered"
            try:
                pid = answering_process(port, pids)
            except OSError:
                pid = None
                time.sleep(0.1)
            if pid is not None:
                seen.add(pid)
        assert process.poll() is None
    finally:
        process.send_signal(signal.SIGTERM)
        code = process.wait(60)
        output.close()
    assert code == 0
    wait_until(lambda: not any(alive(pid) for pid in pids), 10, "both API processes to exit")
