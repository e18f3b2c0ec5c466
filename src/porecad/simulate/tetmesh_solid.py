"""Tetrahedral volume meshes of closed porecad solids (linear C3D4 and quadratic C3D10), periodic cells.

Pipeline: the closed surface is checked (closed, manifold, oriented, no
self-intersections), remeshed to the target edge length without slivers
(:mod:`porecad.simulate.surface_prep`), tetrahedralised by TetGen with the
surface preserved (constrained Delaunay with quality refinement: radius–edge
ratio ≤ 1.3, dihedral target 15°, volume bound from the element size; Si,
"TetGen, a Delaunay-based quality tetrahedral mesh generator", *ACM Trans.
Math. Softw.* 41 (2015) 11), and its remaining slivers are repaired
(:mod:`porecad.simulate.sliver_repair`). Quadratic tets get straight-sided
mid-edge nodes (node order of VTK/meshio ``tetra10`` = Abaqus C3D10).

Why TetGen: it preserves the given surface exactly (``-Y``), which is what
makes a periodic cell mesh possible (opposite faces stay identical), it is
fast, and it is a maintained wheel (``tetgen`` on PyPI). Its licence is the
**AGPL-3.0** (the Python wrapper is MIT), so it lives in porecad's optional
``simulate`` extra and porecad itself stays MIT; TetGen runs in a separate
process so that a crash inside it becomes a one-line error, never a dead
program. fTetWild (MPL-2.0) was considered: it does not preserve surfaces
(no periodic meshes) and its Python wrapper needs VTK/pyvista; gmsh is GPL.

Periodic cells: the surface comes from the cell's field with identical caps
on opposite faces; vertices on the box faces never move, so the nodes on
opposite faces match (checked by
:func:`porecad.simulate.mesh_quality.periodic_face_mismatch`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from porecad.errors import InputError, MeshError, ResourceError
from porecad.simulate.mesh_quality import periodic_face_mismatch
from porecad.simulate.sliver_repair import repair_slivers
from porecad.simulate.surface_coarsen import coarsen_surface, coarsening_target
from porecad.simulate.surface_prep import (
    box_face_vertices,
    periodic_cell_surface,
    remesh_surface,
    require_closed_surface,
)
from porecad.volmesh.tetmesh import tet_quality

__all__ = ["tetrahedralise_surface", "quadratic_tets", "volume_mesh", "periodic_volume_mesh",
           "write_volume_mesh", "VOLUME_MESH_FORMATS", "MAX_TETS"]

#: Suffix → meshio format of the volume meshes written.
VOLUME_MESH_FORMATS = {".msh": "gmsh", ".vtu": "vtu", ".inp": "abaqus", ".mesh": "medit", ".vtk": "vtk"}
#: Largest mesh built (estimated from the volume and the element size before meshing).
MAX_TETS = 8_000_000
#: The default element size (no `size` given) keeps a volume mesh near this many tets: seconds, not minutes.
DEFAULT_TETS = 50_000
#: Largest remeshed surface (triangles, estimated from the area and the element size before meshing).
MAX_SURFACE_TRIANGLES = 2_000_000
#: Surfaces with more triangles than this, and more than twice the count of the element size, are
#: first coarsened by quadric decimation (:mod:`porecad.simulate.surface_coarsen`) instead of remeshed.
COARSEN_MIN_TRIANGLES = 200_000
#: A second, more thorough sliver repair runs when the first leaves a dihedral angle below this (degrees).
ESCALATE_BELOW_DEG = 7.0
#: Largest relative difference between the volume of the tet mesh and that of the input surface.
VOLUME_TOLERANCE = 0.005


#: The child process that runs TetGen: reads the surface from an .npz, writes the mesh to another.
_TETGEN_CHILD = """
import sys
import numpy as np
import tetgen
d = np.load(sys.argv[1], allow_pickle=False)
tg = tetgen.TetGen(np.ascontiguousarray(d["v"], dtype=np.float64), np.ascontiguousarray(d["f"], dtype=np.int32))
try:
    nodes, elem, _, _ = tg.tetrahedralize(switches=str(d["switches"]))
except RuntimeError as exc:
    sys.stderr.write(" ".join(str(exc).split()))
    sys.exit(3)
np.savez(sys.argv[2], nodes=np.asarray(nodes, dtype=np.float64), elem=np.asarray(elem, dtype=np.int64))
"""


def tetrahedralise_surface(vertices, faces, size: float | None = None, preserve_surface: bool = True,
                           timeout: float = 900.0):
    """Quality tet mesh of a closed surface by TetGen (in a child process).

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        Closed, outward oriented, free of self-intersections.
    size : float, optional
        Target edge length: tets are refined to at most the volume of the
        regular tet of that edge (``√2 h³ / 12``).
    preserve_surface : bool
        Keep the surface triangulation exactly (TetGen ``-Y``): needed for periodic cells.
    timeout : float
        Seconds before the mesher is stopped.

    Returns
    -------
    points : (N, 3) float64
        The surface vertices come first, in their input order.
    tets : (T, 4) int64
        Positively oriented.

    Raises
    ------
    ImportError
        TetGen is not installed (``pip install "porecad[simulate]"``).
    MeshError
        TetGen failed or crashed.
    """
    import subprocess
    import sys
    import tempfile

    try:
        import tetgen  # noqa: F401
    except ImportError as exc:
        raise InputError('volume meshing needs TetGen: pip install "porecad[simulate]" '
                         "(TetGen is AGPL-3.0)") from exc
    switches = "pq1.3/15"
    if size is not None:
        switches += f"a{np.sqrt(2.0) * float(size) ** 3 / 12.0:.6g}"
    if preserve_surface:
        switches += "Y"
    switches += "Q"
    with tempfile.TemporaryDirectory(prefix="porecad-tetgen-") as tmp:
        src, dst = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(src, v=np.asarray(vertices, dtype=np.float64), f=np.asarray(faces, dtype=np.int64),
                 switches=np.array(switches))
        try:
            run = subprocess.run([sys.executable, "-c", _TETGEN_CHILD, src, dst], capture_output=True,
                                 text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise ResourceError(f"TetGen did not finish within {timeout:.0f} s; use a larger element size") from None
        if run.returncode == 3:
            raise MeshError(f"TetGen failed: {run.stderr.strip()[:300]}")
        if run.returncode != 0 or not os.path.exists(dst):
            raise MeshError(f"TetGen crashed on this surface (exit {run.returncode}; it may be nearly "
                            "self-intersecting); try a different element size")
        with np.load(dst, allow_pickle=False) as d:
            nodes, elem = d["nodes"], d["elem"]
    if len(elem) == 0:
        raise MeshError("TetGen produced no tetrahedra")
    # orientation: porecad's tets are positive
    q = nodes[elem]
    det = np.einsum("ij,ij->i", q[:, 1] - q[:, 0], np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]))
    if np.median(det) < 0:
        elem = elem[:, [0, 2, 1, 3]]
    return nodes, elem


def quadratic_tets(points, tets):
    """Add straight-sided mid-edge nodes: 10-node tets (meshio/VTK ``tetra10``, Abaqus C3D10 order).

    Node order per tet: the four corners, then the midpoints of edges
    01, 12, 02, 03, 13, 23. Shared edges share their node, so the mesh stays
    conforming (and periodic if the linear mesh was).

    Returns
    -------
    points : (N + E, 3) float64
    tets10 : (T, 10) int64
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64)
    pairs = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
    e = np.sort(t[:, pairs].reshape(-1, 2), axis=1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    mid = 0.5 * (p[uniq[:, 0]] + p[uniq[:, 1]])
    t10 = np.concatenate([t, len(p) + inv.reshape(-1, 6)], axis=1)
    return np.concatenate([p, mid]), t10


def _estimate_tets(volume: float, size: float) -> float:
    return 1.5 * 12.0 / np.sqrt(2.0) * (volume / size) / size / size  # divided in turn: no overflow of size³


def _checked_size(size, extent: float) -> float:
    """``size`` as a float; InputError unless it lies between a millionth of ``extent`` (mm) and ``extent``."""
    size = float(size)
    if not (np.isfinite(size) and extent * 1e-6 <= size <= extent):
        raise InputError(f"element size must lie between a millionth of the solid's extent and the extent "
                         f"({extent * 1e-6:.3g} to {extent:.3g} mm), got {size:g}")
    return size


def _budget_size(volume: float, area: float) -> float:
    """The element size at which a solid has about ``DEFAULT_TETS`` tets and ``DEFAULT_TETS / 2`` surface triangles."""
    by_volume = (1.5 * 12.0 * volume / (np.sqrt(2.0) * DEFAULT_TETS)) ** (1.0 / 3.0)
    return max(by_volume, float(np.sqrt(2.3 * area / (DEFAULT_TETS / 2))))


def _finish(points, tets, frozen, order, surface_volume, info, periodic_box=None):
    p, t, rep = repair_slivers(points, tets, frozen=frozen)
    if rep["min_dihedral_deg"] < ESCALATE_BELOW_DEG:
        # the few tets left (slivers across thin walls, all four vertices on the surface) get more
        # candidate positions per vertex and more passes; only those below 10 deg are worked on
        p, t, rep2 = repair_slivers(p, t, frozen=frozen, target_deg=ESCALATE_BELOW_DEG + 3.0, trials=30,
                                    rounds=30, seed=101)
        rep = {"min_dihedral_before_deg": rep["min_dihedral_before_deg"],
               "min_dihedral_deg": rep2["min_dihedral_deg"], "moved": rep["moved"] + rep2["moved"],
               "peeled": rep["peeled"] + rep2["peeled"], "escalated": True}
    quality = tet_quality(p, t)
    if quality["inverted"]:
        raise MeshError(f"the volume mesh has {quality['inverted']} inverted or flat tets")
    verr = quality["volume"] / surface_volume - 1
    if abs(verr) > VOLUME_TOLERANCE:
        raise MeshError(f"the volume mesh's volume differs from the surface's by {100 * verr:.2f} % "
                        f"(tolerance {100 * VOLUME_TOLERANCE:.1f} %); use a smaller element size")
    out = {"points": p, "tets": t, "order": int(order), "quality": quality, "surface": info,
           "sliver_repair": rep, "surface_volume": float(surface_volume), "volume_error": float(verr)}
    if periodic_box is not None:
        out["periodic"] = periodic_face_mismatch(p, *periodic_box)
    if order == 2:
        p2, t10 = quadratic_tets(p, t)
        out.update({"points": p2, "cells": t10, "cell_type": "tetra10"})
    else:
        out.update({"cells": t, "cell_type": "tetra"})
    return out


def _check_order(order):
    if order not in (1, 2):
        raise InputError(f"element order must be 1 (C3D4) or 2 (C3D10), got {order!r}")
    return int(order)


def volume_mesh(vertices, faces, size: float | None = None, order: int = 1, remesh: bool = True,
                progress=None) -> dict:
    """Tetrahedral volume mesh of a closed solid.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        A closed, manifold, outward-oriented surface without self-intersections
        (an open mesh is refused with a one-line :class:`MeshError`).
    size : float, optional
        Target element edge length (mm); default the mean surface edge length, or larger where
        that would give more than about ``DEFAULT_TETS`` tets.
    order : {1, 2}
        Linear (C3D4) or quadratic (C3D10, straight-sided) tets.
    remesh : bool
        Remesh the surface first (removes marching-cubes slivers). A large
        surface much finer than ``size`` (over ``COARSEN_MIN_TRIANGLES``
        triangles and twice the count of an isotropic triangulation at
        ``0.7 size``) is coarsened by quadric decimation instead
        (:func:`~porecad.simulate.surface_coarsen.coarsen_surface`); TetGen and
        the sliver repair then deal with its poorly shaped triangles.
    progress : callable, optional
        ``progress(stage, done, total)`` at each stage.

    Returns
    -------
    dict
        ``points``, ``cells`` (T × 4 or T × 10), ``cell_type`` (``tetra`` or
        ``tetra10``), ``tets`` (the linear corner tets), ``quality``
        (:func:`~porecad.volmesh.tetmesh.tet_quality`),
        ``surface`` (remeshing report), ``surface_volume`` (of the input),
        ``volume_error`` (relative; at most 0.5 %), ``sliver_repair``.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> m = volume_mesh(s.vertices, s.faces, size=0.2)
    >>> bool(m["quality"]["dihedral_deg"]["min"] > 5)
    True
    """
    order = _check_order(order)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) < 4:
        raise InputError("a solid needs (V, 3) vertices and at least four (F, 3) faces")
    vol, area, size, h = _element_size(v, f, size)
    v, f, info = _prepared_surface(v, f, size, h, area, remesh, progress)
    say = progress or (lambda stage, done, total: None)
    say("tetgen", 0, 1)
    nodes, tets = tetrahedralise_surface(v, f, size=size, preserve_surface=True)
    say("tetgen", 1, 1)
    return _finish(nodes, tets, None, order, vol, info)


def _element_size(v, f, size):
    """Element size of :func:`volume_mesh`, checked against the mesh limits.

    Takes the surface and the requested ``size`` (or ``None``); returns
    ``(vol, area, size, h)``: the surface's signed volume and area, the size
    passed on to the mesher (``None`` only for a default that fits within
    ``DEFAULT_TETS``, else a float) and the edge length ``h`` actually aimed
    at (``0.7`` times the mean edge length when ``size`` is ``None``).
    Raises :class:`InputError` for a non-positive size and
    :class:`ResourceError` when the surface triangles or tets would exceed
    ``MAX_SURFACE_TRIANGLES`` or ``MAX_TETS``.
    """
    from porecad.mesh.validate import signed_volume, surface_area

    vol = float(signed_volume(v, f))
    area = float(surface_area(v, f))
    mean_edge = float(np.linalg.norm(v[f[:, [1, 2, 0]]] - v[f], axis=2).mean())
    extent = float(np.max(np.ptp(v, axis=0)))
    if not (area > 0 and mean_edge > 0):
        raise MeshError("the surface encloses no volume (its triangles have no area)")
    if size is not None:
        size = _checked_size(size, extent)
    if size is None and (budget := _budget_size(abs(vol), area)) > 0.7 * mean_edge:
        size = budget  # a fine surface: the default elements stay within DEFAULT_TETS
    h = 0.7 * mean_edge if size is None else size
    tris = 2.3 * (area / h) / h  # an isotropic triangulation has about 2.3 triangles per h² of area
    n_tets = _estimate_tets(abs(vol), h)
    if tris > MAX_SURFACE_TRIANGLES or n_tets > MAX_TETS:
        raise ResourceError(f"a volume mesh with elements of {h:.3g} mm would have about {tris:.3g} surface "
                            f"triangles and {n_tets:.3g} tets (limits {MAX_SURFACE_TRIANGLES:,} and {MAX_TETS:,}): "
                            "give a larger element size")
    return vol, area, size, h


def _prepared_surface(v, f, size, h, area, remesh, progress):
    """The surface handed to TetGen by :func:`volume_mesh`.

    Takes the surface, the sizes from :func:`_element_size`, its area, the
    ``remesh`` flag and the progress callback; returns ``(v, f, info)``: a
    large surface much finer than ``size`` coarsened, else (with
    ``remesh``) remeshed, else the input checked closed; ``info`` is the
    coarsening or remeshing report (``remeshed`` False when not remeshed).
    """
    say = progress or (lambda stage, done, total: None)
    if remesh and size is not None and len(f) > COARSEN_MIN_TRIANGLES and 2 * coarsening_target(area, h) < len(f):
        say("check surface", 0, 1)
        require_closed_surface(v, f)
        say("check surface", 1, 1)
        v, f, info = coarsen_surface(v, f, size=h, volume_tolerance=VOLUME_TOLERANCE, progress=progress)
        info["remeshed"] = False
    elif remesh:
        say("remesh surface", 0, 1)
        v, f, info = remesh_surface(v, f, size=size)
        say("remesh surface", 1, 1)
    else:
        require_closed_surface(v, f)
        info = {"remeshed": False, "triangles": int(len(f))}
    return v, f, info


def periodic_volume_mesh(field, lo, hi, size: float, order: int = 1) -> dict:
    """Periodic tet mesh of a cell's solid ``{field ≤ 0}``: nodes on opposite faces match.

    Parameters
    ----------
    field : porecad Field
        Periodic over the box (e.g. a TPMS structure on whole cells).
    lo, hi : (3,) float
        The cell box (mm).
    size : float
        Target edge length (mm); the field is sampled at this spacing.
    order : {1, 2}

    Returns
    -------
    dict
        As :func:`volume_mesh`, plus ``periodic``
        (:func:`~porecad.simulate.mesh_quality.periodic_face_mismatch`) and
        ``box``. ``surface_volume`` is that of the periodic marching-cubes
        surface.
    """
    from porecad.mesh.validate import signed_volume

    order = _check_order(order)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    ext = hi - lo
    size = _checked_size(size, float(ext.max()))
    # the surface is sampled finer than the elements (at most 96 samples per edge), so that the
    # remeshed surface follows the field closely; the tets then take the element size
    samples = int(min(96, max(16, round(2.0 * float(ext.min()) / size))))
    if _estimate_tets(float(np.prod(ext)), size) > MAX_TETS:
        raise ResourceError(f"element size {size:g} mm would give too many tets for this cell: use a larger size")
    v, f = periodic_cell_surface(field, lo, hi, samples)
    vol = float(signed_volume(v, f))
    fixed = box_face_vertices(v, lo, hi)
    v2, f2, info = remesh_surface(v, f, size=size, fixed=fixed)
    nodes, tets = tetrahedralise_surface(v2, f2, size=size, preserve_surface=True)
    frozen = box_face_vertices(nodes, lo, hi)
    out = _finish(nodes, tets, frozen, order, vol, info, periodic_box=(lo, hi))
    out["box"] = [lo.tolist(), hi.tolist()]
    if not out["periodic"]["matched"]:
        raise MeshError("the periodic mesh's opposite faces do not match "
                        f"({ {a: out['periodic'][a]['max_distance'] for a in 'xyz'} })")
    return out


def write_volume_mesh(path, points, cells, cell_type: str = "tetra", force: bool = False) -> Path:
    """Write a tet mesh with meshio, atomically (``.msh`` Gmsh 4.1, ``.vtu``, ``.inp`` Abaqus, ``.mesh`` Medit, ``.vtk``).

    Parameters
    ----------
    path : str or os.PathLike
    points : (N, 3) float array
    cells : (T, 4) or (T, 10) int array
    cell_type : {'tetra', 'tetra10'}
        Medit ``.mesh`` holds linear tets only.
    force : bool
        Replace an existing file.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    InputError
        Unknown suffix, or quadratic tets to Medit.
    OutputError
        Exists without ``force``, or cannot be written (nothing partial is left).
    """
    import meshio

    from porecad.io.atomic import check_output_path
    from porecad.volmesh.tetio import write_meshio_atomic

    p = Path(os.fspath(path))
    suffix = p.suffix.lower()
    if suffix not in VOLUME_MESH_FORMATS:
        raise InputError(f"{p}: unsupported volume mesh format {p.suffix or '(none)'!r} "
                         f"(use {', '.join(VOLUME_MESH_FORMATS)})")
    if cell_type not in ("tetra", "tetra10"):
        raise InputError(f"cell type must be tetra or tetra10, got {cell_type!r}")
    if cell_type == "tetra10" and suffix == ".mesh":
        raise InputError(f"{p}: Medit .mesh files hold linear tets only; write quadratic tets as .msh, .vtu or .inp")
    check_output_path(p, force=force)
    mesh = meshio.Mesh(np.asarray(points, dtype=np.float64), [(cell_type, np.asarray(cells, dtype=np.int64))])
    return write_meshio_atomic(p, mesh, VOLUME_MESH_FORMATS[suffix])
