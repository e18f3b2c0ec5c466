"""Safe output files: refuse clobbering, write atomically.

Every file porecad writes goes through :func:`atomic_write`: the data lands in
a hidden temporary file next to the target, is flushed to disk, and only then
renamed over the target with :func:`os.replace`. A crash or exception part
way through therefore never leaves a truncated output behind, and an existing
file is either fully replaced or left untouched.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from porecad.errors import OutputError, one_line

__all__ = ["check_output_path", "check_output_dir", "atomic_write"]


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
    p = Path(os.fspath(path))
    if not p.name or p.is_dir():
        raise OutputError(f"{p}: is a directory, not a file")
    if (p.exists() or p.is_symlink()) and not force:
        raise OutputError(f"{p}: already exists (use force / --force to overwrite)")
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


def _create_temp(p: Path) -> tuple[int, Path]:
    # O_EXCL with a random suffix; mode 0o666 so the process umask applies and
    # the final file gets ordinary permissions (mkstemp would give 0o600).
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = p.parent / f".{p.name}.tmp-{secrets.token_hex(4)}"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"could not create a temporary file next to {p}")


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
        os.replace(tmp, p)
    except BaseException as exc:
        if fobj is None:
            os.close(fd)
        else:
            with contextlib.suppress(OSError):
                fobj.close()
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise OutputError(f"{p}: cannot write: {_describe_oserror(exc)}") from exc
        raise
    if durable:
        _fsync_dir(p.parent)
