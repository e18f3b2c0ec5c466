"""File input and output: atomic writes and mesh file formats.

The names below load their module on first use (PEP 562): importing
``porecad.io.atomic`` (every command does) loads neither numpy nor the mesh
formats and their compiled kernels.
"""

import importlib

#: name -> the module of porecad.io that defines it
_NAMES = {
    "atomic_write": "atomic",
    "check_output_path": "atomic",
    "read_mesh": "meshfiles",
    "write_mesh": "meshfiles",
}

__all__ = [
    "atomic_write",
    "check_output_path",
    "read_mesh",
    "write_mesh",
]


def __getattr__(name):
    if name not in _NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_NAMES[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
