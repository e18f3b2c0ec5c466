"""Reading and writing tetrahedral meshes with meshio (VTK, VTU, Gmsh, Abaqus, Medit, XDMF).

Only the tetrahedra of a file are used: every ``tetra`` block, and the four
corner nodes of every ``tetra10`` block (quadratic tets; the mid-edge nodes
are left as unused points). Other cells (triangles, lines, hexahedra, ...)
are ignored; points are kept as stored, so a point used by no tet stays, and
indices match the file. What is read goes through
:func:`porecad.volmesh.tetmesh.check_tet_mesh`, so a mesh comes back
positively oriented and conforming or is refused with a one-line reason.

Writes are atomic like every porecad output (:mod:`porecad.io.atomic`):
meshio writes to a hidden temporary file with the same suffix next to the
target, which is then renamed over it with :func:`os.replace`. XDMF is
written with inline XML data (no ``.h5`` companion file, which a rename would
orphan); meshio's XDMF support needs ``h5py`` in any case.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from porecad.errors import InputError, OutputError, one_line
from porecad.io.atomic import check_output_path
from porecad.volmesh.tetmesh import check_tet_mesh

__all__ = ["VOLUME_MESH_SUFFIXES", "is_volume_mesh_path", "read_tet_mesh", "write_tet_mesh", "read_volume_mesh",
           "read_hex_mesh",
           "read_meshio", "volume_mesh_suffix"]

#: File suffixes of the volume mesh formats read and written here.
VOLUME_MESH_SUFFIXES = (".vtk", ".vtu", ".msh", ".inp", ".mesh", ".xdmf")

#: largest volume mesh file read (bytes)
MAX_VOLUME_MESH_BYTES = 4 << 30

#: meshio format names used for writing (``.msh`` is Gmsh 4.1; reading also tries ANSYS).
_WRITE_FORMAT = {".vtk": "vtk", ".vtu": "vtu", ".msh": "gmsh", ".inp": "abaqus", ".mesh": "medit",
                 ".xdmf": "xdmf"}


def is_volume_mesh_path(path) -> bool:
    """Whether ``path`` has a volume mesh suffix (:data:`VOLUME_MESH_SUFFIXES`, case-insensitive)."""
    return Path(os.fspath(path)).suffix.lower() in VOLUME_MESH_SUFFIXES


def volume_mesh_suffix(p: Path) -> str:
    """The lower-case suffix of a volume mesh file, or a one-line error for another format."""
    s = p.suffix.lower()
    if s not in VOLUME_MESH_SUFFIXES:
        what = f"extension {p.suffix!r}" if p.suffix else "no extension"
        raise InputError(f"{p}: {what} is not a volume mesh format "
                         f"(supported: {', '.join(VOLUME_MESH_SUFFIXES)})")
    return s


def read_meshio(p: Path, suffix: str):
    """Read with the format modules of meshio directly.

    ``meshio.read`` prints and calls ``sys.exit(1)`` when a file cannot be
    read; the format readers raise instead. ``.msh`` is tried as Gmsh, then ANSYS.
    """
    import meshio

    from porecad.io.bounded import check_file_size, check_memory, failure_reason
    size = check_file_size(p, MAX_VOLUME_MESH_BYTES, "a volume mesh file")
    check_memory(size * 8.0, f"{p}: reading this volume mesh")
    if suffix in (".vtu", ".xdmf"):  # meshio parses these with xml.etree: refuse DTDs/entities, check blocks first
        from porecad.io.safe_xml import has_doctype
        if has_doctype(p):
            raise InputError(f"{p}: cannot read as a volume mesh (it declares a document type or entities, "
                             "which are not allowed)")
        if suffix == ".vtu":
            from porecad.io.vtk_xml import check_vtk_xml
            check_vtk_xml(p)
    readers = {".vtk": [meshio.vtk.read], ".vtu": [meshio.vtu.read],
               ".msh": [meshio.gmsh.read, meshio.ansys.read], ".inp": [meshio.abaqus.read],
               ".mesh": [meshio.medit.read], ".xdmf": [meshio.xdmf.read]}[suffix]
    from porecad.io.bounded import quiet_third_party
    first = None
    for read in readers:
        try:
            with quiet_third_party():  # meshio prints warnings (and may quote the file)
                return read(str(p))
        except ImportError as exc:
            raise InputError(f"{p}: reading this format needs the {exc.name or 'missing'} package") from exc
        except (Exception, SystemExit) as exc:  # ReadError, ValueError, KeyError, struct.error, ...
            first = first or exc
    # meshio's messages may quote the file: say what kind of failure it was, not what it read
    raise InputError(f"{p}: cannot read as a volume mesh ({failure_reason(first)})") from first


def read_tet_mesh(path):
    """Read the tetrahedra of a volume mesh file.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.vtk``, ``.vtu``, ``.msh``, ``.inp``, ``.mesh`` or ``.xdmf`` file.

    Returns
    -------
    points : (V, 3) float64
    tets : (T, 4) int64
        Positively oriented (see :func:`~porecad.volmesh.tetmesh.check_tet_mesh`).

    Raises
    ------
    InputError
        Missing, unreadable or unsupported file; no tetrahedra (``"BODY.vtu
        holds no tetrahedra (cell types: hexahedron)"``); an invalid tet mesh.
        Messages are one line.
    """
    p = Path(os.fspath(path))
    suffix = volume_mesh_suffix(p)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    if p.is_dir():
        raise InputError(f"{p}: is a directory, not a volume mesh file")
    mesh = read_meshio(p, suffix)
    blocks = []
    types = []
    for block in mesh.cells:
        types.append(block.type)
        data = np.asarray(block.data)
        if block.type == "tetra":
            blocks.append(data)
        elif block.type == "tetra10":
            blocks.append(data[:, :4])
    if not blocks or sum(len(b) for b in blocks) == 0:
        kinds = ", ".join(sorted(set(types))) or "none"
        raise InputError(f"{p} holds no tetrahedra (cell types: {kinds})")
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise InputError(f"{p}: points have shape {points.shape}, expected (V, 3)")
    if points.shape[1] == 2:
        raise InputError(f"{p}: points are two-dimensional; tetrahedra need 3D points")
    tets = np.concatenate(blocks).astype(np.int64)
    try:
        return check_tet_mesh(points, tets)
    except InputError as exc:
        raise InputError(f"{p}: {exc}") from exc


def write_tet_mesh(path, points, tets, force: bool = False) -> Path:
    """Write a tet mesh to a volume mesh file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; the format comes from the suffix (``.vtk`` legacy VTK,
        ``.vtu`` VTK XML, ``.msh`` Gmsh 4.1, ``.inp`` Abaqus, ``.mesh``
        Medit, ``.xdmf`` XDMF 3 with inline XML data).
    points : (V, 3) float array
    tets : (T, 4) int array
        Checked with :func:`~porecad.volmesh.tetmesh.check_tet_mesh` first
        (an all-negative mesh is written flipped).
    force : bool
        Replace an existing file.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        Unsupported suffix or invalid mesh.
    OutputError
        The file exists (without ``force``) or cannot be written.
    """
    import meshio

    p = Path(os.fspath(path))
    suffix = volume_mesh_suffix(p)
    pts, tt = check_tet_mesh(points, tets)
    check_output_path(p, force=force)
    mesh = meshio.Mesh(pts, [("tetra", tt)])
    kwargs = {"data_format": "XML"} if suffix == ".xdmf" else {}
    return write_meshio_atomic(p, mesh, _WRITE_FORMAT[suffix], **kwargs)


def write_meshio_atomic(path, mesh, file_format: str, **kwargs) -> Path:
    """Write a ``meshio.Mesh`` through a temporary file renamed into place; nothing partial is left.

    The caller has checked the path (:func:`porecad.io.atomic.check_output_path`).
    Every failure is an :class:`OutputError` in one line.
    """
    import meshio

    from ..io.atomic import atomic_path
    p = Path(os.fspath(path))
    try:
        with atomic_path(p, force=True, suffix=p.suffix) as tmp:  # the caller checked the path
            meshio.write(tmp, mesh, file_format=file_format, **kwargs)
    except BaseException as exc:
        if isinstance(exc, OutputError):
            raise
        if isinstance(exc, ImportError):
            raise OutputError(f"{p}: writing this format needs the {exc.name or 'missing'} package") from exc
        if isinstance(exc, OSError):
            raise OutputError(f"{p}: cannot write: {one_line(exc.strerror or exc)}") from exc
        if isinstance(exc, Exception):
            raise OutputError(f"{p}: cannot write: {one_line(exc) or type(exc).__name__}") from exc
        raise
    return p


def read_volume_mesh(path):
    """The tets or hexes of a volume-mesh file: ``(points, cells, "tet" | "hex")`` (one-line errors)."""
    p = Path(os.fspath(path))
    suffix = volume_mesh_suffix(p)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    if p.is_dir():
        raise InputError(f"{p}: is a directory, not a volume mesh file")
    types = {b.type for b in read_meshio(p, suffix).cells if len(b.data)}
    if types & {"tetra", "tetra10"}:
        pts, tets = read_tet_mesh(p)
        return pts, tets, "tet"
    if types & {"hexahedron", "hexahedron20", "hexahedron27"}:
        pts, hexes = read_hex_mesh(p)
        return pts, hexes, "hex"
    raise InputError(f"{p} holds no tetrahedra or hexahedra (cell types: {', '.join(sorted(types)) or 'none'}); "
                     "the mesh is empty")


def read_hex_mesh(path):
    """Read the hexahedra of a volume mesh file (``.vtk .vtu .msh .inp .mesh .xdmf``, meshio).

    ``hexahedron`` blocks (and the corners of ``hexahedron20/27``) are used;
    the result goes through :func:`check_hex_mesh`. One-line errors.
    """
    from porecad.volmesh.hexshapes import check_hex_mesh
    p = Path(os.fspath(path))
    suffix = volume_mesh_suffix(p)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    mesh = read_meshio(p, suffix)
    blocks = [np.asarray(b.data)[:, :8] for b in mesh.cells if b.type in ("hexahedron", "hexahedron20",
                                                                          "hexahedron27")]
    if not blocks or sum(len(b) for b in blocks) == 0:
        kinds = ", ".join(sorted({b.type for b in mesh.cells})) or "none"
        raise InputError(f"{p} holds no hexahedra (cell types: {kinds})")
    try:
        return check_hex_mesh(np.asarray(mesh.points, dtype=np.float64), np.concatenate(blocks).astype(np.int64))
    except InputError as exc:
        raise InputError(f"{p}: {exc}") from exc
