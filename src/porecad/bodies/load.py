"""Loading a body mesh: check it, repair what can be repaired, refuse the rest.

Repairs use trimesh (a well-kept library for exactly this): merging duplicate
vertices, dropping degenerate and duplicate faces, making the orientation
consistent (``trimesh.repair.fix_winding``) and outward
(``trimesh.repair.fix_inversion``), and closing small holes
(``trimesh.repair.fill_holes``). Every change is listed in the report. A
mesh that is still open or non-manifold afterwards is refused with a one-line
reason. Self-intersections are reported, not refused: inside/outside is the
winding number, so an overlapping closed mesh is the union of its parts.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from ..errors import InputError, ResourceError
from ..io import read_mesh
from ..mesh.validate import check_solid, self_intersections
from ..resources import memory_budget

#: bytes of memory per body triangle while loading, repairing and binning (measured, rounded up)
BYTES_PER_TRIANGLE = 600


def _triangle_count_hint(p: Path) -> int | None:
    """Triangle count of a binary STL from its header (None for other files)."""
    if p.suffix.lower() != ".stl":
        return None
    try:
        with open(p, "rb") as fh:
            head = fh.read(84)
    except OSError:
        return None
    if len(head) < 84 or head[:5].lower() == b"solid":
        return None
    n = struct.unpack("<I", head[80:84])[0]
    return n if 84 + 50 * n == os.path.getsize(p) else None


def load_body(path, repair: bool = True, check_intersections: bool = True,
              memory_limit: int | None = None, label=None, threshold=None, keep_all: bool = False,
              progress=None, scale: float = 1.0):
    """Read a closed body mesh, repairing it where possible; or make one from an image.

    Parameters
    ----------
    path : str or os.PathLike
        STL, OBJ, PLY, OFF or 3MF file; or an image (NIfTI, MHA/MHD,
        NRRD, a DICOM series directory or file), see :mod:`porecad.bodies.image`.
    label, threshold, keep_all :
        For images: the body's label value, or its intensity threshold (and
        whether to keep every connected component).
    repair : bool
        Try the repairs listed in the module docstring; otherwise refuse any defect.
    check_intersections : bool
        Count self-intersecting face pairs for the report.
    memory_limit : int, optional
        Bytes available (default: the machine's available memory).
    progress : callable, optional
        ``progress(done, total)`` while an image body's surface is extracted.
    scale : float
        Millimetres per unit of a mesh file (:func:`porecad.bodies.units.unit_scale`).

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    report : dict
        ``triangles_in``, ``triangles``, ``repairs`` (list of strings),
        ``self_intersections``, ``volume`` (mm³), ``bounds``.

    Raises
    ------
    InputError
        Unreadable, empty or unrepairable meshes, with a one-line reason.
    ResourceError
        A mesh too large for the machine's memory.
    """
    from .image import is_image_path

    p = Path(os.fspath(path))
    if is_image_path(p):
        return _image_body(p, label, threshold, keep_all, progress)
    if label is not None or threshold is not None:
        raise InputError(f"{p}: a label or intensity threshold applies to image bodies only")
    _check_fits(p, memory_limit)
    v, f = _read_scaled(p, scale)
    report = {"triangles_in": int(len(f)), "repairs": []}
    v, f, chk = _valid_solid(p, v, f, repair, report["repairs"])
    report["self_intersections"] = (int(self_intersections(v, f, max_report=0)[1])
                                    if check_intersections else None)
    if report["self_intersections"]:
        report["repairs"].append(f"{report['self_intersections']} self-intersecting face pairs: inside "
                                 "is taken by winding number (the union of the overlapping parts)")
    report.update(triangles=int(len(f)), volume=float(chk["volume"]), bounds=chk["bounds"])
    return v, np.asarray(f, dtype=np.int64), report


def _image_body(p: Path, label, threshold, keep_all: bool, progress):
    """Takes an image path and :func:`load_body`'s image keys; returns its ``(vertices, faces, report)``.

    The surface comes from :func:`porecad.bodies.image.image_body`; one that is
    not a closed, manifold, outward solid with volume raises InputError.
    """
    from .image import image_body

    v, f, info = image_body(p, label=label, threshold=threshold, keep_all=keep_all, progress=progress)
    chk = check_solid(v, f, check_self_intersections=False)
    if not (chk["closed"] and chk["manifold"] and chk["outward"]) or chk["volume"] <= 0:
        raise InputError(f"{p}: the image body's surface is not a valid solid ({_defect(chk)})")
    report = {"triangles_in": int(len(f)), "repairs": [], "self_intersections": 0,
              "triangles": int(len(f)), "volume": float(chk["volume"]), "bounds": chk["bounds"],
              "image": info}
    return v, f, report


def _check_fits(p: Path, memory_limit: int | None) -> None:
    """Takes a mesh path and the memory limit; returns nothing, raises ResourceError when the body cannot fit.

    The triangle count is a binary STL's header or, for other files, at most
    one per 50 bytes; each costs :data:`BYTES_PER_TRIANGLE`.
    """
    limit = memory_budget(memory_limit)
    hint = _triangle_count_hint(p) if p.is_file() else None
    if hint is None and p.is_file():
        hint = os.path.getsize(p) // 50  # at least 50 bytes per triangle in any format
    if hint is not None and hint * BYTES_PER_TRIANGLE > 0.8 * limit:
        raise ResourceError(f"{p}: about {hint:,} triangles need about "
                            f"{hint * BYTES_PER_TRIANGLE / 2**30:.1f} GiB; "
                            f"{limit / 2**30:.1f} GiB available (decimate the body first)")


def _read_scaled(p: Path, scale: float):
    """Takes a mesh path and millimetres per unit; returns ``(vertices, faces)`` in mm (InputError if no triangles)."""
    v, f = read_mesh(p)
    if scale != 1.0:  # held at float32 as the file in mm would store it (no ulp of the scaling moves the grid)
        v = (np.asarray(v, np.float64) * float(scale)).astype(np.float32).astype(np.float64)
    if len(f) == 0:
        raise InputError(f"{p}: the body mesh has no triangles")
    return v, f


def _valid_solid(p: Path, v, f, repair: bool, log: list):
    """Takes a mesh, whether to repair it and the repair log; returns ``(vertices, faces, check)`` of a valid solid.

    A mesh that is not closed, manifold, oriented and outward is repaired
    (each change appended to ``log``) or, without ``repair`` or when repair
    fails, refused with InputError; so is one that encloses no volume.
    ``check`` is :func:`porecad.mesh.validate.check_solid` of the result.
    """
    chk = check_solid(v, f, check_self_intersections=False)
    ok = chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"]
    if not ok:
        if not repair:
            raise InputError(f"{p}: {_defect(chk)}")
        v, f = _repair(v, f, log)
        chk = check_solid(v, f, check_self_intersections=False)
        if not (chk["closed"] and chk["manifold"]):
            raise InputError(f"{p}: {_defect(chk)} after repair ({'; '.join(log) or 'nothing to do'})")
        if not chk["oriented"] or not chk["outward"]:
            raise InputError(f"{p}: {_defect(chk)} after repair")
    if chk["volume"] <= 0:
        raise InputError(f"{p}: the body encloses no volume")
    return v, f, chk


def _defect(chk: dict) -> str:
    if not chk["closed"]:
        return f"the body mesh is not closed ({chk['boundary_edges']} boundary edges)"
    if not chk["manifold"]:
        return (f"the body mesh is not manifold ({chk['nonmanifold_edges']} edges shared by more than two "
                f"faces, {chk['nonmanifold_vertices']} pinched vertices)")
    if not chk["oriented"]:
        return f"the body mesh is not consistently oriented ({chk['misoriented_edges']} edges)"
    if not chk["outward"]:
        return "the body mesh is inside out"
    return "the body mesh is invalid"


#: a hole larger than this share of the body's bounding-box diagonal (perimeter), or with more edges, is refused
MAX_HOLE_PERIMETER = 0.15
MAX_HOLE_EDGES = 64


def check_holes(m) -> str:
    """Count the holes (boundary loops) of a trimesh; refuse large ones; return the repair line."""
    edges = m.edges_sorted
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = uniq[counts == 1]
    if len(open_edges) == 0:
        return "no holes"
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    n = len(m.vertices)
    g = sp.coo_matrix((np.ones(len(open_edges)), (open_edges[:, 0], open_edges[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    loop = lab[open_edges[:, 0]]
    length = np.linalg.norm(m.vertices[open_edges[:, 0]] - m.vertices[open_edges[:, 1]], axis=1)
    ids, per_edges = np.unique(loop, return_counts=True)
    perimeter = np.bincount(np.searchsorted(ids, loop), weights=length)
    diag = float(np.linalg.norm(np.ptp(m.vertices, axis=0)))
    worst = int(np.argmax(perimeter))
    if perimeter[worst] > MAX_HOLE_PERIMETER * diag or per_edges[worst] > MAX_HOLE_EDGES:
        raise InputError(f"the body mesh has a hole too large to close ({per_edges[worst]} edges, perimeter "
                         f"{perimeter[worst]:.3g} mm, {100 * perimeter[worst] / diag:.0f} % of its size): "
                         "close it in a mesh editor")
    return (f"closed {len(ids)} hole{'s' if len(ids) > 1 else ''} (at most {int(per_edges.max())} edges, "
            f"perimeter {perimeter.max():.3g} mm)")


def _repair(v, f, log: list):
    """Repairs with trimesh; appends a line per change to ``log``."""
    import trimesh

    n_v, n_f = len(v), len(f)
    m = trimesh.Trimesh(vertices=v, faces=f, process=True, validate=False)
    m.update_faces(m.nondegenerate_faces())
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    if len(m.vertices) < n_v:
        log.append(f"merged {n_v - len(m.vertices)} duplicate vertices")
    if len(m.faces) < n_f:
        log.append(f"removed {n_f - len(m.faces)} degenerate or duplicate faces")
    before = np.asarray(m.faces).copy()
    trimesh.repair.fix_winding(m)
    flipped = int(np.count_nonzero(np.any(np.asarray(m.faces) != before, axis=1)))
    if flipped:
        log.append(f"re-oriented {flipped} faces consistently")
    if m.volume < 0:
        m.invert()
        log.append("inverted the mesh (it was inside out)")
    if not m.is_watertight:
        log.append(check_holes(m))
        n_before = len(m.faces)
        trimesh.repair.fill_holes(m)
        if len(m.faces) > n_before:
            log.append(f"filled holes with {len(m.faces) - n_before} faces")
        if m.volume < 0:
            m.invert()
            log.append("inverted the mesh (it was inside out)")
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
