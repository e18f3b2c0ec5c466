"""Surfaces ready for tetrahedral meshing: sliver-free remeshing, and periodic unit-cell surfaces.

Marching cubes makes sliver triangles wherever the surface passes close to a
sample (angles below 0.1° are common), and a boundary-preserving tet mesher
turns each one into a sliver tet. Two remedies are used here:

* any closed surface is remeshed isotropically (Botsch & Kobbelt, "A
  remeshing approach to multiresolution modeling", *Symp. Geometry
  Processing* 2004: split long edges, collapse short ones, flip to equalise
  valences, tangential smoothing, projection back onto the input), with
  sharp creases (dihedral angle above 45°) kept as feature lines, by
  gpytoolbox (MIT); the result is checked closed, manifold and free of
  self-intersections, and its volume against the input;
* a periodic unit cell is polygonised from its field with the samples nearer
  the level set than a tenth of a voxel (along the local gradient) pushed to
  that distance, which bounds the smallest marching-cubes angle, on a grid
  whose last sample planes are exact copies of the first; the six caps are
  then identical on opposite faces, and the remeshing keeps every vertex on
  the box faces fixed, so opposite faces still match exactly.
"""

from __future__ import annotations

import numpy as np

from porecad.errors import InputError, MeshError
from porecad.simulate.surface_slivers import remove_sliver_triangles

__all__ = ["remesh_surface", "crease_vertices", "periodic_cell_surface", "triangle_min_angles", "box_face_vertices",
           "require_closed_surface"]


def triangle_min_angles(vertices, faces) -> np.ndarray:
    """Smallest interior angle (degrees) of each triangle."""
    p = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    out = np.full(len(p), 180.0)
    for i in range(3):
        u = p[:, (i + 1) % 3] - p[:, i]
        w = p[:, (i + 2) % 3] - p[:, i]
        with np.errstate(invalid="ignore", divide="ignore"):
            c = (u * w).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        out = np.minimum(out, np.degrees(np.arccos(np.clip(np.nan_to_num(c, nan=1.0), -1, 1))))
    return out


def box_face_vertices(vertices, lo, hi, tol: float = 1e-9) -> np.ndarray:
    """Boolean mask of the vertices lying on a face of the box ``[lo, hi]`` (within ``tol`` × its size)."""
    v = np.asarray(vertices, dtype=np.float64)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    t = tol * float(np.max(hi - lo))
    return np.any((np.abs(v - lo) <= t) | (np.abs(v - hi) <= t), axis=1)


def require_closed_surface(vertices, faces, what="surface"):
    from porecad.mesh.validate import check_solid

    rep = check_solid(vertices, faces, check_self_intersections=True)
    if rep.get("boundary_edges", 0):
        raise MeshError(f"the {what} is open ({rep['boundary_edges']} boundary edges): a volume mesh needs a "
                        "closed solid")
    for key, text in (("nonmanifold_edges", "non-manifold edges"), ("nonmanifold_vertices", "non-manifold vertices"),
                      ("misoriented_edges", "inconsistently oriented edges"),
                      ("self_intersections", "self-intersecting face pairs")):
        if rep.get(key, 0):
            raise MeshError(f"the {what} has {rep[key]} {text}: a volume mesh needs a valid closed solid")
    if not rep.get("volume", 0) > 0:
        raise MeshError(f"the {what} encloses no positive volume (inside out or empty)")
    return rep


def crease_vertices(vertices, faces, angle: float = 45.0) -> np.ndarray:
    """Vertices on sharp creases: edges whose two faces' normals differ by more than ``angle`` degrees."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    e = np.sort(np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    face = np.repeat(np.arange(len(f)), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, face = e[order], face[order]
    same = np.all(e[1:] == e[:-1], axis=1)
    i = np.flatnonzero(same)
    cosang = np.einsum("ij,ij->i", n[face[i]], n[face[i + 1]])
    sharp = i[cosang < np.cos(np.radians(angle))]
    out = np.zeros(len(v), dtype=bool)
    out[e[sharp].ravel()] = True
    return out


def remesh_surface(vertices, faces, size: float | None = None, fixed=None, iterations: int = 10,
                   feature_angle: float = 45.0, volume_tolerance: float = 0.005, sliver_angle: float = 10.0):
    """Isotropic remeshing of a closed surface, checked before it is returned.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        Closed, manifold, outward oriented, free of self-intersections
        (checked; an open mesh is refused).
    size : float, optional
        Target edge length (mm); default 0.7 times the mean edge length of
        the input (finer, so that thin walls keep their thickness).
    fixed : (V,) bool array, optional
        Vertices that must not move (e.g. those on the faces of a periodic
        cell); default the vertices on sharp creases (:func:`crease_vertices`).
    iterations : int
        Remeshing iterations.
    feature_angle : float
        Vertices on edges whose faces' normals differ by more than this (degrees) are kept fixed.
    volume_tolerance : float
        Largest relative volume change accepted.
    sliver_angle : float
        Triangles left with an angle below this (degrees) are then removed by
        needle collapses and cap flips
        (:func:`porecad.simulate.surface_slivers.remove_sliver_triangles`; vertices in
        ``fixed`` stay put, crease vertices may move by a fraction of an edge); the result
        is kept only if it passes the same checks.

    Returns
    -------
    vertices, faces : arrays
    info : dict
        ``triangles_in``, ``triangles``, ``min_angle_in_deg``,
        ``min_angle_deg``, ``volume_change``, ``remeshed`` (False when the
        remeshed surface failed its checks and the input is kept),
        ``sliver_triangles`` (the collapse/flip report).

    References
    ----------
    M. Botsch, L. Kobbelt, "A remeshing approach to multiresolution modeling",
    Symposium on Geometry Processing 2004; gpytoolbox ``remesh_botsch``.
    If the remeshed surface self-intersects (thin walls), it is retried at 0.6 times the
    target, then the input is kept (``remeshed`` False).
    """
    from porecad.mesh.validate import signed_volume

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    rep = require_closed_surface(v, f)
    vol = float(rep["volume"])
    h = _target_edge(v, f, size)
    hard_fixed = None if fixed is None else np.asarray(fixed, dtype=bool)
    if fixed is None:
        fixed = crease_vertices(v, f, feature_angle)
    fixed = np.asarray(fixed, dtype=bool)
    info = {"triangles_in": int(len(f)), "min_angle_in_deg": float(triangle_min_angles(v, f).min()),
            "fixed_vertices": int(fixed.sum())}
    v2, f2, ok, h = _checked_remesh(v, f, h, fixed, iterations, vol, volume_tolerance)
    # marching-cubes needles and caps the remeshing left (or all of them, if it failed): collapse and flip;
    # the vertices that must stay are those of the remeshed surface at a fixed input vertex (the remesher
    # renumbers the vertices, so the input's mask does not index its output)
    fixed_now = None if hard_fixed is None else _same_positions(v2, v[hard_fixed])
    v2, f2, sl = _checked_sliver_removal(v2, f2, sliver_angle, fixed_now, vol, volume_tolerance)
    info["sliver_triangles"] = sl
    info.update({"triangles": int(len(f2)), "min_angle_deg": float(triangle_min_angles(v2, f2).min()),
                 "volume_change": float(signed_volume(v2, f2) / vol - 1), "remeshed": bool(ok),
                 "target_edge": h})
    return v2, f2, info


def _target_edge(v, f, size):
    """Target edge length of :func:`remesh_surface`.

    Takes the surface and the requested ``size`` (``None``: 0.7 times the
    mean edge length); returns it as a float. Raises :class:`InputError`
    when it is not positive or below 0.05 times the mean edge length.
    """
    e = v[f[:, [1, 2, 0]]] - v[f]
    mean_edge = float(np.linalg.norm(e, axis=2).mean())
    h = 0.7 * mean_edge if size is None else float(size)
    if not np.isfinite(h) or h <= 0:
        raise InputError(f"element size must be positive, got {size}")
    if h < 0.05 * mean_edge:
        raise InputError(f"element size {h:g} mm is far below the surface's edge length {mean_edge:.3g} mm; "
                         "refine the surface itself (a finer resolution)")
    return h


def _checked_remesh(v, f, h, fixed, iterations, vol, volume_tolerance):
    """Botsch–Kobbelt remeshing (gpytoolbox), kept only if the result passes its checks.

    Takes the surface, the target edge ``h``, the fixed-vertex mask, the
    iterations, the input volume and the volume tolerance; tries ``h`` and
    then ``0.6 h`` (thin walls may make the first try self-intersect).
    Returns ``(v2, f2, ok, h)``: the first remeshed surface that is closed,
    manifold, oriented, free of self-intersections and within the volume
    tolerance, ``ok`` True and the target used; else the input, ``ok``
    False and ``h`` unchanged.
    """
    import gpytoolbox

    from porecad.mesh.validate import check_solid

    ok = False
    v2, f2 = v, f
    for shrink in (1.0, 0.6):  # a finer target when thin walls made the first try self-intersect
        try:
            cand_v, cand_f = gpytoolbox.remesh_botsch(v, f.astype(np.int32), i=int(iterations), h=h * shrink,
                                                      feature=np.flatnonzero(fixed).astype(np.int64))
            cand_v = np.asarray(cand_v, dtype=np.float64)
            cand_f = np.asarray(cand_f, dtype=np.int64)
            chk = check_solid(cand_v, cand_f, check_self_intersections=True)
            ok = bool(chk.get("closed") and chk.get("manifold") and chk.get("oriented", True)
                      and not chk.get("self_intersections") and chk.get("volume", 0) > 0
                      and abs(chk["volume"] / vol - 1) <= volume_tolerance)
        except Exception:  # noqa: BLE001 - a failed remesh falls back to the checked input
            ok = False
        if ok:
            v2, f2 = cand_v, cand_f
            h = h * shrink
            break
    return v2, f2, ok, h


def _checked_sliver_removal(v2, f2, sliver_angle, fixed_now, vol, volume_tolerance):
    """Remove sliver triangles, kept only if the result passes its checks.

    Takes the surface, the sliver angle, the mask of vertices that must not
    move (or ``None``), the input volume and the volume tolerance; returns
    ``(v, f, sl)``: the cleaned surface if it is closed, manifold, free of
    self-intersections and within the volume tolerance, else the given one
    with ``sl["kept"]`` False; ``sl`` is the report of
    :func:`porecad.simulate.surface_slivers.remove_sliver_triangles`.
    """
    from porecad.mesh.validate import check_solid

    v3, f3, sl = remove_sliver_triangles(v2, f2, min_angle=sliver_angle, fixed=fixed_now)
    if sl["collapsed"] or sl["flipped"]:
        chk = check_solid(v3, f3, check_self_intersections=True)
        if (chk.get("closed") and chk.get("manifold") and not chk.get("self_intersections")
                and abs(chk.get("volume", 0) / vol - 1) <= volume_tolerance):
            v2, f2 = v3, f3
        else:
            sl["kept"] = False
    return v2, f2, sl


def _same_positions(vertices, points) -> np.ndarray:
    """Boolean mask of the ``vertices`` that coincide exactly with one of ``points``."""
    mask = np.zeros(len(vertices), dtype=bool)
    if len(points) and len(vertices):
        from scipy.spatial import cKDTree
        d, _ = cKDTree(points).query(vertices, distance_upper_bound=1e-12)
        mask = d == 0.0
    return mask


def periodic_cell_surface(field, lo, hi, samples: int, snap: float = 0.1):
    """Closed surface of a periodic cell's solid ``{field ≤ 0}`` with identical opposite caps.

    Parameters
    ----------
    field : porecad Field
        Periodic with the box (e.g. a TPMS structure over whole cells).
    lo, hi : (3,) float
        The cell box.
    samples : int
        Sample intervals along the shortest edge.
    snap : float
        Samples nearer the level set than ``snap`` voxels (first-order
        distance ``|f| / |∇f|``) are pushed out to that distance.

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """
    from porecad.mesh import polygonise
    from porecad.mesh.polygonise import Grid

    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    ext = hi - lo
    n = np.maximum(np.round(ext / (ext.min() / int(samples))).astype(np.int64), 2)
    if float(np.prod(n.astype(float))) > 400 ** 3:
        raise InputError(f"{n.tolist()} samples are too many for a periodic cell surface")
    h = ext / n
    axes = [lo[a] + np.arange(n[a]) * h[a] for a in range(3)]
    F = np.asarray(field.sample_grid(axes[0], axes[1], axes[2]), dtype=np.float64)  # [z, y, x], one period
    g2 = np.zeros_like(F)
    for arr_ax, a in ((2, 0), (1, 1), (0, 2)):
        g2 += ((np.roll(F, -1, arr_ax) - np.roll(F, 1, arr_ax)) / (2 * h[a])) ** 2
    d = snap * float(h.min()) * np.sqrt(g2)
    F = np.where(np.abs(F) < d, np.where(F < 0, -d, d), F)
    F = np.pad(F, ((0, 1), (0, 1), (0, 1)), mode="wrap").astype(np.float32)
    grid = Grid.from_box(lo, hi, samples_per_axis=n + 1)

    def sample_slab(xs, ys, zs):
        k = np.rint((np.asarray(zs) - lo[2]) / h[2]).astype(np.int64)
        return F[k]

    res = polygonise(sample_slab, grid, caps=True, threads=1)
    if len(res.faces) == 0:
        raise MeshError("the cell holds no solid on this grid")
    v = np.asarray(res.vertices, dtype=np.float64)
    # put the far-face vertices exactly at hi (they are lo + n h, equal up to rounding)
    for a in range(3):
        v[np.abs(v[:, a] - hi[a]) <= 1e-9 * ext[a], a] = hi[a]
        v[np.abs(v[:, a] - lo[a]) <= 1e-9 * ext[a], a] = lo[a]
    return v, np.asarray(res.faces, dtype=np.int64)
