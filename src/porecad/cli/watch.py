"""Ctrl-C and SIGTERM stop a command within moments, whatever it is doing, and leave only complete files.

A Python signal handler runs only between bytecodes of the main thread, so a
job inside a long compiled kernel (numba, a solver) would not notice Ctrl-C
for seconds or minutes. :func:`run_watched` therefore runs the command in a
forked child and keeps the parent idle: on SIGINT or SIGTERM the parent kills
the child at once, removes every temporary file the child had made
(:func:`porecad.io.atomic.set_journal` reports each, with its device and
inode, through a pipe: only that very file is removed, never another of the
same name), undoes an output set that was cut short while being renamed into
place (its new files go, the earlier ones come back), and prints exactly
what was written, removed and restored.
"""

from __future__ import annotations

import fcntl
import json
import os
import select
import signal
import sys
from pathlib import Path


class Journal:
    """What the child reported (:func:`porecad.io.atomic.set_journal`): one JSON record a line.

    Temporaries alive (each with the identity it was made with), outputs
    written, and the renames of an output set being committed. A name is a
    JSON string inside one record: whatever it holds, it cannot make a
    record of its own.
    """

    def __init__(self):
        self.temps: dict[str, dict] = {}   # path -> its record (insertion-ordered)
        self.written: dict[str, list] = {}  # output -> identity
        self.committing: dict[str, list] | None = None
        self._rest = b""

    def feed(self, data: bytes) -> None:
        lines = (self._rest + data).split(b"\n")
        self._rest = lines.pop()
        for line in lines:
            try:
                record = json.loads(line)
            except ValueError:  # not a record (a torn or foreign line): nothing to act on
                continue
            if isinstance(record, dict):
                self._apply(record)

    def _apply(self, record: dict) -> None:
        op, path = record.get("op"), record.get("path")
        if op in ("temp", "gone", "done") and not (isinstance(path, str) and os.path.isabs(path)):
            return
        if op == "temp":
            self.temps[path] = record
        elif op == "gone":
            self.temps.pop(path, None)
        elif op == "done":  # noted before the rename: its temporary stays listed (gone once renamed)
            (self.written if self.committing is None else self.committing)[path] = record.get("id")
        elif op == "begin":
            self.committing = {}
        elif op == "end":
            if record.get("ok"):
                self.written.update(self.committing or {})
            self.committing = None

    def clean(self) -> tuple[list[str], list[str], list[str]]:
        """Undo what an abort leaves; returns (written, removed, restored), each only what really is so.

        The temporaries go, each only while it still is the file or folder
        this run made; a set cut short while being renamed into place gets
        its earlier files back and loses its new ones.
        """
        from ..io.atomic import identity, remove_temp, restore_backup
        removed, restored = [], []
        open_set = self.committing is not None
        for path, record in list(self.temps.items()):
            target = record.get("of")
            if isinstance(target, str) and os.path.isabs(target) and record.get("id"):  # an earlier output kept aside
                del self.temps[path]
                if not open_set:
                    remove_temp(path, record["id"])
                elif restore_backup(path, record["id"], target, (self.committing or {}).get(target)):
                    restored.append(target)
        for target, ident in (self.committing or {}).items():
            if target not in restored and ident and remove_temp(target, ident):
                removed.append(target)
        for path, record in reversed(list(self.temps.items())):
            if remove_temp(path, record.get("id"), bool(record.get("tree"))) and not Path(path).name.startswith("."):
                removed.append(path)  # a folder made for the outputs
        written = [p for p, ident in self.written.items() if ident and identity(p) == tuple(ident)]
        return written, removed, restored


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
        if stop and status is None:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            _, status = os.waitpid(pid, 0)
        elif stop:  # the child had finished (and been reaped) when the signal came: its run stands as it ended
            stop.clear()
        _read_all(r, journal)
    finally:
        os.close(r)
        for s, h in handlers.items():
            signal.signal(s, h)
    if stop:
        return _stopped(stop[0], journal)
    if os.WIFSIGNALED(status):
        print(f"porecad: error: the job was killed by signal {os.WTERMSIG(status)} "
              f"(out of memory?); {_what(*journal.clean())}", file=sys.stderr)
        return 3
    return os.waitstatus_to_exitcode(status)


def _what(written, removed, restored) -> str:
    text = "wrote " + ", ".join(written) if written else "nothing written"
    if removed:
        text += "; removed the unfinished " + ", ".join(removed)
    if restored:
        text += "; restored the earlier " + ", ".join(restored)
    return text


def _stopped(signum: int, journal: Journal) -> int:
    what = _what(*journal.clean())
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    print(f"porecad: {word}; {what}", file=sys.stderr, flush=True)
    return 130 if signum == signal.SIGINT else 143
