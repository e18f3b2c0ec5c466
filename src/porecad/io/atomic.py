"""Safe output files: refuse clobbering, write atomically.

Every file porecad writes goes through :func:`atomic_write`: the data lands in
a hidden temporary file next to the target, is flushed to disk, and only then
renamed over the target with :func:`os.replace`. A crash or exception part
way through therefore never leaves a truncated output behind, and an existing
file is either fully replaced or left untouched.

Two more guarantees hold for a run's outputs:

- **All or nothing.** Inside :func:`output_set` the renames are deferred
  until the block ends, so the files of one run (mesh, recipe, report) appear
  together, or none does when the block raises; each earlier file is kept
  aside while the set is renamed into place, so a rename that fails puts
  every earlier file back.
- **Nothing left behind on a signal.** Every temporary file is announced
  before it is created and recorded with its identity (device, inode) once
  made; :func:`set_journal` sends each record to a pipe, one JSON object a
  line (a name with a newline cannot forge a record), so that a watching
  parent process (the command line's, :mod:`porecad.cli.watch`) that kills a
  run removes what this run made, and only that (:func:`remove_temp`), puts
  the earlier files of a set cut short back (:func:`restore_backup`), and
  says exactly what was written.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
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
           "temp_file", "temp_dir", "register_temp", "forget_temp", "set_journal", "identity", "remove_temp",
           "restore_backup"]


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
    read-only or unwritable ancestor, or a name no file can have; creates nothing.
    """
    from .confine import check_name
    try:
        p = Path(check_name(path, "output folder"))
    except InputError as exc:
        raise OutputError(str(exc)) from None
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


def _create_temp(p: Path, suffix: str = "", tag: str = "tmp", folder: bool = False) -> tuple[int | None, Path]:
    # O_EXCL with a random name; mode 0o666 so the process umask applies and
    # the final file gets ordinary permissions (mkstemp would give 0o600).
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = p.parent / f".{p.name}.{tag}-{secrets.token_hex(4)}{suffix}"
        with _LOCK:  # announced before it exists, so that an abort never misses it
            register_temp(tmp)
            try:
                fd = None if folder else os.open(tmp, flags, 0o666)
                if folder:
                    os.mkdir(tmp)
            except FileExistsError:
                forget_temp(tmp)
                continue
            except BaseException:
                forget_temp(tmp)
                raise
            _made(tmp, tree=folder)
            return fd, tmp
    raise FileExistsError(f"could not create a temporary file next to {p}")


def temp_file(near, tag: str) -> tuple[int, Path]:
    """A new hidden temporary file ``.{name}.{tag}-XXXXXXXX`` beside ``near``: ``(open descriptor, path)``.

    Journaled as made by this run; :func:`forget_temp` (``remove``) or an
    abort removes it, only while it still is that very file.
    """
    from .confine import check_name
    return _create_temp(Path(check_name(near, "output")), tag=tag)


def temp_dir(near, tag: str) -> Path:
    """A new hidden temporary folder beside ``near`` (like :func:`temp_file`; removed with its content)."""
    from .confine import check_name
    return _create_temp(Path(check_name(near, "output")), tag=tag, folder=True)[1]


# ---------------------------------------------------------------------------- registry and output sets
_LOCK = threading.RLock()
#: temporaries of this process now on disk: path -> (identity once made, else None; a folder to remove whole)
_TEMPS: dict[Path, tuple] = {}
#: the pipe (a file descriptor) each registration and completed rename is reported to, or None
_JOURNAL: list = [None]
_SET: contextvars.ContextVar = contextvars.ContextVar("porecad_output_set", default=None)


def set_journal(fd: int | None) -> None:
    """Report temporaries and outputs to pipe ``fd``, one JSON object a line (None: stop reporting).

    ``{"op": "temp", "path", "id", ...}`` a temporary about to be made
    (``id`` null) or made (``id`` its ``[st_dev, st_ino]``; ``tree``: a
    temporary folder, ``of``: an earlier output kept aside while a set
    commits); ``{"op": "gone", "path"}`` it is gone; ``{"op": "done", "path",
    "id", "was"}`` temporary ``was`` is about to be renamed onto output
    ``path``; ``{"op": "begin"}`` and ``{"op": "end", "ok"}`` bracket an
    output set's renames. A name is a JSON string, never a line of its own.
    """
    _JOURNAL[0] = fd


def _forget_journal_in_child() -> None:  # a forked helper process writes no outputs
    _JOURNAL[0] = None


os.register_at_fork(after_in_child=_forget_journal_in_child)


def _note(op: str, path=None, **fields) -> None:
    fd = _JOURNAL[0]
    if fd is None:
        return
    record = {"op": op} if path is None else {"op": op, "path": os.path.abspath(os.fsdecode(path))}
    data = (json.dumps({**record, **fields}) + "\n").encode("ascii")
    try:
        while data:
            data = data[os.write(fd, data):]
    except OSError:
        _JOURNAL[0] = None


def identity(path) -> tuple[int, int] | None:
    """``(st_dev, st_ino)`` of ``path`` itself (a link not followed), or None when there is nothing."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def remove_temp(path, ident=None, tree: bool = False) -> bool:
    """Remove the temporary ``path`` of this run if it still is what was made; True when removed.

    With ``ident`` (its identity once made) only that very file, or folder
    (with its content when ``tree``, else only when empty); without, the
    name was announced but not yet confirmed made: only an empty file or an
    empty folder goes. Never follows a link, never removes anything else.
    """
    try:
        st = os.lstat(path)
        if ident is not None and (st.st_dev, st.st_ino) != tuple(ident):
            return False
        if stat.S_ISDIR(st.st_mode):
            shutil.rmtree(path) if tree and ident is not None else os.rmdir(path)
        elif ident is not None or (stat.S_ISREG(st.st_mode) and st.st_size == 0):
            os.unlink(path)
        else:
            return False
    except OSError:
        return False
    return True


def restore_backup(backup, ident, target, new=None) -> bool:
    """Undo one rename of a cut-short set: earlier file ``backup`` goes back to ``target``; True when it did.

    Restored when ``target`` is gone or holds this run's new file (identity
    ``new``); else (``target`` is still the earlier file, or someone
    replaced it since) the backup, an extra name of the earlier file or a
    copy nobody asked for, is removed. Either only while ``backup`` still
    has identity ``ident``.
    """
    if identity(backup) != tuple(ident):
        return False
    now = identity(target)
    try:
        if now is None or (new is not None and now == tuple(new)):
            os.replace(backup, target)
            return True
        os.unlink(backup)
    except OSError:
        pass
    return False


def register_temp(path) -> None:
    """Note a temporary file or folder about to be created (removed by an abort only if still empty)."""
    with _LOCK:
        _TEMPS[Path(path)] = (None, False)
        _note("temp", path, id=None)


def _made(path, tree: bool = False, **fields) -> tuple:
    """The temporary ``path`` now exists, made by this run: its identity is recorded (and journaled)."""
    ident = fields.pop("id", None) or identity(path)
    with _LOCK:
        _TEMPS[Path(path)] = (ident, tree)
        _note("temp", path, id=list(ident) if ident else None, tree=tree, **fields)
    return ident


def _adopt(tmp: Path) -> None:
    """A writer given the temporary name may have made a new file there: that file is this run's too."""
    ident = identity(tmp)
    if ident is not None and tmp in _TEMPS and _TEMPS[tmp][0] != ident:
        _made(tmp)


def forget_temp(path, remove: bool = False) -> None:
    """The temporary ``path`` is gone or renamed (``remove``: delete it first, if it still is this run's)."""
    p = Path(path)
    with _LOCK:
        ident, tree = _TEMPS.pop(p, (None, None))
        if remove and tree is not None:
            remove_temp(p, ident, tree)
        _note("gone", p)


def _publish(tmp: Path, target: Path) -> None:
    """Rename a finished temporary file onto its target now, or when the open output set commits."""
    pending = _SET.get()
    if pending is not None:
        pending.append((tmp, target))
        return
    with _LOCK:
        new = identity(tmp)
        _note("done", target, id=new and list(new), was=os.path.abspath(tmp))
        os.replace(tmp, target)
        _TEMPS.pop(tmp, None)


def withdraw(target) -> bool:
    """Take back the pending writes of ``target`` in the open output set (their temporary files go).

    For a job that wrote a file and then found it must write it again (a
    streamed mesh whose porosity missed): the set then renames only the new
    one. Returns whether anything was pending (outside a set, nothing is).
    """
    pending = _SET.get()
    if pending is None:
        return False
    target = os.path.abspath(target)
    gone = [(tmp, t) for tmp, t in pending if os.path.abspath(t) == target]
    for entry in gone:
        pending.remove(entry)
        forget_temp(entry[0], remove=True)
    return bool(gone)


def make_dirs(path) -> Path:
    """Create folder ``path`` (and parents); inside an output set, ones it created go if the set fails."""
    from .confine import check_name
    p = Path(check_name(path, "output folder"))
    made = []
    for a in reversed([a for a in (p, *p.parents) if not a.exists()]):
        register_temp(a)
        try:
            os.mkdir(a)
        except FileExistsError:  # someone else's (or a file: the next mkdir says so)
            forget_temp(a)
            continue
        except BaseException:
            forget_temp(a)
            raise
        _made(a)
        made.append(a)
    if not p.is_dir():
        raise FileExistsError(f"{p}: exists and is not a folder")
    pending = _SET.get()
    if pending is not None:
        pending.dirs.extend(reversed(made))
    else:
        for a in made:
            forget_temp(a)
    return p


class _Pending(list):
    """``(temporary, target)`` renames of an open output set, and the folders it created (deepest first)."""

    def __init__(self):
        super().__init__()
        self.dirs: list[Path] = []

    def discard(self) -> None:
        """Remove every temporary file and created folder (only while each is still this run's)."""
        for tmp, _ in self:
            forget_temp(tmp, remove=True)
        for d in self.dirs:
            forget_temp(d, remove=True)


@contextlib.contextmanager
def output_set() -> Iterator[list]:
    """Write several files as one: every :func:`atomic_write` in the block is renamed into place at its end.

    When the block raises (an error, Ctrl-C), every temporary file is
    removed and every folder the block created is removed if empty: no
    output of the set appears. At the end each earlier file is kept aside
    (a second hard link, in the same folder) before the new one replaces it,
    so that a rename that fails puts every earlier file back. Yields the
    list of targets once committed.
    """
    pending = _Pending()
    token = _SET.set(pending)
    done: list[Path] = []
    try:
        yield done
    except BaseException:
        _SET.reset(token)
        pending.discard()
        raise
    _SET.reset(token)
    with _LOCK:
        _note("begin")
        kept: list[tuple] = []  # (target, backup, its identity, the new file's identity) as each is renamed
        try:
            for tmp, target in pending:
                new = identity(tmp)  # a writer given the name may have made a new file there
                kept.append((target, *_back_up(target), new))
                _note("done", target, id=new and list(new), was=os.path.abspath(tmp))
                os.replace(tmp, target)
                _TEMPS.pop(tmp, None)
                done.append(target)
        except BaseException as exc:
            _roll_back(kept)
            pending.discard()
            _note("end", ok=False)
            done.clear()
            if isinstance(exc, OSError):
                raise OutputError(f"cannot write the outputs: {_describe_oserror(exc)}") from exc
            raise
        _note("end", ok=True)
        for _, backup, _, _ in kept:
            if backup is not None:
                forget_temp(backup, remove=True)
        for d in pending.dirs:
            forget_temp(d)


def _back_up(target: Path) -> tuple:
    """Keep the earlier ``target`` aside (a hard link, or a rename where links fail): ``(backup, identity)``.

    ``(None, None)`` when there is no earlier file. The backup is journaled
    with the earlier file's identity before it exists (a link or a rename
    keeps it), so an abort at any moment knows it.
    """
    ident = identity(target)
    if ident is None:
        return None, None
    for _ in range(100):
        backup = target.parent / f".{target.name}.old-{secrets.token_hex(4)}"
        _made(backup, id=ident, of=os.path.abspath(target))
        try:
            try:
                os.link(target, backup, follow_symlinks=False)
            except FileExistsError:
                forget_temp(backup)
                continue
            except OSError:  # no hard links on this file system: move it aside (a failure puts it back)
                os.rename(target, backup)
        except BaseException:
            forget_temp(backup)
            raise
        return backup, ident
    raise FileExistsError(f"could not keep {target} aside")


def _roll_back(kept: list) -> None:
    """Put the earlier files of a set back after one rename failed (or the set was stopped while renaming)."""
    for target, backup, ident, new in reversed(kept):
        if backup is not None:
            restore_backup(backup, ident, target, new)
            with _LOCK:
                _TEMPS.pop(backup, None)
                _note("gone", backup)
        elif new is not None:
            remove_temp(target, new)  # a new file of the set where there was none


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
        _adopt(tmp)
        _publish(tmp, p)
    except BaseException as exc:
        _adopt(tmp)
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
