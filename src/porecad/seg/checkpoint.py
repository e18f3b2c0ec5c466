"""Checkpoints: plain weights only (``torch.load(..., weights_only=True)``).

A checkpoint is one ``torch.save`` file holding a dict of primitive values and
tensors only::

    {"format": "porecad-ivd-unet3d" | "porecad-ivd-unet2d", "version": 1,
     "meta": "<JSON text: channels, network sizes, crop, training summary>",
     "nets": {name: state_dict, ...}}

plus ``<file>.json`` with the same meta for people. Loading never unpickles
arbitrary objects: anything that is not plain weights is refused with a
one-line :class:`~porecad.errors.InputError`.
"""

from __future__ import annotations

import json
import pickle
import zipfile
from pathlib import Path

from ..errors import InputError

FORMATS = ("porecad-ivd-unet3d", "porecad-ivd-unet2d")
VERSION = 1


def save_checkpoint(path, fmt: str, meta: dict, nets: dict, force: bool = False) -> Path:
    """Write the checkpoint and its JSON side file atomically."""
    import torch

    from ..io import check_output_path
    from ..io.atomic import atomic_write
    p = check_output_path(path, force=force)
    side = Path(str(p) + ".json")
    check_output_path(side, force=force)
    payload = {"format": fmt, "version": VERSION, "meta": json.dumps(meta),
               "nets": {k: {n: t.detach().cpu() for n, t in m.state_dict().items()} for k, m in nets.items()}}
    with atomic_write(p, force=force) as fh:
        torch.save(payload, fh)
    with atomic_write(side, force=True) as fh:
        fh.write((json.dumps({"format": fmt, "version": VERSION, **meta}, indent=1) + "\n").encode())
    return p


def load_checkpoint(path) -> tuple[str, dict, dict]:
    """``(format, meta, state dicts)`` of a checkpoint, refusing anything but plain weights."""
    import torch
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such checkpoint")
    if p.is_dir():
        raise InputError(f"{p}: is a directory, not a checkpoint file")
    try:
        obj = torch.load(p, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        first = (str(exc).strip().splitlines() or ["?"])[0]
        raise InputError(f"{p}: not a plain-weights checkpoint; refusing to load it "
                         f"({first[:120]})") from None
    except (RuntimeError, EOFError, OSError, ValueError, KeyError, zipfile.BadZipFile, AttributeError,
            TypeError, IndexError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputError(f"{p}: not a readable checkpoint ({first[:120]})") from None
    if not isinstance(obj, dict) or obj.get("format") not in FORMATS or not isinstance(obj.get("nets"), dict):
        raise InputError(f"{p}: not a porecad IVD checkpoint (written by `porecad seg train`)")
    if obj.get("version") != VERSION:
        raise InputError(f"{p}: checkpoint version {obj.get('version')!r}; this porecad reads version {VERSION}")
    try:
        meta = json.loads(obj.get("meta", "{}"))
    except (TypeError, ValueError):
        raise InputError(f"{p}: checkpoint meta data is not JSON") from None
    return obj["format"], meta, obj["nets"]


def load_into(model, state: dict, name: str, path) -> None:
    """Load a state dict into a network; a mismatch is a one-line error."""
    try:
        model.load_state_dict(state, strict=True)
    except (RuntimeError, TypeError, AttributeError) as exc:
        first = (str(exc).strip().splitlines() or ["?"])[0]
        raise InputError(f"{path}: the {name} weights do not fit the network ({first[:120]})") from None
