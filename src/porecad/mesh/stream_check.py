"""Exact check and measures of a mesh that is seen slab by slab (never whole).

The streamed pipeline (:mod:`porecad.scale`) hands over the welded slabs of
:func:`porecad.mesh.polygonise.welded_slabs` one at a time. A slab's faces
use its own vertices and the previous slab's last-plane vertices only, so a
window of two slabs resolves every face, and an edge with both ends on a
seam plane can occur only in the two slabs that share that plane.

:class:`StreamedSolidCheck` uses this to check, exactly and in memory
bounded by two slabs:

* **closed** - every directed edge ``(u, v)`` has its reverse ``(v, u)``;
* **edge-manifold and oriented** - no directed edge occurs twice (so every
  edge has exactly two faces, traversed in opposite directions);
* **outward** - the signed volume is positive.

It also sums the signed volume and the area (float64, per slab) and the
bounds, and counts the solid's **pieces** (:class:`StreamedPieces`: the
shells of positive volume, joined across the seams) with their volumes. Unlike :func:`porecad.mesh.validate.check_solid` it does not look
for non-manifold *vertices* (pinches of two sheets at one vertex), which the
marching-cubes table cannot produce, nor for self-intersections.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .union_find import Forest


@njit(cache=True, nogil=True)
def _edge_keys(faces, carry):
    """The carried keys followed by the directed edge keys of ``faces``.

    Key of the directed edge ``(u, v)``: ``min << 32 | max << 1 | (u > v)``,
    so that sorting groups the two directions of an edge together.
    """
    out = np.empty(len(carry) + 3 * faces.shape[0], np.int64)
    out[: len(carry)] = carry
    n = len(carry)
    for f in range(faces.shape[0]):
        for c in range(3):
            u = np.int64(faces[f, c])
            v = np.int64(faces[f, (c + 1) % 3])
            if u < v:
                out[n] = (u << 32) | (v << 1)
            else:
                out[n] = (v << 32) | (u << 1) | 1
            n += 1
    return out


@njit(cache=True, nogil=True)
def _classify(keys, is_top, top_offset):
    """Walk the sorted edge keys: count open and duplicate edges, collect the edges to carry.

    An edge whose two ends are on the slab's last plane (``is_top[id -
    top_offset]``) is carried to the next slab (each direction once) instead
    of being judged here.
    """
    n = len(keys)
    carry = np.empty(n, np.int64)
    n_carry = 0
    open_edges = 0
    duplicates = 0
    i = 0
    while i < n:
        base = keys[i] >> 1
        n0 = 0
        n1 = 0
        j = i
        while j < n and (keys[j] >> 1) == base:
            if keys[j] & 1:
                n1 += 1
            else:
                n0 += 1
            j += 1
        if n0 > 1:
            duplicates += n0 - 1
        if n1 > 1:
            duplicates += n1 - 1
        a = (base >> 31) - top_offset
        b = (base & 0x7FFFFFFF) - top_offset
        top = (0 <= a < len(is_top)) and (0 <= b < len(is_top)) and is_top[a] and is_top[b]
        if top:
            if n0:
                carry[n_carry] = base << 1
                n_carry += 1
            if n1:
                carry[n_carry] = (base << 1) | 1
                n_carry += 1
        elif n0 == 0 or n1 == 0:
            open_edges += 1
        i = j
    return open_edges, duplicates, carry[:n_carry].copy()


class SlabWindow:
    """Vertex positions for the faces of the current slab (its own and the previous slab's)."""

    def __init__(self):
        self.prev_vertices = np.zeros((0, 3))
        self.prev_offset = 0

    def local(self, slab):
        """``(positions, faces)``: the slab's faces indexing ``positions`` (int64)."""
        if len(self.prev_vertices):
            pos = np.concatenate([self.prev_vertices, slab.vertices])
            base = self.prev_offset
        else:
            pos = slab.vertices
            base = slab.offset
        faces = slab.faces.astype(np.int64) - base
        # the coordinates as stored (float32): checked, measured and written like an in-memory mesh
        from .validate import stored_coordinates
        return np.ascontiguousarray(stored_coordinates(pos), dtype=np.float64), faces

    def advance(self, slab):
        self.prev_vertices = slab.vertices
        self.prev_offset = slab.offset


class StreamedPieces:
    """The connected shells of a mesh seen slab by slab, with their signed volumes, in memory of the shells.

    Each slab's window (its vertices and the previous slab's) is split into
    connected components (``scipy.sparse.csgraph``); a component takes a new
    id, and the ids of components that share a vertex of a seam plane are
    joined (union-find over the ids: as many as the components of all slabs,
    never the vertices of the mesh).
    """

    def __init__(self):
        self.forest = Forest()
        self.volume = np.zeros(0)
        self.area = np.zeros(0)
        self.n_vertices = np.zeros(0, np.int64)  # the vertices each component owns (of its own slab)
        self.face_ids = np.zeros(0, np.int64)    # the component of each face of the last slab added
        self.top_ids = np.zeros(0, np.int64)    # global ids of the last seam plane's vertices ...
        self.top_comp = np.zeros(0, np.int64)   # ... and their component ids

    def add(self, slab, faces, face_volume, face_area, window_base: int):
        """Add a slab: ``faces`` index its window (global id ``window_base`` + index), ``face_volume`` and
        ``face_area`` their signed volume terms and areas."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        n = int(max(faces.max() + 1 if len(faces) else 0, slab.offset - window_base + len(slab.vertices)))
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]]) if len(faces) else np.zeros((0, 2), np.int64)
        k, labels = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)),
                                         directed=False)
        base = self.forest.grow(k)
        fl = labels[faces[:, 0]] if len(faces) else np.zeros(0, np.int64)
        self.face_ids = base + fl.astype(np.int64)
        self.volume = np.concatenate([self.volume, np.bincount(fl, weights=face_volume, minlength=k)])
        self.area = np.concatenate([self.area, np.bincount(fl, weights=face_area, minlength=k)])
        own = labels[slab.offset - window_base: slab.offset - window_base + len(slab.vertices)]
        self.n_vertices = np.concatenate([self.n_vertices, np.bincount(own, minlength=k)])
        if len(self.top_ids):  # the previous seam plane's vertices are in this window
            local = self.top_ids - window_base
            ok = (local >= 0) & (local < n)
            self.forest.join(self.top_comp[ok], base + labels[local[ok]])
        top = slab.top_ids.ravel()
        self.top_ids = top[top >= 0].astype(np.int64)
        self.top_comp = base + labels[self.top_ids - window_base]

    def kept(self, keep_fraction: float) -> np.ndarray:
        """Which components (ids of :attr:`face_ids`) belong to a piece kept when islands are dropped: the
        largest piece and those of at least ``keep_fraction`` of its volume."""
        roots = self.forest.roots()
        vol = np.bincount(roots, weights=self.volume, minlength=len(self.forest))
        return vol[roots] >= keep_fraction * vol.max() if len(vol) else np.zeros(0, bool)

    def dropped(self, keep: np.ndarray) -> dict:
        """The figures of the pieces left when the components not in ``keep`` are dropped."""
        roots = self.forest.roots()
        vol = np.bincount(roots, weights=self.volume, minlength=len(self.forest))
        pieces = vol > 0
        kept_pieces = pieces & (np.bincount(roots, weights=keep, minlength=len(vol)) > 0)
        total = float(vol[pieces].sum())
        return {"pieces": int(kept_pieces.sum()), "islands_dropped": int(pieces.sum() - kept_pieces.sum()),
                "islands_volume_fraction": 1.0 - float(vol[kept_pieces].sum()) / total if total > 0 else 0.0,
                "volume": float(self.volume[keep].sum()), "area": float(self.area[keep].sum()),
                "vertices": int(self.n_vertices[keep].sum())}

    def result(self) -> dict:
        """``pieces`` (shells of positive volume), the largest one's volume and that of all of them."""
        if not len(self.forest):
            return {"pieces": 0, "largest_volume": 0.0, "pieces_volume": 0.0}
        vol = np.bincount(self.forest.roots(), weights=self.volume)
        pos = vol[vol > 0]
        return {"pieces": int(len(pos)), "largest_volume": float(pos.max()) if len(pos) else 0.0,
                "pieces_volume": float(pos.sum())}


class StreamedSolidCheck:
    """Accumulate the checks and measures of a mesh slab by slab; :meth:`result` at the end.

    Parameters
    ----------
    centre : (3,) float, optional
        Reference point of the signed volume (the grid centre keeps the sum
        accurate far from the origin).
    """

    def __init__(self, centre=(0.0, 0.0, 0.0)):
        self.centre = np.asarray(centre, dtype=np.float64)
        self.carry = np.zeros(0, np.int64)  # directed edges on the last seam plane
        self.duplicates = 0
        self.open_edges = 0
        self.volume = 0.0
        self.area = 0.0
        self.n_faces = 0
        self.n_vertices = 0
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)
        self.pieces = StreamedPieces()

    def add(self, slab, positions, faces):
        """Add a welded slab; ``positions``/``faces`` as from :meth:`SlabWindow.local`."""
        f = slab.faces
        self.n_faces += len(f)
        self.n_vertices += len(slab.vertices)
        if len(slab.vertices):
            self.lo = np.minimum(self.lo, slab.vertices.min(axis=0))
            self.hi = np.maximum(self.hi, slab.vertices.max(axis=0))
        if len(f):
            p0 = positions[faces[:, 0]] - self.centre
            p1 = positions[faces[:, 1]] - self.centre
            p2 = positions[faces[:, 2]] - self.centre
            cr = np.cross(p1 - p0, p2 - p0)
            face_area = 0.5 * np.sqrt(np.einsum("ij,ij->i", cr, cr))
            self.area += float(face_area.sum())
            face_volume = np.einsum("ij,ij->i", p0, np.cross(p1, p2)) / 6.0
            self.volume += float(face_volume.sum())
            self.pieces.add(slab, faces, face_volume, face_area, int(slab.faces.min()) - int(faces.min()))
        else:  # nothing joins across this slab
            self.pieces.top_ids = np.zeros(0, np.int64)
            self.pieces.face_ids = np.zeros(0, np.int64)
        keys = np.sort(_edge_keys(f, self.carry))
        is_top = np.zeros(len(slab.vertices), np.bool_)
        top = slab.top_ids.ravel()
        top = top[top >= 0] - slab.offset
        is_top[top[(top >= 0) & (top < len(is_top))]] = True
        n_open, n_dup, self.carry = _classify(keys, is_top, np.int64(slab.offset))
        self.open_edges += n_open
        self.duplicates += n_dup

    def result(self) -> dict:
        """The check as a dict (``closed``, ``manifold``, ``oriented``, ``outward``, measures)."""
        # edges left on the last plane: judged now (nothing follows)
        if len(self.carry):
            n_open, n_dup, _ = _classify(np.sort(self.carry), np.zeros(0, np.bool_), np.int64(0))
            self.open_edges += n_open
            self.duplicates += n_dup
            self.carry = np.zeros(0, np.int64)
        closed = self.open_edges == 0 and self.duplicates == 0
        out = {"closed": closed, "manifold": self.duplicates == 0, "oriented": self.duplicates == 0,
               "outward": closed and self.volume > 0, "open_edges": self.open_edges,
               "duplicate_edges": self.duplicates, "volume": self.volume, "area": self.area,
               "triangles": self.n_faces, "vertices": self.n_vertices, **self.pieces.result(),
               "check": "streamed: edges closed, edge-manifold, oriented"}
        out["bounds"] = [self.lo.tolist(), self.hi.tolist()] if self.n_vertices else None
        return out

