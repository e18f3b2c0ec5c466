"""Connected shells of a closed mesh: their signed volumes, cavities, and removing specks.

A closed, outward-oriented solid's shells with positive volume are solid
pieces; shells with negative volume are cavities (closed voids).
"""

from __future__ import annotations

import numpy as np


def shell_labels(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """Face labels of the vertex-connected shells and each shell's signed volume: ``(labels (F,), volumes (S,))``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    f = np.asarray(faces, np.int64)
    nv = len(vertices)
    r = np.concatenate([f[:, 0], f[:, 1]])
    c = np.concatenate([f[:, 1], f[:, 2]])
    g = coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(nv, nv))
    n, lab = connected_components(g, directed=False)
    v = np.asarray(vertices, np.float64)
    fl = lab[f[:, 0]]
    used, fl = np.unique(fl, return_inverse=True)
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])) / 6.0
    return fl, np.bincount(fl, weights=vol, minlength=len(used))


def mesh_shells(vertices, faces) -> dict:
    """Counts of shells, solid pieces (positive volume) and cavities (negative volume: closed pores)."""
    if len(faces) == 0:
        return {"shells": 0, "solid_pieces": 0, "cavities": 0}
    _, vol = shell_labels(vertices, faces)
    return {"shells": int(len(vol)), "solid_pieces": int(np.sum(vol > 0)), "cavities": int(np.sum(vol < 0))}


def drop_specks(vertices, faces, min_volume: float):
    """Remove closed shells enclosing less than ``min_volume`` (sub-grid specks and pockets).

    Returns ``(vertices, faces, info)`` with ``shells``, ``solid_islands``
    (positive-volume shells besides the largest), ``cavities`` (negative-volume
    shells) and ``specks_removed``.
    """
    from .weld import compact
    lab, vol = shell_labels(vertices, faces)
    speck = np.abs(vol) < float(min_volume)
    keep_faces = ~speck[lab]
    if speck.any() and keep_faces.any():
        vertices, faces = compact(vertices, np.asarray(faces)[keep_faces])
    vol = vol[~speck]
    info = {"shells": int(len(vol)), "solid_islands": int(max((vol > 0).sum() - 1, 0)),
            "cavities": int((vol < 0).sum()), "specks_removed": int(speck.sum())}
    return vertices, faces, info
