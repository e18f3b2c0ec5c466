"""Peak resident memory of this process and its children, sampled on a thread."""

from __future__ import annotations

import threading


def tree_rss(proc) -> int:
    """Resident bytes of ``proc`` and all its descendants (0 for those that vanished)."""
    import psutil
    total = 0
    try:
        procs = [proc] + proc.children(recursive=True)
    except psutil.Error:
        return 0
    for p in procs:
        try:
            total += p.memory_info().rss
        except psutil.Error:
            pass
    return total


class PeakMemory:
    """Context manager: ``peak_bytes`` of the process tree while inside (polled every ``interval`` s).

    Local only: the workers of a remote cluster are not counted. Without
    psutil ``peak_bytes`` stays None.
    """

    def __init__(self, interval: float = 0.2):
        self.interval = interval
        self.peak_bytes = None
        self._stop = threading.Event()
        self._thread = None

    def _poll(self, proc):
        while True:
            self.peak_bytes = max(self.peak_bytes or 0, tree_rss(proc))
            if self._stop.wait(self.interval):
                break

    def __enter__(self):
        try:
            import psutil
        except ImportError:  # pragma: no cover - psutil is a dependency
            return self
        self._thread = threading.Thread(target=self._poll, args=(psutil.Process(),), daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
        return False
