"""TPMS cells mapped into the hexahedra of an unstructured, conforming hex mesh (004 §3, Fig. 5).

004 builds a scaffold by mapping one TPMS unit cell into every hexahedron
with the isoparametric shape functions and joining the cells (its "Boolean
union of the pore units"). Here the unit cell is polygonised once in the
reference cube ``[0, 1]³`` (closed on its six faces), its vertices are mapped
into every hexahedron (8-node trilinear or 20-node serendipity, see
:mod:`porecad.maps.hexmesh`), the cap triangles are kept only on faces that
lie on the mesh boundary, and the vertices of shared faces are welded.

Shared faces of an unstructured mesh meet in any of the eight orientations of
a square, so the cell's pattern on a face must look the same in all of them:
only TPMS types with the full symmetry of the cube (P, I-WP, F-RD, Neovius,
tubular P) are accepted here; others need a structured mesh
(:func:`porecad.maps.hexmesh.hex_scaffold`), whose faces always agree.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError, MeshError

CUBIC_TYPES = ("P", "IWP", "FRD", "neovius", "tubular_P")


def _reference_cell(tpms_type, structure, threshold, resolution):
    from ..fields.tpms import TPMSField
    from ..mesh.polygonise import Grid, polygonise
    from ..solids import StructureField
    field = StructureField(TPMSField(tpms_type, cell_size=1.0), structure, threshold=threshold)
    grid = Grid.from_box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), samples_per_axis=int(resolution))
    res = polygonise(field.sample_grid, grid, caps=True)
    v = np.clip(res.vertices, 0.0, 1.0)
    f = res.faces.astype(np.int64)
    # which cube face (VTK hexahedron face order of porecad.volmesh.hexshapes.HEX_FACES) a cap triangle lies on
    planes = [(2, 0.0), (2, 1.0), (1, 0.0), (0, 1.0), (1, 1.0), (0, 0.0)]
    face_of = np.full(len(f), -1, np.int64)
    tol = 1e-12
    for k, (axis, value) in enumerate(planes):
        on = np.all(np.abs(v[f][:, :, axis] - value) <= tol, axis=1)
        face_of[on & (face_of < 0)] = k
    on_face = np.zeros((len(v), 6), bool)
    for k, (axis, value) in enumerate(planes):
        on_face[:, k] = np.abs(v[:, axis] - value) <= tol
    return v, f, face_of, on_face


def _check_conforming(hexes):
    """Refuse hanging nodes: the boundary quads must close up (every boundary edge in exactly two)."""
    from ..volmesh.hexshapes import hex_boundary_faces
    quads, owner, _ = hex_boundary_faces(hexes)
    e = np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]])
    e.sort(axis=1)
    uniq, inv, cnt = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    bad = np.flatnonzero(cnt != 2)
    if bad.size:
        a, b = (int(x) for x in uniq[bad[0]])
        q = int(np.flatnonzero(inv.reshape(-1) == bad[0])[0]) % len(quads)
        raise InputError(f"hex mesh is not conforming: boundary edge ({a}, {b}) is used by {int(cnt[bad[0]])} "
                         f"boundary face(s) (hanging node or gap near hexahedron {int(owner[q])})")


def hex_cells_scaffold(points, hexes, tpms_type, structure, threshold, resolution, weld_tol=1e-7):
    """One TPMS cell per hexahedron of a conforming hex mesh, welded into one closed solid.

    Parameters
    ----------
    points : (V, 3) float
    hexes : (H, 8) or (H, 20) int
        VTK (quadratic) hexahedron order; 20 nodes select the serendipity map.
    tpms_type : a cubic-symmetric type (see :data:`CUBIC_TYPES`)
    structure, threshold : the solid (pore / rod / sheet and C)
    resolution : samples per cell edge of the reference cell

    Returns ``{'vertices', 'faces', 'boundary_quads', 'welded'}``.
    """
    from ..fields.tpms import get_type
    from ..mesh.weld import close_point_representatives
    from ..volmesh.hexshapes import check_hex_mesh, hex_face_groups
    from .hexmesh import shape_hex8, shape_hex20
    name = get_type(tpms_type).name
    if name not in CUBIC_TYPES:
        raise InputError(f"{name} is not symmetric under the cube's rotations, so its cells do not match across "
                         f"arbitrarily oriented faces; use one of {', '.join(CUBIC_TYPES)} on an unstructured "
                         "hex mesh, or a structured mesh (frustum, cylinder, a parameterised body)")
    P = np.asarray(points, dtype=np.float64)
    H = np.asarray(hexes, dtype=np.int64)
    if H.ndim != 2 or H.shape[1] not in (8, 20):
        raise InputError(f"unsupported element type: cells with {H.shape[-1] if H.ndim == 2 else '?'} nodes; "
                         "use 8-node or 20-node hexahedra")
    P, corners = check_hex_mesh(P, H[:, :8])
    if not np.array_equal(corners, H[:, :8]):  # an all-mirrored mesh was turned over
        if H.shape[1] == 20:
            raise InputError("20-node hexahedra must be positively oriented (corner Jacobians > 0)")
        H = corners
    _check_conforming(H[:, :8])
    inverse, counts = hex_face_groups(H[:, :8])
    shared = (counts[inverse] == 2).reshape(-1, 6)  # (H, 6): local face shared with another hex
    v_ref, f_ref, face_of, on_face = _reference_cell(name, structure, threshold, resolution)
    N = shape_hex20(v_ref) if H.shape[1] == 20 else shape_hex8(v_ref)  # (n_ref, nodes)
    verts = np.einsum("rn,hnd->hrd", N, P[H]).reshape(-1, 3)
    nref = len(v_ref)
    faces = []
    for h in range(len(H)):
        keep = (face_of < 0) | ~shared[h][np.maximum(face_of, 0)]
        faces.append(f_ref[keep] + h * nref)
    faces = np.concatenate(faces)
    # weld the vertices on shared faces (positions agree up to rounding)
    on_any = on_face.any(axis=1)
    cand = (np.nonzero(np.broadcast_to(on_any, (len(H), nref)).reshape(-1))[0])
    scale = float(np.ptp(P, axis=0).max()) or 1.0
    parent = close_point_representatives(verts, weld_tol * scale, candidates=cand)
    used, faces_new = np.unique(parent[faces], return_inverse=True)
    faces_new = faces_new.reshape(-1, 3)
    vertices = verts[used]
    degenerate = (faces_new[:, 0] == faces_new[:, 1]) | (faces_new[:, 1] == faces_new[:, 2]) | \
        (faces_new[:, 0] == faces_new[:, 2])
    if degenerate.any():
        raise MeshError(f"welding collapsed {int(degenerate.sum())} triangles; lower weld_tol or raise the "
                        "resolution")
    return {"vertices": vertices, "faces": faces_new, "welded": int(len(verts) - len(used)),
            "hexes": int(len(H))}
