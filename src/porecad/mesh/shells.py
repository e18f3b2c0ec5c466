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
    present = np.zeros(n, bool)
    present[fl] = True  # components with a face (not lone vertices), numbered in order without a sort
    renumber = np.cumsum(present) - 1
    fl = renumber[fl]
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])) / 6.0
    return fl, np.bincount(fl, weights=vol, minlength=int(present.sum()))


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


#: a piece whose bounding box lies this much (by volume) in the largest piece's is interwoven with it
WOVEN_OVERLAP = 0.5


def _box_overlap(v, f, lab, n, ref):
    """``(n,)``: the fraction of each shell's bounding box (by volume) inside shell ``ref``'s."""
    shell = np.full(len(v), -1, np.int64)  # each vertex of a face lies on exactly one (vertex-connected) shell
    shell[f.ravel()] = np.repeat(lab, 3)
    used = np.flatnonzero(shell >= 0)
    order = used[np.argsort(shell[used], kind="stable")]
    s = shell[order]
    starts = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    lo[s[starts]] = np.minimum.reduceat(v[order], starts, axis=0)
    hi[s[starts]] = np.maximum.reduceat(v[order], starts, axis=0)
    inter = np.clip(np.minimum(hi, hi[ref]) - np.maximum(lo, lo[ref]), 0.0, None).prod(axis=1)
    return inter / np.maximum(np.prod(hi - lo, axis=1), 1e-300)


def keep_largest_piece(vertices, faces, keep_fraction: float = 0.0, overlap: float = WOVEN_OVERLAP,
                       anchored=None):
    """Keep the largest solid piece of a closed solid (with the cavities inside it); drop the islands.

    A shell with positive signed volume is the outer surface of a piece; one
    with negative volume a cavity. The piece of largest volume is kept, with
    every piece of at least ``keep_fraction`` of its volume whose bounding
    box lies at least ``overlap`` (by volume) in the largest one's (interwoven
    networks of a lattice, not debris), and every cavity inside a kept piece
    (winding number 1) and not inside a dropped one. Returns ``(vertices,
    faces, info)`` with ``pieces`` (solid pieces before), ``kept`` (after),
    ``islands_dropped``, ``islands_volume`` and ``islands_fraction`` (of the solid's volume), and
    ``separate`` / ``separate_fraction``: the dropped pieces of at least ``keep_fraction`` of the largest
    (separate parts of comparable size, not debris) and their share of the volume. ``anchored``, when given, is
    ``anchored(vertices, faces, labels, n) -> bool (n,)``: the shells held by something beyond the solid (a
    lattice's pieces cut by its domain's faces, which go on in the next cell); their pieces are kept whatever
    their size and counted as ``anchored``.
    """
    from ..bodies.mesh import MeshBody
    from .weld import compact
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    info = {"pieces": 0, "kept": 0, "islands_dropped": 0, "islands_volume": 0.0, "islands_fraction": 0.0,
            "separate": 0, "separate_fraction": 0.0, "anchored": 0}
    if len(f) == 0:
        return v, f, info
    lab, vol = shell_labels(v, f)
    pos = np.flatnonzero(vol > 0)
    info["pieces"] = info["kept"] = int(len(pos))
    if len(pos) <= 1:
        return v, f, info
    big = vol[pos] >= max(float(keep_fraction), 0.0) * float(vol[pos].max())
    largest = int(np.argmax(vol[pos]))
    woven = big & (_box_overlap(v, f, lab, len(vol), pos[largest])[pos] >= overlap)
    woven[largest] = True
    if anchored is not None:
        held = np.asarray(anchored(v, f, lab, len(vol)), bool)[pos]
        held[largest] = False
        info["anchored"] = int(np.sum(held))
        woven |= held
    kept, islands = pos[woven], pos[~woven]
    total = float(vol.sum())
    info.update(separate=int(np.sum(big & ~woven)), separate_fraction=float(vol[pos[big & ~woven]].sum() / total)
                if total > 0 else 0.0)
    if len(islands) == 0:
        return v, f, info
    keep = np.zeros(len(vol), bool)
    keep[kept] = True
    cav = np.flatnonzero(vol < 0)
    if cav.size:
        first = np.full(len(vol), len(f), np.int64)
        np.minimum.at(first, lab, np.arange(len(f)))  # each shell's first face
        probe = v[f[first[cav], 0]]
        ext = float(np.ptp(v, axis=0).max()) or 1.0
        inside = MeshBody(v, f[np.isin(lab, kept)], band=ext).winding(probe) > 0.5
        inside &= MeshBody(v, f[np.isin(lab, islands)], band=ext).winding(probe) < 0.5
        keep[cav[inside]] = True
    info.update(kept=int(len(kept)), islands_dropped=int(len(islands)), islands_volume=float(vol[islands].sum()),
                islands_fraction=float(vol[islands].sum() / total) if total > 0 else 0.0)
    v2, f2 = compact(v, f[keep[lab]])
    return v2, f2, info
