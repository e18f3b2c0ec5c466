"""The mesh file formats porecad reads and writes, in one table (a registry in the manner of meshio's).

The writers and readers (:mod:`porecad.io.meshfiles`), the streamed writer
(:mod:`porecad.io.stream_mesh`), the command line's help, the recipe
schema's help and the studio's upload list all read :data:`MESH_FORMATS`; a
new format is an entry here and its reader or writer in ``meshfiles.py``.
Pure Python (no numpy), so the help texts can read it.
"""

from __future__ import annotations

#: format name -> what porecad does with it: read, write, stream (write slab by slab, memory bounded)
MESH_FORMATS = {
    "stl": {"title": "STL (binary; ASCII read too)", "read": True, "write": True, "stream": True},
    "ply": {"title": "PLY (binary)", "read": True, "write": True, "stream": True},
    "obj": {"title": "Wavefront OBJ", "read": True, "write": True, "stream": False},
    "off": {"title": "OFF", "read": True, "write": False, "stream": False},
    "3mf": {"title": "3MF (core mesh)", "read": True, "write": True, "stream": False},
}


def mesh_formats(can: str) -> tuple[str, ...]:
    """The names of the formats porecad can ``"read"``, ``"write"`` or ``"stream"``."""
    return tuple(name for name, f in MESH_FORMATS.items() if f[can])


def mesh_suffixes(can: str, sep: str | None = None):
    """The file suffixes (``.stl``, ...) of :func:`mesh_formats`; joined by ``sep`` when given."""
    out = tuple("." + name for name in mesh_formats(can))
    return out if sep is None else sep.join(out)
