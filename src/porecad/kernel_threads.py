"""Run a serial, GIL-free numba kernel on several threads.

A numba kernel compiled with ``parallel=True`` costs one to two seconds more
to compile than the same loop compiled serially, and that compile is paid on
the first run after an install (issue 22). The kernels used by every build and
report are therefore serial and ``nogil=True``, take ``(first, step)`` as their
last two arguments and handle items ``first, first + step, ...``;
:func:`run_interleaved` calls them once per thread. Each item is written by
exactly one run, so the result does not depend on the number of threads.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor


def thread_count() -> int:
    """Threads to use: numba's setting (``NUMBA_NUM_THREADS``), at most the cores and at most 8."""
    try:
        from numba import get_num_threads
        n = int(get_num_threads())
    except Exception:   # pragma: no cover - numba is a base dependency
        n = os.cpu_count() or 1
    return max(1, min(n, os.cpu_count() or 1, 8))


def run_interleaved(kernel, n_items: int, *args, threads: int | None = None, min_per_thread: int = 64) -> None:
    """``kernel(*args, first, step)`` on ``step`` threads (one run per thread, interleaved items).

    Small jobs (fewer than ``min_per_thread`` items a thread) run on the calling thread.
    """
    t = thread_count() if threads is None else max(1, int(threads))
    t = max(1, min(t, int(n_items) // max(1, int(min_per_thread))))
    if t == 1:
        kernel(*args, 0, 1)
        return
    with ThreadPoolExecutor(max_workers=t) as pool:
        futures = [pool.submit(kernel, *args, i, t) for i in range(t)]
        for fu in futures:
            fu.result()
