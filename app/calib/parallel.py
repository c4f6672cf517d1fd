"""Row-parallel calls of the compiled kernels that score many cameras.

The search scores hundreds of thousands of cameras, one row each, with kernels that release the
GIL (`nogil=True`). Splitting the rows over a few threads gives a single calibration the machine's
cores without numba's parallel backend (whose default threading layer must not be entered from
two threads at once, as the API's threads could). Each row is computed by the same serial code
as before, so the results are identical whatever the number of threads.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

# at most this many threads per process (a worker per core on a big machine keeps its share)
MAX_THREADS = 4
# below this many rows per thread, handing work to a thread costs more than it saves
MIN_ROWS_PER_THREAD = 64

_T = TypeVar("_T")
_R = TypeVar("_R")

_pool: ThreadPoolExecutor | None = None
_pool_key = (0, 0)  # (process id, threads) the pool was made for


def thread_count() -> int:
    """Threads per call: the CPUs this process may use, at most MAX_THREADS; the environment
    variable SQUASHCAL_KERNEL_THREADS sets it (1: no threads, e.g. one worker process per core)."""
    configured = os.environ.get("SQUASHCAL_KERNEL_THREADS", "").strip()
    if configured.isdigit() and int(configured) >= 1:
        return int(configured)
    return max(1, min(MAX_THREADS, len(os.sched_getaffinity(0))))


def _executor() -> ThreadPoolExecutor:
    """The process's pool, as many threads as `thread_count` says now (a forked child inherits
    the parent's pool object but none of its threads; a changed setting gets a new pool)."""
    global _pool, _pool_key
    key = (os.getpid(), thread_count())
    if _pool is None or _pool_key != key:
        if _pool is not None and _pool_key[0] == key[0]:
            _pool.shutdown(wait=False)
        _pool = ThreadPoolExecutor(max_workers=key[1], thread_name_prefix="kernel")
        _pool_key = key
    return _pool


def row_chunks(n_rows: int, n_chunks: int) -> list[tuple[int, int]]:
    """[start, stop) ranges covering n_rows in up to n_chunks nearly equal, non-empty parts."""
    n_chunks = max(1, min(n_chunks, n_rows))
    bounds = [n_rows * k // n_chunks for k in range(n_chunks + 1)]
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


def over_rows(n_rows: int, run: Callable[[int, int], None]) -> None:
    """Call run(start, stop) over [0, n_rows), split across threads when there is enough work;
    `run` must write only its own rows."""
    n_chunks = min(thread_count(), n_rows // MIN_ROWS_PER_THREAD)
    if n_chunks <= 1:
        if n_rows:
            run(0, n_rows)
        return
    futures = [_executor().submit(run, a, b) for a, b in row_chunks(n_rows, n_chunks)]
    for future in futures:
        future.result()


def ordered_map(run: Callable[[_T], _R], items: Iterable[_T]) -> list[_R]:
    """[run(item) for item in items], the calls spread over threads, the results in order."""
    work = list(items)
    if thread_count() == 1 or len(work) <= 1:
        return [run(item) for item in work]
    return list(_executor().map(run, work))
