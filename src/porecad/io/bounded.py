"""Bounded reading of untrusted files: sizes checked before anything is read or inflated.

Files from other people may be truncated, corrupt or hostile (a 9 MB zip
that inflates to terabytes, a zlib stream that never ends, a file that is
larger than the machine's memory). The helpers here check sizes from
headers and the file system *before* reading or decompressing, stream with
a hard output bound, and describe a parser's failure without quoting the
file (an error message must never echo a line of, say, ``/etc/passwd``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys

from ..errors import InputError, ResourceError

__all__ = ["quiet_third_party", "check_file_size", "zip_member", "available_memory", "memory_budget", "check_memory", "failure_reason", "Malformed",
           "MAX_ZIP_MEMBER", "MAX_ZIP_RATIO"]


class Malformed(ValueError):
    """A reason, in our words, why a mesh file cannot be read (never quotes the file)."""


#: largest uncompressed size of one zip member read (bytes)
MAX_ZIP_MEMBER = 8 << 30
#: largest compression ratio accepted for a zip member (deflated XML reaches about 10 to 30)
MAX_ZIP_RATIO = 1000


def check_file_size(path, limit: int, what: str) -> int:
    """The size of regular file ``path`` in bytes, or a one-line error when it exceeds ``limit``.

    Anything but a regular file (a FIFO, a device, ``/proc``) is refused
    before it is opened (:func:`porecad.io.confine.regular_file`).
    """
    from .confine import regular_file
    size = regular_file(path, what)
    if size > limit:
        raise ResourceError(f"{path}: {size:,} bytes is too large for {what} (at most {limit:,})")
    return size


def available_memory() -> int:
    """Bytes of memory available to this process now (psutil; a conservative 2 GiB without it)."""
    try:
        import psutil
        return int(psutil.virtual_memory().available)
    except Exception:  # pragma: no cover - psutil is a dependency
        return 2 << 30


def memory_budget(memory_limit=None) -> int:
    """Bytes a job may use: ``memory_limit`` when given, else the available memory."""
    return available_memory() if memory_limit is None else int(memory_limit)


def check_memory(need: float, what: str, fraction: float = 0.8) -> None:
    """Refuse up front when ``need`` bytes exceed ``fraction`` of the available memory (ResourceError)."""
    have = available_memory() * fraction
    if not need <= have:  # also refuses NaN
        raise ResourceError(f"{what} needs about {need / 2**30:.3g} GiB of memory; {have / 2**30:.3g} GiB is "
                            "available")


def zip_member(zf, name: str, what: str, limit: int = MAX_ZIP_MEMBER, ratio: int = MAX_ZIP_RATIO,
               memory_factor: float = 0.0):
    """Open member ``name`` of a :class:`zipfile.ZipFile` after checking its declared sizes.

    The uncompressed size in the zip directory bounds what :mod:`zipfile`
    will ever produce (it stops there and checks the CRC), so checking it
    first refuses a zip bomb without inflating a byte.

    Parameters
    ----------
    zf : zipfile.ZipFile
    name : str
        The member.
    what : str
        The archive, for messages.
    limit : int
        Largest uncompressed size.
    ratio : int
        Largest uncompressed / compressed ratio.
    memory_factor : float
        When positive, refuse a member whose size times this factor exceeds
        the available memory (what parsing it will hold).
    """
    info = zf.getinfo(name)
    size, packed = int(info.file_size), max(int(info.compress_size), 1)
    if size > limit:
        raise InputError(f"{what}: an archive member inflates to {size:,} bytes (at most {limit:,}): refused")
    if size > 1 << 20 and size / packed > ratio:
        raise InputError(f"{what}: archive member inflates {size / packed:,.0f} times (at most {ratio}): refused "
                         "as a likely zip bomb")
    if memory_factor > 0:
        check_memory(size * memory_factor, f"{what}: reading its {size:,}-byte model")
    return zf.open(info)


def failure_reason(exc: BaseException) -> str:
    """A third-party parser's failure in words, without its message (which may quote the file)."""
    import struct

    if isinstance(exc, MemoryError):
        return "too large to read into memory"
    if type(exc).__name__ == "ReadError":  # meshio
        return "not in this format, or corrupt"
    if isinstance(exc, SystemExit):
        return "not in this format, or corrupt"
    if isinstance(exc, (UnicodeError,)):
        return "undecodable text"
    if isinstance(exc, (struct.error, EOFError)):
        return "truncated or corrupt binary data"
    if isinstance(exc, (IndexError, KeyError)):
        return "a count, index or reference is inconsistent"
    if isinstance(exc, (OverflowError,)):
        return "a number is out of range"
    if isinstance(exc, (ValueError, TypeError)):
        return "malformed or unparsable data"
    if isinstance(exc, RecursionError):
        return "nested too deeply"
    return f"unreadable ({type(exc).__name__})"


@contextlib.contextmanager
def quiet_third_party():
    """Silence what a third-party reader prints while it runs (its failure still surfaces as an exception).

    trimesh logs tracebacks of the parsers it tries, meshio prints warnings,
    and ITK's MetaIO and GDCM write to file descriptor 2 from C++: none of it
    may reach the user (one-line errors; ``--json`` prints exactly one JSON
    object on stdout), and it may quote the file. Logging is disabled,
    Python's ``sys.stdout``/``sys.stderr`` and file descriptors 1 and 2 point
    to the null device for the duration.
    """
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    saved = []
    try:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, ValueError, OSError):
                pass
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                for fd in (1, 2):
                    saved.append((fd, os.dup(fd)))
                    os.dup2(devnull, fd)
            finally:
                os.close(devnull)
        except OSError:  # no real descriptors (embedded use): Python-level redirection only
            pass
        with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            yield
    finally:
        for fd, copy in reversed(saved):
            os.dup2(copy, fd)
            os.close(copy)
        logging.disable(previous)
