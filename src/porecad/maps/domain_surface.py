"""Closed boundary surfaces of mapped and meshed volume domains.

A scaffold built in a mapped domain — a trivariate B-spline solid (TBSS,
document 001), a structured hexahedral map (000 ch.3, 004), a hexahedral
mesh — is analysed inside that domain, never in its bounding box (issue 22).
The analysis takes a closed, outward triangle surface
(:class:`porecad.analysis.domain.MeshDomain`); this module makes one:

* :func:`mapped_box_surface` — the image of a parameter box's six faces
  under any map, sampled on one grid per axis, so the faces share their
  edge vertices exactly and are welded by parameter (periodic axes: the
  faces at both ends are the same interior surface and are left out, their
  neighbours wrap around). Vertices that the map sends to exactly one point
  (a collapsed edge) are welded too. Triangles keep the parameter-space
  orientation, outward for a map with positive Jacobian (a negative map is
  flipped as a whole).
* :func:`tbss_surface` and :func:`hex_map_surface` — that surface for a TBSS
  and for a structured hex map of 8- or 20-node elements.
* :func:`hex_mesh_surface` — the boundary quads of a hexahedral mesh (faces
  of one hex only), each split in two triangles; :func:`cell_union_surface`
  that of a union of lattice cells; :func:`tet_mesh_surface` the boundary
  faces of a tetrahedral mesh.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

#: most samples along one parameter axis of a mapped surface
MAX_AXIS_SAMPLES = 257


def _face_triangles(nb: int, nc: int, flip: bool) -> np.ndarray:
    """Triangles of an ``nb × nc`` vertex grid (row-major, b slow) with normal ``e_b × e_c`` (or flipped)."""
    i, j = np.meshgrid(np.arange(nb - 1), np.arange(nc - 1), indexing="ij")
    a = (i * nc + j).ravel()
    b, c, d = a + nc, a + nc + 1, a + 1          # (i+1, j), (i+1, j+1), (i, j+1)
    tri = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return tri[:, ::-1] if flip else tri


def mapped_box_surface(map_points, lo, hi, samples, periodic=(False, False, False), return_params=False):
    """Closed surface of the image of the parameter box ``[lo, hi]`` under ``map_points``.

    Parameters
    ----------
    map_points : callable
        ``(m, 3)`` parameters → ``(m, 3)`` points (mm).
    lo, hi : 3 floats
        The parameter box.
    samples : 3 ints
        Samples per parameter axis (ends included), at most :data:`MAX_AXIS_SAMPLES`.
    periodic : 3 bools
        Axes whose two end faces are one surface (left out; the grid wraps).

    Returns
    -------
    vertices (n, 3) float64, faces (m, 3) int64
        Outward for a map of positive Jacobian (a map that inverts the box is flipped).
    params (n, 3) float64
        With ``return_params``: the parameters of the vertices.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    n = [int(s) for s in samples]
    if len(n) != 3 or min(n) < 2 or max(n) > MAX_AXIS_SAMPLES:
        raise InputError(f"a mapped surface takes 2..{MAX_AXIS_SAMPLES} samples per axis, got {samples}")
    axes = [np.linspace(lo[a], hi[a], n[a]) for a in range(3)]
    params, tris, offset = [], [], 0
    for a in range(3):
        if periodic[a]:
            continue
        b, c = (a + 1) % 3, (a + 2) % 3
        for end in (0, 1):
            B, C = np.meshgrid(axes[b], axes[c], indexing="ij")
            P = np.empty((B.size, 3))
            P[:, a] = hi[a] if end else lo[a]
            P[:, b], P[:, c] = B.ravel(), C.ravel()
            params.append(P)
            tris.append(_face_triangles(n[b], n[c], flip=not end) + offset)
            offset += len(P)
    if not params:
        raise InputError("a parameter box periodic along all three axes has no boundary")
    P = np.concatenate(params)
    F = np.concatenate(tris)
    key = P.copy()
    for a in range(3):
        if periodic[a]:
            key[:, a] = np.where(np.isclose(key[:, a], hi[a]), lo[a], key[:, a])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    F = inverse.reshape(-1)[F]
    P = P[first]
    V = np.asarray(map_points(P), dtype=np.float64)
    # a map that collapses an edge or face to one point: weld exactly coincident images
    _, first2, inverse2 = np.unique(V, axis=0, return_index=True, return_inverse=True)
    V, F, P = V[first2], inverse2.reshape(-1)[F], P[first2]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    from ..mesh.validate import signed_volume
    if signed_volume(V, F) < 0:
        F = F[:, ::-1]
    F = np.ascontiguousarray(F, dtype=np.int64)
    return (V, F, P) if return_params else (V, F)


def tbss_surface(tbss, samples_per_control: int = 6, min_samples: int = 33, return_params: bool = False):
    """The closed boundary surface of a TBSS solid (periodic faces left out), outward (and with
    ``return_params`` its vertices' parameters)."""
    dom = np.asarray(tbss.domain, dtype=np.float64)
    n = [int(min(MAX_AXIS_SAMPLES, max(min_samples, samples_per_control * c))) for c in tbss.n_ctrl]
    return mapped_box_surface(tbss.map_points, dom[:, 0], dom[:, 1], n, periodic=tuple(tbss.periodic),
                              return_params=return_params)


def hex_map_surface(nodes, element: str, cells, samples_per_cell: int = 8):
    """The closed boundary surface of a structured hex map (``hex8``/``hex20`` node grid over ``cells``)."""
    from .hexmesh import map_params
    c = np.asarray(cells, dtype=np.int64)
    per = max(2, min(int(samples_per_cell), int((MAX_AXIS_SAMPLES - 1) // max(int(c.max()), 1))))
    n = [int(min(MAX_AXIS_SAMPLES, k * per + 1)) for k in c]
    return mapped_box_surface(lambda P: map_params(nodes, P, element), np.zeros(3), c.astype(np.float64), n)


def hex_mesh_surface(points, hexes):
    """The boundary of a hexahedral mesh (VTK order, valid hexes) as outward triangles, compacted."""
    from ..mesh.weld import compact
    from ..volmesh.hexshapes import hex_boundary_faces
    quads, _, _ = hex_boundary_faces(hexes)
    tri = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return compact(np.asarray(points, dtype=np.float64), tri)


def cell_union_surface(kept, c_lo, origin, cell_size):
    """The boundary of a union of lattice cells (an infill's complete cells) as outward triangles.

    ``kept[cz, cy, cx]`` marks cell ``c_lo + (cx, cy, cz)`` of the lattice
    of boxes ``origin + index * cell_size``
    (:func:`porecad.bodies.cells.complete_cells`); the cells become
    hexahedra of one node grid, so shared faces drop out.
    """
    kept = np.asarray(kept, dtype=bool)
    if not kept.any():
        raise InputError("the union of cells is empty")
    L = np.broadcast_to(np.asarray(cell_size, dtype=np.float64), (3,))
    nz, ny, nx = kept.shape
    gx, gy, gz = (np.arange(m + 1) for m in (nx, ny, nz))
    Z, Y, X = np.meshgrid(gz, gy, gx, indexing="ij")
    base = np.asarray(origin, dtype=np.float64) + np.asarray(c_lo, dtype=np.float64) * L
    points = base + np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1) * L

    def node(i, j, k):
        return (k * (ny + 1) + j) * (nx + 1) + i

    k, j, i = np.nonzero(kept)
    hexes = np.stack([node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                      node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)],
                     axis=1)
    return hex_mesh_surface(points, hexes)


def tet_mesh_surface(points, tets):
    """The boundary of a tetrahedral mesh as outward triangles, compacted."""
    from ..mesh.weld import compact
    from ..volmesh import boundary_faces
    return compact(np.asarray(points, dtype=np.float64), boundary_faces(tets)[0])
