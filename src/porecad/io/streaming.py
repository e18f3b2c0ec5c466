"""Streamed writing of large files: keep the page cache bounded.

Writing a gigabyte-sized STL through the page cache first fills a gigabyte of
cache with dirty pages, which costs memory that other work could use (and, on
virtual machines that back guest memory lazily, seconds of first-touch
faults). :class:`StreamedWriter` follows the pattern the Linux kernel
developers recommend for streaming writes: after each block it starts the
writeback of that block (``sync_file_range(SYNC_FILE_RANGE_WRITE)``), waits
for the block before it to reach the disk and drops it from the cache
(``posix_fadvise(POSIX_FADV_DONTNEED)``). At most two blocks of the file are
cached at a time. Elsewhere (no ``sync_file_range``) it is a plain write.

Durability is not promised (that is ``atomic_write(durable=True)``); the hints
only bound the cache.
"""

from __future__ import annotations

import ctypes
import os

_WAIT_BEFORE, _WRITE, _WAIT_AFTER = 1, 2, 4
#: files smaller than this are written plainly
STREAM_MIN_BYTES = 64 << 20


def _load_sync_file_range():
    if not hasattr(os, "posix_fadvise"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).sync_file_range
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_longlong, ctypes.c_longlong, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_sync_file_range = _load_sync_file_range()


class StreamedWriter:
    """Write blocks to an open binary file, keeping at most two of them cached.

    Parameters
    ----------
    fh : binary file object
        An open, unbuffered-or-flushed file (as from ``atomic_write``).
    total_bytes : int
        Expected size of what will be written; small files are written plainly.
    """

    def __init__(self, fh, total_bytes: int):
        self.fh = fh
        self.enabled = _sync_file_range is not None and total_bytes >= STREAM_MIN_BYTES
        self._prev = None
        self._offset = None

    def write(self, data) -> None:
        if not self.enabled:
            self.fh.write(data)
            return
        if self._offset is None:
            self.fh.flush()
            self._offset = self.fh.tell()
        n = len(memoryview(data).cast("B"))
        self.fh.write(data)
        self.fh.flush()
        fd = self.fh.fileno()
        start = self._offset
        self._offset += n
        try:
            _sync_file_range(fd, start, n, _WRITE)
            if self._prev is not None:
                p_start, p_len = self._prev
                _sync_file_range(fd, p_start, p_len, _WAIT_BEFORE | _WRITE | _WAIT_AFTER)
                os.posix_fadvise(fd, p_start, p_len, os.POSIX_FADV_DONTNEED)
        except OSError:
            self.enabled = False  # hints are optional; the data is written
        self._prev = (start, n)
