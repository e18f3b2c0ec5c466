"""Where untrusted files may point: outputs inside a folder, inputs that are plain files.

A recipe is meant to be shared, so running one must not write outside its
own folder: :func:`confined_output` accepts only a relative path without
``..`` or ``~`` whose real location (symlinks followed) stays inside the
folder. Every reader opens only a regular file (:func:`regular_file`): a
FIFO blocks forever, ``/dev/zero`` never ends and ``/proc`` files report a
size of 0, so each is refused before it is opened. An image header may name
a detached data file only beside itself (:func:`detached_file`).
:func:`check_name` refuses names no file system takes (a component over 255
bytes, text that cannot be encoded) and names with a control character
(newline, carriage return, tab, NUL, DEL, C1 controls, the Unicode line and
paragraph separators): such a name breaks every line-based record and
message that shows it.
"""

from __future__ import annotations

import os
import stat
import sys
import unicodedata
from pathlib import Path

from ..errors import InputError

__all__ = ["check_name", "confined_output", "regular_file", "detached_file", "SYSTEM_DIRS", "MAX_NAME_BYTES"]

#: longest file or folder name (bytes, encoded) on common file systems
MAX_NAME_BYTES = 255
#: pseudo-file systems whose files lie about their size or never end
SYSTEM_DIRS = ("/proc", "/sys", "/dev")
#: how a refusal names the commonest control characters (others by code point)
_CONTROL_NAMES = {"\x00": "NUL", "\n": "newline", "\r": "carriage return", "\t": "tab", "\x7f": "DEL"}


def check_name(name, what: str) -> str:
    """``name`` as a string, or a one-line :class:`InputError` naming ``what`` for a name no file can have."""
    s = os.fspath(name)
    if isinstance(s, bytes):
        s = os.fsdecode(s)
    bad = next((c for c in s if unicodedata.category(c) in ("Cc", "Zl", "Zp")), None)  # Zl, Zp: line breaks
    if bad is not None:
        label = _CONTROL_NAMES.get(bad, f"U+{ord(bad):04X}")
        raise InputError(f"{what}: a file name cannot contain a control character ({label})")
    try:
        encoded = s.encode(sys.getfilesystemencoding() or "utf-8", "strict")
    except UnicodeEncodeError:
        raise InputError(f"{what}: the file name {s[:40]!r} cannot be encoded on this system") from None
    for part in encoded.split(b"/"):
        if len(part) > MAX_NAME_BYTES:
            raise InputError(f"{what}: a file or folder name is {len(part)} bytes long (at most {MAX_NAME_BYTES})")
    return s


def _inside(path: Path, root: Path) -> bool:
    try:
        path.relative_to(root)
        return True
    except ValueError:
        return False


def confined_output(value: str, root, what: str) -> Path:
    """The output ``value`` (a recipe's relative path) resolved inside folder ``root``, or a refusal.

    Refused: absolute paths, ``~``, any ``..`` component, and a path whose
    real location (every symlink on the way followed, the file itself
    included) leaves ``root``. ``what`` names the recipe key in the message.

    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> confined_output("out/a.stl", d, "output.mesh").name
    'a.stl'
    >>> confined_output("../a.stl", d, "output.mesh")
    Traceback (most recent call last):
    ...
    porecad.errors.InputError: output.mesh: '../a.stl' leaves the recipe's folder (no '..' in an output path)
    """
    s = check_name(value, what)
    if s.startswith("~"):
        raise InputError(f"{what}: {s!r} names a home folder; a recipe writes only inside its own folder")
    p = Path(s)
    if p.is_absolute() or p.drive:
        raise InputError(f"{what}: {s!r} is an absolute path; a recipe writes only inside its own folder "
                         "(give a relative path, or run it with an output folder of your choice)")
    if ".." in p.parts:
        raise InputError(f"{what}: {s!r} leaves the recipe's folder (no '..' in an output path)")
    base = Path(os.path.realpath(root))
    target = base / p
    if not _inside(Path(os.path.realpath(target)), base):
        raise InputError(f"{what}: {s!r} leads outside the recipe's folder through a symbolic link")
    return target


def regular_file(path, what: str = "input") -> int:
    """The size of ``path`` when it is a regular file outside ``/proc``, ``/sys`` and ``/dev``; else a refusal.

    Checked before the file is opened: a FIFO would block, a device never
    ends, a ``/proc`` file reports size 0.
    """
    s = check_name(path, what)
    real = os.path.realpath(s)
    if any(real == d or real.startswith(d + "/") for d in SYSTEM_DIRS):
        raise InputError(f"{s}: a system file ({real}), not a file to read as {what}")
    try:
        st = os.stat(real)
    except FileNotFoundError:
        raise InputError(f"{s}: no such file") from None
    except OSError as exc:
        raise InputError(f"{s}: cannot be read ({exc.strerror or type(exc).__name__})") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{s}: is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" if stat.S_ISCHR(st.st_mode) or \
            stat.S_ISBLK(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file"
        raise InputError(f"{s}: is {kind}, not a regular file")
    return int(st.st_size)


def detached_file(header, name: str, need: int | None = None) -> Path:
    """The data file ``name`` that image header ``header`` names, when it lies beside the header; else a refusal.

    Only a plain file name in the header's own folder is accepted (no folder,
    no ``..``, no absolute path), it must be a regular file, and it must hold
    at least ``need`` bytes when given (the header's promise).
    """
    h = Path(header)
    n = name.strip()
    n = n[2:] if n.startswith("./") else n
    if not n or "/" in n or "\\" in n or n in (".", "..") or Path(n).is_absolute() or n.startswith("~"):
        raise InputError(f"{h}: the header names a data file {n[:60]!r} outside its own folder; a detached data "
                         "file must lie beside the header")
    p = h.parent / n
    size = regular_file(p, "image data")
    if need is not None and size < need:
        raise InputError(f"{h}: its data file {n} holds {size:,} bytes, the header announces {need:,}")
    return p
