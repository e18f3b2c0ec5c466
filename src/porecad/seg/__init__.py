"""U-Net segmentation of intervertebral discs (000 §6.2) — the ``seg`` extra (PyTorch + MONAI).

Nothing here is imported by porecad's core; the modules import torch at
import time, so call :func:`require_torch` first: without the extra it raises
a one-line :class:`~porecad.errors.InputError` saying how to install it.
"""

from __future__ import annotations

from ..errors import InputError

INSTALL_HINT = ("segmentation needs the seg extra: pip install torch --index-url https://download.pytorch.org/whl/cpu "
                "(the CPU build; a plain install pulls CUDA's, several GB), then pip install 'porecad[seg]' "
                "(PyTorch and MONAI)")


def _import_torch():
    import monai  # noqa: F401
    import torch
    return torch


def require_torch():
    """Import torch (and check MONAI); a one-line InputError with the install command if missing."""
    try:
        return _import_torch()
    except ImportError:
        raise InputError(INSTALL_HINT) from None
