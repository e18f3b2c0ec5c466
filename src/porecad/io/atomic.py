"""Safe output files: refuse clobbering, write atomically.

Every file porecad writes goes through :func:`atomic_write`: the data lands in
a hidden temporary file next to the target, is flushed to disk, and only then
renamed over the target with :func:`os.replace`. A crash or exception part
way through therefore never leaves a truncated output behind, and an existing
file is either fully replaced or left untouched.

Two more guarantees hold for a run's outputs:

- **All or nothing.** Inside :func:`output_set` the renames are deferred
  until the block ends, so the files of one run (mesh, recipe, report) appear
  together, or none does when the block raises.
- **Nothing left behind on a signal.** Every temporary file is registered
  before it is created; :func:`set_journal` sends each registration and each
  completed rename to a pipe, so that a watching parent process (the command
  line's, :mod:`porecad.cli.watch`) that kills a run can remove its
  temporary files and say exactly which outputs were written.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import secrets
import shutil
import stat
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from porecad.errors import InputError, OutputError, one_line

__all__ = ["check_output_path", "check_output_dir", "atomic_write", "atomic_path", "output_set", "make_dirs",
           "register_temp", "forget_temp", "set_journal"]


def _describe_oserror(exc: OSError) -> str:
    return one_line(exc.strerror or exc) or type(exc).__name__


def check_output_path(path: str | os.PathLike, force: bool = False) -> Path:
    """Check that `path` can be written as an output file.

    Parameters
    ----------
    path : str or os.PathLike
        The file to be written.
    force : bool, optional
        Allow replacing an existing file.

    Returns
    -------
    pathlib.Path
        The path, as given (not resolved).

    Raises
    ------
    OutputError
        If `path` is a directory, exists and `force` is false, or its parent
        directory does not exist or is not writable. The message is one line.
    """
    from .confine import check_name
    try:
        check_name(path, "output")
    except InputError as exc:
        raise OutputError(str(exc)) from None
    p = Path(os.fspath(path))
    if not p.name or p.is_dir():
        raise OutputError(f"{p}: is a directory, not a file")
    if (p.exists() or p.is_symlink()) and not force:
        raise OutputError(f"{p}: already exists (`force` overwrites it)")
    if p.exists() and not stat.S_ISREG(p.stat().st_mode):
        raise OutputError(f"{p}: exists and is not a regular file; refusing to replace it")
    parent = p.parent
    if not parent.exists():
        raise OutputError(f"{p}: directory {parent} does not exist")
    if not parent.is_dir():
        raise OutputError(f"{p}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK) or _marked_read_only(parent):
        raise OutputError(f"{p}: directory {parent} is not writable")
    return p


def check_output_dir(path: str | os.PathLike) -> Path:
    """Check that output directory `path` exists or can be created (its nearest existing ancestor writable).

    Raises :class:`OutputError` (one line) for a file in the way or a
    read-only or unwritable ancestor; creates nothing.
    """
    p = Path(os.fspath(path))
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: is a file, not a directory")
    base = p if p.exists() else next((a for a in p.absolute().parents if a.exists()), None)
    if base is None or not base.is_dir():
        raise OutputError(f"{p}: no existing directory to create it in")
    if not os.access(base, os.W_OK | os.X_OK) or _marked_read_only(base):
        raise OutputError(f"{p}: directory {base} is not writable")
    return p


def _marked_read_only(directory: Path) -> bool:
    """A directory nobody may write to by its mode bits (``chmod a-w``), refused even for root.

    ``os.access`` says yes to the superuser whatever the mode; a directory
    its owner marked read-only is still not a place to put outputs.
    """
    try:
        return (directory.stat().st_mode & 0o222) == 0
    except OSError:
        return False


def _create_temp(p: Path, suffix: str = "") -> tuple[int, Path]:
    # O_EXCL with a random suffix; mode 0o666 so the process umask applies and
    # the final file gets ordinary permissions (mkstemp would give 0o600).
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = p.parent / f".{p.name}.tmp-{secrets.token_hex(4)}{suffix}"
        with _LOCK:  # registered before it exists, so that an abort never misses it
            register_temp(tmp)
            try:
                return os.open(tmp, flags, 0o666), tmp
            except FileExistsError:
                _TEMPS.discard(tmp)
                continue
            except BaseException:
                _TEMPS.discard(tmp)
                raise
    raise FileExistsError(f"could not create a temporary file next to {p}")


# ---------------------------------------------------------------------------- registry and output sets
_LOCK = threading.RLock()
#: temporary files and folders of this process now on disk
_TEMPS: set[Path] = set()
#: the pipe (a file descriptor) each registration and completed rename is reported to, or None
_JOURNAL: list = [None]
_SET: contextvars.ContextVar = contextvars.ContextVar("porecad_output_set", default=None)


def set_journal(fd: int | None) -> None:
    """Report temporary files (``T path``, ``U path``) and completed outputs (``C path``) to pipe ``fd``.

    An output set's renames are bracketed by ``S`` and ``E`` lines: a reader
    that sees ``S`` without ``E`` knows the set was cut short.
    """
    _JOURNAL[0] = fd


def _forget_journal_in_child() -> None:  # a forked helper process writes no outputs
    _JOURNAL[0] = None


os.register_at_fork(after_in_child=_forget_journal_in_child)


def _note(kind: str, path=None) -> None:
    fd = _JOURNAL[0]
    if fd is None:
        return
    line = kind.encode() + (b" " + os.fsencode(os.path.abspath(path)) if path is not None else b"") + b"\n"
    try:
        os.write(fd, line)
    except OSError:
        _JOURNAL[0] = None


def register_temp(path) -> None:
    """Note a temporary file or folder about to be created (removed by an abort if it is still there)."""
    with _LOCK:
        _TEMPS.add(Path(path))
        _note("T", path)


def forget_temp(path, remove: bool = False) -> None:
    """The temporary ``path`` is gone or renamed (``remove``: delete it first, file or folder)."""
    p = Path(path)
    if remove:
        with contextlib.suppress(OSError):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                os.unlink(p)
    with _LOCK:
        _TEMPS.discard(p)
        _note("U", p)


def _publish(tmp: Path, target: Path) -> None:
    """Rename a finished temporary file onto its target now, or when the open output set commits."""
    pending = _SET.get()
    if pending is not None:
        pending.append((tmp, target))
        return
    with _LOCK:
        os.replace(tmp, target)
        _TEMPS.discard(tmp)
        _note("C", target)


def make_dirs(path) -> Path:
    """Create folder ``path`` (and parents); inside an output set, ones it created go if the set fails."""
    p = Path(os.fspath(path))
    missing = [a for a in (p, *p.parents) if not a.exists()]
    p.mkdir(parents=True, exist_ok=True)
    for a in reversed(missing):
        register_temp(a)  # an abort before the set commits removes it (only if still empty, see _remove)
    created = _SET.get()
    if created is not None:
        created.dirs.extend(missing)
    else:
        for a in missing:
            forget_temp(a)
    return p


class _Pending(list):
    """``(temporary, target)`` renames of an open output set, and the folders it created."""

    def __init__(self):
        super().__init__()
        self.dirs: list[Path] = []


@contextlib.contextmanager
def output_set() -> Iterator[list]:
    """Write several files as one: every :func:`atomic_write` in the block is renamed into place at its end.

    When the block raises (an error, Ctrl-C), every temporary file is
    removed and every folder the block created is removed if empty: no
    output of the set appears. Yields the list of targets once committed.
    """
    pending = _Pending()
    token = _SET.set(pending)
    done: list[Path] = []
    try:
        yield done
    except BaseException:
        _SET.reset(token)
        for tmp, _ in pending:
            forget_temp(tmp, remove=True)
        for d in reversed(pending.dirs):
            with contextlib.suppress(OSError):
                d.rmdir()
            forget_temp(d)
        raise
    _SET.reset(token)
    with _LOCK:
        _note("S")
        try:
            for tmp, target in pending:
                os.replace(tmp, target)
                _TEMPS.discard(tmp)
                _note("C", target)
                done.append(target)
        except OSError as exc:
            for target in done:
                with contextlib.suppress(OSError):
                    os.unlink(target)
            for tmp, _ in pending:
                forget_temp(tmp, remove=True)
            raise OutputError(f"cannot write the outputs: {_describe_oserror(exc)}") from exc
        finally:
            _note("E")
        for d in pending.dirs:
            forget_temp(d)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, force: bool = False, suffix: str = "") -> Iterator[Path]:
    """Like :func:`atomic_write` for a writer that needs a file name: yields the temporary path to write.

    ``suffix`` is appended to the temporary name (a third-party writer may
    choose its format by it, e.g. ``.nii.gz``).
    """
    p = check_output_path(path, force=force)
    try:
        fd, tmp = _create_temp(p, suffix)
    except OSError as exc:
        raise OutputError(f"{p}: cannot create file: {_describe_oserror(exc)}") from exc
    os.close(fd)
    try:
        yield tmp
        _publish(tmp, p)
    except BaseException as exc:
        forget_temp(tmp, remove=True)
        if isinstance(exc, OSError):
            raise OutputError(f"{p}: cannot write: {_describe_oserror(exc)}") from exc
        raise


def _fsync_dir(directory: Path) -> None:
    # Make the rename durable; not possible on every platform, so best effort.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, force: bool = False, durable: bool = False) -> Iterator[BinaryIO]:
    """Write a file atomically.

    Yields a binary file object on a temporary file ``.{name}.tmp-XXXXXXXX``
    in the target's directory. When the ``with`` block finishes normally the
    data is flushed and the temporary file is renamed onto `path` with
    :func:`os.replace`, so readers see either the old file or the whole new
    one, never a partial file. If the block raises, the temporary file is
    removed, the target is left as it was, and the exception propagates.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    force : bool, optional
        Allow replacing an existing file.
    durable : bool, optional
        Also fsync the data and the directory before returning, so the file
        survives a power failure. Off by default: forcing a gigabyte-sized
        STL to disk costs seconds, and atomicity does not need it.

    Yields
    ------
    BinaryIO
        The open temporary file.

    Raises
    ------
    OutputError
        If :func:`check_output_path` refuses `path`, or any :class:`OSError`
        occurs while creating, writing or renaming the file (permission
        denied, disk full, ...), including one raised inside the block.

    Examples
    --------
    >>> import os, tempfile
    >>> target = os.path.join(tempfile.mkdtemp(), "out.bin")
    >>> with atomic_write(target) as f:
    ...     n = f.write(b"data")
    >>> open(target, "rb").read()
    b'data'
    """
    p = check_output_path(path, force=force)
    try:
        fd, tmp = _create_temp(p)
    except OSError as exc:
        raise OutputError(f"{p}: cannot create file: {_describe_oserror(exc)}") from exc
    fobj = None
    try:
        fobj = os.fdopen(fd, "wb")
        yield fobj
        if fobj.closed:  # the caller closed it; data is flushed
            if durable:
                fd2 = os.open(tmp, os.O_RDONLY)
                try:
                    os.fsync(fd2)
                finally:
                    os.close(fd2)
        else:
            fobj.flush()
            if durable:
                os.fsync(fobj.fileno())
            fobj.close()
        _publish(tmp, p)
    except BaseException as exc:
        if fobj is None:
            os.close(fd)
        else:
            with contextlib.suppress(OSError):
                fobj.close()
        forget_temp(tmp, remove=True)
        if isinstance(exc, OSError):
            raise OutputError(f"{p}: cannot write: {_describe_oserror(exc)}") from exc
        raise
    if durable:
        _fsync_dir(p.parent)
