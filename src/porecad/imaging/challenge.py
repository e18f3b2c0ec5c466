"""The public IVD challenge layout (000 §6.2.1) and other image folders.

The multi-modality IVD data of 000 ch.6 (University of Bern; published as
the MICCAI 2018 IVDM3Seg challenge) hold, per subject, four Dixon
volumes and a binary label map as NIfTI files named by a subject id::

    Training/
      01/01_inn.nii  01/01_opp.nii  01/01_fat.nii  01/01_wat.nii  01/01_Labels.nii
      02/...

Supported here (case-insensitive):

* a *subject folder* with files ``<id>_<channel>.<ext>`` where ``<channel>``
  is ``inn``, ``opp``, ``fat`` or ``wat`` (also ``in``, ``water``, ``t2``,
  ``ct``, ``image``), and optionally ``<id>_Labels.<ext>`` (or ``_label``,
  ``_seg``, ``_mask``); ``<ext>`` is ``nii``, ``nii.gz``, ``mha``, ``mhd``,
  ``nrrd`` or ``nhdr``; or subfolders named by channel, each a DICOM series
  (or holding one image file);
* a *data set folder* whose subfolders are subject folders (all subjects);
* a single image file or DICOM series folder (one channel, ``image``).

All channels of a subject must share one grid (checked: size, spacing,
origin, direction), else a one-line error.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..errors import InputError
from .io import Stack, read_stack

CHANNEL_ALIASES = {"inn": "inn", "in": "inn", "opp": "opp", "fat": "fat", "wat": "wat", "water": "wat",
                   "t2": "t2", "ct": "ct", "image": "image"}
LABEL_WORDS = ("labels", "label", "seg", "mask")
EXT = r"\.(nii\.gz|nii|mha|mhd|nrrd|nhdr)$"
_CHANNEL_RE = re.compile(r"^(?P<id>.*?)[_\-\.]?(?P<ch>" + "|".join(sorted(CHANNEL_ALIASES, key=len, reverse=True))
                         + r")" + EXT, re.IGNORECASE)
_LABEL_RE = re.compile(r"^(?P<id>.*?)[_\-\.]?(?P<ch>" + "|".join(LABEL_WORDS) + r")" + EXT, re.IGNORECASE)
#: channel order used by default (000 §6.2.7: opp, wat, fat is the best combination)
DEFAULT_ORDER = ("opp", "wat", "fat", "inn", "t2", "ct", "image")


def _is_dicom_dir(p: Path) -> bool:
    return p.is_dir() and any(f.suffix.lower() == ".dcm" for f in p.iterdir() if f.is_file())


def scan_subject(folder) -> tuple[dict, Path | None, str]:
    """Channel name → path, the label file (or None) and the subject id of one subject folder."""
    d = Path(os.fspath(folder))
    channels, labels, ids = {}, None, set()
    for f in sorted(d.iterdir()):
        name = f.name
        if f.is_file():
            m = _LABEL_RE.match(name)
            if m:
                if labels is not None:
                    raise InputError(f"{d}: two label files ({labels.name}, {name})")
                labels = f
                ids.add(m.group("id"))
                continue
            m = _CHANNEL_RE.match(name)
            if m:
                ch = CHANNEL_ALIASES[m.group("ch").lower()]
                if ch in channels:
                    raise InputError(f"{d}: two files for channel {ch!r} ({channels[ch].name}, {name})")
                channels[ch] = f
                ids.add(m.group("id"))
        elif f.is_dir() and f.name.lower() in CHANNEL_ALIASES:
            ch = CHANNEL_ALIASES[f.name.lower()]
            if _is_dicom_dir(f):
                channels[ch] = f
            else:
                inner = [g for g in f.iterdir() if re.search(EXT, g.name, re.IGNORECASE)]
                if len(inner) == 1:
                    channels[ch] = inner[0]
        elif f.is_dir() and f.name.lower() in LABEL_WORDS:
            labels = f
    subject = sorted(ids)[0].strip("_-.") if ids else d.name
    return channels, labels, subject or d.name


def find_subjects(root) -> list[Path]:
    """Subject folders under ``root`` (``root`` itself when it is one); InputError for an unreadable folder."""
    r = Path(os.fspath(root))
    try:
        return _subjects(r)
    except OSError as exc:  # an entry that cannot be listed or stat'ed (permissions, /proc, a vanished file)
        raise InputError(f"{r}: cannot read {exc.filename or 'it'} ({exc.strerror or type(exc).__name__})") from None


def _subjects(r: Path) -> list[Path]:
    if not r.exists():
        raise InputError(f"{r}: no such file or directory")
    if r.is_file() or _is_dicom_dir(r):
        return [r]
    ch, _, _ = scan_subject(r)
    if ch:
        return [r]
    subs = [s for s in sorted(r.iterdir()) if s.is_dir() and scan_subject(s)[0]]
    if not subs:
        raise InputError(f"{r}: no images found (expected <id>_opp/_wat/_fat/_inn NIfTI/MHA/NRRD files, channel "
                         "subfolders with DICOM series, subject subfolders, or one image)")
    return subs


def load_subject(path, channels=None, labels: bool = True) -> tuple[Stack, str]:
    """Read one subject: ``(stack, subject id)``.

    Parameters
    ----------
    path : path
        Subject folder, single image file or DICOM series folder.
    channels : list of str, optional
        Channels to read (default: all found, in the order opp, wat, fat, inn).
    labels : bool
        Also read the label map when there is one.
    """
    p = Path(os.fspath(path))
    if not p.exists():
        raise InputError(f"{p}: no such file or directory")
    if p.is_file() or _is_dicom_dir(p):
        if channels and list(channels) != ["image"]:
            raise InputError(f"{p} is a single image; it has no channels {', '.join(channels)}")
        name = p.name.split(".")[0]
        return read_stack({"image": p}), name
    found, lab, subject = scan_subject(p)
    if not found:
        raise InputError(f"{p}: no image channels found (expected files like 01_opp.nii, 01_wat.nii)")
    if channels:
        missing = [c for c in channels if c not in found]
        if missing:
            raise InputError(f"{p}: channel(s) {', '.join(missing)} not found; found {', '.join(found)}")
        order = list(channels)
    else:
        order = [c for c in DEFAULT_ORDER if c in found]
    stack = read_stack({c: found[c] for c in order}, labels=lab if labels else None)
    return stack, subject


def load_dataset(root, channels=None) -> list[tuple[Stack, str]]:
    """Every subject under ``root`` (see :func:`find_subjects`)."""
    return [load_subject(s, channels) for s in find_subjects(root)]
