"""Ctrl-C and SIGTERM stop a command within moments, whatever it is doing, and leave only complete files.

A Python signal handler runs only between bytecodes of the main thread, so a
job inside a long compiled kernel (numba, a solver) would not notice Ctrl-C
for seconds or minutes. :func:`run_watched` therefore runs the command in a
forked child and keeps the parent idle: on SIGINT or SIGTERM the parent kills
the child at once, removes every temporary file the child had registered
(:func:`porecad.io.atomic.set_journal` reports them through a pipe) and
every file of an output set that was cut short while being renamed into
place, and prints exactly what was written and what was not.
"""

from __future__ import annotations

import fcntl
import os
import select
import shutil
import signal
import sys
from pathlib import Path


class Journal:
    """What the child reported: temporary paths alive, outputs completed, an output set being committed."""

    def __init__(self):
        self.temps: dict[str, None] = {}   # insertion-ordered set
        self.written: list[str] = []
        self.committing: list[str] | None = None
        self._rest = b""

    def feed(self, data: bytes) -> None:
        lines = (self._rest + data).split(b"\n")
        self._rest = lines.pop()
        for line in lines:
            kind, _, raw = line.partition(b" ")
            path = os.fsdecode(raw)
            if kind == b"T":
                self.temps[path] = None
            elif kind == b"U":
                self.temps.pop(path, None)
            elif kind == b"C":
                self.temps = {k: None for k in self.temps if k != path}
                (self.committing if self.committing is not None else self.written).append(path)
            elif kind == b"S":
                self.committing = []
            elif kind == b"E":
                self.written += self.committing or []
                self.committing = None

    def clean(self) -> tuple[list[str], list[str]]:
        """Remove what an abort leaves: temporaries, and a half-committed set. Returns (written, removed)."""
        removed = []
        for path in reversed(list(self.temps)):
            p = Path(path)
            try:
                if p.is_dir() and not p.is_symlink():
                    if p.name.startswith("."):
                        shutil.rmtree(p)
                    else:
                        p.rmdir()  # a folder created for the outputs: only if nothing else is in it
                elif p.exists() or p.is_symlink():
                    p.unlink()
            except OSError:
                continue
            if not p.name.startswith("."):
                removed.append(path)
        for path in self.committing or []:  # a set cut short while being renamed: all or nothing
            try:
                os.unlink(path)
                removed.append(path)
            except OSError:
                pass
        return list(self.written), removed


def _end_with_parent() -> None:
    """Linux: SIGTERM this process when its parent dies (killed outright, nobody left to stop it)."""
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the child finishes on its own
        pass


def _read_all(fd: int, journal: Journal) -> None:
    while True:
        try:
            data = os.read(fd, 1 << 16)
        except BlockingIOError:
            return
        except OSError:
            return
        if not data:
            return
        journal.feed(data)


def run_watched(invoke) -> int:
    """Run ``invoke()`` (returns an exit code) in a forked child; stop it at once on SIGINT or SIGTERM."""
    from ..io.atomic import set_journal
    r, w = os.pipe()
    sys.stdout.flush()
    sys.stderr.flush()
    stop: list[int] = []
    # the parent's handlers are in place before the child exists: no moment when a signal finds neither ready
    handlers = {s: signal.signal(s, lambda signum, frame: stop.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    pid = os.fork()
    if pid == 0:  # the child: the command itself
        code = 1
        try:
            os.close(r)
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides; a terminal sends it to both
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            _end_with_parent()
            set_journal(w)
            code = invoke()
        finally:
            try:
                sys.stdout.flush()
                sys.stderr.flush()
            finally:
                os._exit(code if isinstance(code, int) else 1)
    os.close(w)
    fcntl.fcntl(r, fcntl.F_SETFL, fcntl.fcntl(r, fcntl.F_GETFL) | os.O_NONBLOCK)
    journal = Journal()
    try:
        status = None
        while status is None and not stop:
            try:
                select.select([r], [], [], 0.1)
            except InterruptedError:  # pragma: no cover - PEP 475 retries; kept for safety
                pass
            _read_all(r, journal)
            done, st = os.waitpid(pid, os.WNOHANG)
            if done:
                status = st
        if stop:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            _, status = os.waitpid(pid, 0)
        _read_all(r, journal)
    finally:
        os.close(r)
        for s, h in handlers.items():
            signal.signal(s, h)
    if stop:
        return _stopped(stop[0], journal)
    if os.WIFSIGNALED(status):
        written, removed = journal.clean()
        print(f"porecad: error: the job was killed by signal {os.WTERMSIG(status)} "
              f"(out of memory?); {_what(written, removed)}", file=sys.stderr)
        return 3
    return os.waitstatus_to_exitcode(status)


def _what(written, removed) -> str:
    text = "wrote " + ", ".join(written) if written else "nothing written"
    if removed:
        text += "; removed the unfinished " + ", ".join(removed)
    return text


def _stopped(signum: int, journal: Journal) -> int:
    written, removed = journal.clean()
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    print(f"porecad: {word}; {_what(written, removed)}", file=sys.stderr, flush=True)
    return 130 if signum == signal.SIGINT else 143
