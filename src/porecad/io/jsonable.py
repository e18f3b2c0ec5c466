"""JSON for reports: numpy scalars and arrays and paths as plain JSON values."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def json_default(obj):
    """``json.dumps`` default: numpy scalars and arrays, paths."""
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def dumps(obj, indent=None) -> str:
    """``json.dumps`` with :func:`json_default`."""
    return json.dumps(obj, default=json_default, indent=indent)
