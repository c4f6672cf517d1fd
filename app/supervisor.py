"""Keeps `squashcal run`'s child processes (the API and the workers) running.

A child that exits is started again after a backoff that doubles with each quick exit in a row
(a child that crashes at start must not spin), and resets once the child has stayed up for
`stable_after_s`. Only `stop()` (SIGTERM/SIGINT in `squashcal run`) ends the children: SIGTERM
first, so workers finish or give back their jobs, SIGKILL for those still there at the deadline.
"""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field


@dataclass
class Child:
    name: str
    argv: Sequence[str]
    process: subprocess.Popen[bytes] | None = None
    started_at: float = 0.0
    quick_exits: int = 0  # exits in a row, each before the child had been up stable_after_s
    restart_at: float | None = None
    pids: list[int] = field(default_factory=list)  # every process it has been, oldest first


class Supervisor:
    def __init__(
        self,
        children: Mapping[str, Sequence[str]],
        env: Mapping[str, str] | None = None,
        backoff_first_s: float = 1.0,
        backoff_max_s: float = 60.0,
        stable_after_s: float = 30.0,
        say: Callable[[str], None] = print,
    ) -> None:
        self.children = [Child(name, list(argv)) for name, argv in children.items()]
        self.env = dict(env) if env is not None else None
        self.backoff_first_s = backoff_first_s
        self.backoff_max_s = backoff_max_s
        self.stable_after_s = stable_after_s
        self.say = say
        self.stopping = threading.Event()

    def start(self) -> None:
        for child in self.children:
            self._spawn(child)

    def run(self, poll_s: float = 0.2) -> None:
        """Restart exited children until `stop()` is called (from a signal handler or thread)."""
        while not self.stopping.wait(poll_s):
            self.check(time.monotonic())

    def check(self, now: float) -> None:
        """One round: notice exited children, start those whose backoff is over."""
        for child in self.children:
            if self.stopping.is_set():
                return
            if child.restart_at is None:
                code = child.process.poll() if child.process is not None else None
                if code is not None:
                    self._schedule_restart(child, code, now)
            if child.restart_at is not None and now >= child.restart_at:
                self._spawn(child)

    def stop(self) -> None:
        self.stopping.set()

    def terminate_all(self, timeout_s: float) -> None:
        """SIGTERM every running child, wait up to `timeout_s` in all, then SIGKILL the rest."""
        self.stopping.set()
        running = [c.process for c in self.children if c.process and c.process.poll() is None]
        for process in running:
            process.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout_s
        for process in running:
            try:
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()

    def _schedule_restart(self, child: Child, code: int, now: float) -> None:
        if now - child.started_at >= self.stable_after_s:
            child.quick_exits = 0
        delay = min(self.backoff_max_s, self.backoff_first_s * 2.0**child.quick_exits)
        child.quick_exits += 1
        child.restart_at = now + delay
        pid = child.process.pid if child.process else None
        self.say(f"{child.name} (pid {pid}) exited with {code}; restarting in {delay:.1f} s")

    def _spawn(self, child: Child) -> None:
        child.process = subprocess.Popen(list(child.argv), env=self.env)
        child.started_at = time.monotonic()
        child.restart_at = None
        child.pids.append(child.process.pid)
        self.say(f"started {child.name} (pid {child.process.pid})")
