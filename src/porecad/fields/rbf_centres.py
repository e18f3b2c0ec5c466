"""ARBF centres and their values: points, face and cell centres, segments (document 000 §5.3).

:func:`mesh_centres` places the centres of a tet, hex, triangle or quad mesh
(13 per tetrahedron, 21 per hexahedron: vertices +1, face and cell centres
and the channel skeleton −1); :func:`point_cloud_centres` those of a point
cloud with values. The interpolant over them is :mod:`porecad.fields.rbf`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field as dc_field, replace

import numpy as np

from ..errors import InputError

#: centre kinds
KIND_VERTEX, KIND_FACE, KIND_CELL, KIND_SEGMENT, KIND_POINT = 0, 1, 2, 3, 4


@dataclass
class Centres:
    """Basis-function centres: points (``a = b``) and segments ``(a, b)`` with their values.

    Attributes
    ----------
    a, b : (N, 3) float64
        A point centre has ``b = a``.
    segment : (N,) bool
    values : (N,) float64
        The interpolation conditions ``f_j``.
    kind : (N,) int8
        ``KIND_VERTEX`` (+1), ``KIND_FACE`` (face or edge centre),
        ``KIND_CELL``, ``KIND_SEGMENT``, ``KIND_POINT`` (point cloud).
    ends : (N, 2) int64
        For a segment, the point centres at its ends (it follows them when
        they move); ``-1`` otherwise.
    constraint : (N, 3, 3) float64 or None
        Projection applied to a point centre's random displacement
        (identity: free; ``I − n nᵀ``: stays on a boundary plane; 0: fixed).
    """

    a: np.ndarray
    b: np.ndarray
    segment: np.ndarray
    values: np.ndarray
    kind: np.ndarray
    ends: np.ndarray
    constraint: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(len(self.a))

    def counts(self) -> dict:
        """Number of centres of each kind (JSON-ready)."""
        names = {KIND_VERTEX: "vertices", KIND_FACE: "face_centres", KIND_CELL: "cell_centres",
                 KIND_SEGMENT: "segments", KIND_POINT: "points"}
        return {names[k]: int(np.sum(self.kind == k)) for k in names if np.any(self.kind == k)}

    def jittered(self, amount: float, seed=None) -> "Centres":
        """Centres moved at random (000 Fig. 5.10): each point centre by a displacement uniform in a ball.

        The ball has radius ``amount`` (mm); the displacement goes through the
        centre's ``constraint`` (centres on the domain's boundary planes stay
        on them, so the pores keep opening there; corners stay put). Segments
        follow their end points. Deterministic for a given ``seed``.
        """
        s = float(amount)
        if not math.isfinite(s) or s < 0:
            raise InputError(f"jitter must be a length ≥ 0 in mm, got {amount!r}")
        if s == 0:
            return self
        rng = np.random.default_rng(seed)
        n = self.n
        d = rng.normal(size=(n, 3))
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
        d *= (s * rng.random(n) ** (1.0 / 3.0))[:, None]
        if self.constraint is not None:
            d = np.einsum("nij,nj->ni", self.constraint, d)
        pt = ~self.segment
        a = self.a.copy()
        a[pt] += d[pt]
        b = a.copy()
        sg = np.flatnonzero(self.segment)
        a[sg] = a[self.ends[sg, 0]]
        b[sg] = a[self.ends[sg, 1]]
        return replace(self, a=a, b=b)


@dataclass
class CellCentres:
    """The centres of a mesh (or point cloud) and the cells that own them.

    Attributes
    ----------
    centres : Centres
    kind : str
        ``"tri"``, ``"quad"``, ``"tet"``, ``"hex"`` or ``"points"``.
    points : (V, 3) float64
        Mesh vertices (for a point cloud: the points).
    cells : (C, k) int64
        Cells as vertex indices (for a point cloud: ``(V, 1)``, one per point).
    cell_start, cell_items : int64 arrays
        CSR: the centres of cell ``i`` are ``cell_items[cell_start[i]:cell_start[i+1]]``.
    scale : float
        Length scale ``h`` (mean edge length; mean nearest-neighbour distance for points), mm.
    """

    centres: Centres
    kind: str
    points: np.ndarray
    cells: np.ndarray
    cell_start: np.ndarray
    cell_items: np.ndarray
    scale: float
    info: dict = dc_field(default_factory=dict)

    def with_centres(self, centres: Centres) -> "CellCentres":
        return replace(self, centres=centres)

    def own(self, i: int) -> np.ndarray:
        return self.cell_items[self.cell_start[i]:self.cell_start[i + 1]]


TRI_EDGES = np.array([[0, 1], [1, 2], [2, 0]], dtype=np.int64)
QUAD_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64)
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)  # FACE_LOCAL
_TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


def unique_rows(rows: np.ndarray):
    """Unique sorted rows: returns ``(first index per unique row, inverse, counts)``."""
    key = np.sort(rows, axis=1)
    _, first, inverse, counts = np.unique(key, axis=0, return_index=True, return_inverse=True,
                                          return_counts=True)
    return first, inverse.reshape(-1), counts


def _normal(poly: np.ndarray) -> np.ndarray:
    """Unit normals of ``(F, k, 3)`` polygons (Newell's method via the fan from corner 0)."""
    n = np.zeros((len(poly), 3))
    for i in range(1, poly.shape[1] - 1):
        n += np.cross(poly[:, i] - poly[:, 0], poly[:, i + 1] - poly[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def mesh_centres(points, cells, kind: str) -> CellCentres:
    """Centres and values of a 2D or 3D mesh (000 §5.3, Fig. 5.3).

    Parameters
    ----------
    points : (V, 2) or (V, 3) float array
        2D points get ``z = 0``.
    cells : (C, k) int array
        ``kind = "tri"`` (k = 3), ``"quad"`` (k = 4, corners in order round
        the quad), ``"tet"`` (k = 4) or ``"hex"`` (k = 8, VTK order; see
        :mod:`porecad.volmesh.hexshapes`).

    Returns
    -------
    CellCentres
        Centres ordered: vertices (+1), edge midpoints (2D) or face centres
        (3D) (−1), cell centres (−1), segments cell centre → edge midpoint /
        face centre (−1). Per cell: 10 (tri), 13 (quad), 13 (tet) or 21 (hex)
        centres. Shared vertices, edge midpoints and face centres appear
        once; only vertices used by a cell are centres.
    """
    kind, p, c, parts = _checked_mesh(points, cells, kind)
    lay = _layout(p, c, parts)
    a, b, segment, kinds, values, ends = _centre_arrays(p, c, lay)
    own, cell_start = _cell_centres(c, lay)
    scale = _length_scale(p, c, kind)
    P, bnd = _jitter_constraints(p, lay, two_d=kind in ("tri", "quad"))
    centres = Centres(a, b, segment, values, kinds, ends, P)
    info = {"boundary_entities": int(len(bnd)), "sub_entities": int(lay.n_sub)}
    return CellCentres(centres, kind, p, c, cell_start, own, scale, info)


def _checked_mesh(points, cells, kind):
    """Check a mesh for :func:`mesh_centres`.

    Takes its ``points``, ``cells`` and ``kind``; returns ``(kind, p, c, parts)``: the kind as a
    str, the points ``(V, 3)`` float64 (2D points with ``z = 0``), the cells ``(C, k)`` int64 and the
    local vertex ids of a cell's sub-entities (edges in 2D, faces in 3D). Raises :class:`InputError`.
    """
    from ..volmesh.hexshapes import HEX_FACES
    kind = str(kind)
    sub = {"tri": (3, TRI_EDGES), "quad": (4, QUAD_EDGES), "tet": (4, TET_FACES), "hex": (8, HEX_FACES)}
    if kind not in sub:
        raise InputError(f"unknown mesh kind {kind!r}; use tri, quad, tet or hex")
    k, parts = sub[kind]
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise InputError(f"points must have shape (V, 2) or (V, 3), got {p.shape}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    c = np.asarray(cells)
    if c.ndim != 2 or c.shape[1] != k:
        raise InputError(f"{kind} cells must have shape (C, {k}), got {c.shape}")
    if len(c) == 0:
        raise InputError("the mesh is empty (no cells)")
    c = np.ascontiguousarray(c, dtype=np.int64)
    if c.min() < 0 or c.max() >= len(p):
        raise InputError(f"cell vertex indices must lie in 0..{len(p) - 1}")
    if not np.isfinite(p).all():
        raise InputError("mesh points must be finite")
    return kind, p, c, parts


@dataclass
class _Layout:
    """Where a mesh's centres go: ``[vertices | sub-entities | cell centres | segments]``.

    ``used``: the vertices used by a cell; ``vid``: vertex -> centre index (−1 unused);
    ``sub_rows``: every cell's sub-entities ``(C * m, s)``; ``first``, ``inverse``, ``counts``:
    :func:`unique_rows` of them; ``m``: sub-entities per cell.
    """

    used: np.ndarray
    vid: np.ndarray
    sub_rows: np.ndarray
    first: np.ndarray
    inverse: np.ndarray
    counts: np.ndarray
    m: int
    n_cells: int

    @property
    def nv(self) -> int:
        return len(self.used)

    @property
    def n_sub(self) -> int:
        return len(self.first)

    @property
    def off_sub(self) -> int:
        return self.nv

    @property
    def off_cell(self) -> int:
        return self.nv + self.n_sub

    @property
    def off_seg(self) -> int:
        return self.nv + self.n_sub + self.n_cells

    @property
    def n(self) -> int:
        return self.off_seg + self.n_cells * self.m


def _layout(p: np.ndarray, c: np.ndarray, parts: np.ndarray) -> _Layout:
    """Takes the checked points, cells and sub-entity table; returns the :class:`_Layout` of the centres."""
    used = np.unique(c)
    vid = np.full(len(p), -1, np.int64)
    vid[used] = np.arange(len(used))
    sub_rows = c[:, parts].reshape(-1, parts.shape[1])  # (C * m, 2 | 3 | 4)
    first, inverse, counts = unique_rows(sub_rows)
    return _Layout(used, vid, sub_rows, first, inverse, counts, parts.shape[0], len(c))


def _centre_arrays(p: np.ndarray, c: np.ndarray, lay: _Layout):
    """Takes the points, cells and layout; returns the centres' ``(a, b, segment, kinds, values, ends)``.

    Vertices get +1, every other centre −1; a segment runs from its cell's
    centre (``ends[:, 0]``) to the sub-entity's centre (``ends[:, 1]``).
    """
    nv, off_sub, off_cell, off_seg, N, C = lay.nv, lay.off_sub, lay.off_cell, lay.off_seg, lay.n, lay.n_cells
    sub_pts = p[lay.sub_rows[lay.first]].mean(axis=1)
    cell_pts = p[c].mean(axis=1)
    a = np.empty((N, 3))
    a[:nv] = p[lay.used]
    a[off_sub:off_cell] = sub_pts
    a[off_cell:off_seg] = cell_pts
    ends = np.full((N, 2), -1, np.int64)
    ends[off_seg:, 0] = np.repeat(off_cell + np.arange(C), lay.m)
    ends[off_seg:, 1] = off_sub + lay.inverse
    a[off_seg:] = a[ends[off_seg:, 0]]
    b = a.copy()
    b[off_seg:] = a[ends[off_seg:, 1]]
    segment = np.zeros(N, bool)
    segment[off_seg:] = True
    kinds = np.full(N, KIND_SEGMENT, np.int8)
    kinds[:nv] = KIND_VERTEX
    kinds[off_sub:off_cell] = KIND_FACE
    kinds[off_cell:off_seg] = KIND_CELL
    values = -np.ones(N)
    values[:nv] = 1.0
    return a, b, segment, kinds, values, ends


def _cell_centres(c: np.ndarray, lay: _Layout):
    """Takes the cells and layout; returns ``(items, start)``, the CSR of each cell's centres.

    Per cell: its k vertices, its m sub-entities, its cell centre, its m segments.
    """
    C, m = lay.n_cells, lay.m
    own = np.concatenate([lay.vid[c], lay.off_sub + lay.inverse.reshape(C, m),
                          (lay.off_cell + np.arange(C))[:, None], lay.off_seg + np.arange(C * m).reshape(C, m)],
                         axis=1)
    cell_start = np.arange(C + 1, dtype=np.int64) * own.shape[1]
    return np.ascontiguousarray(own.reshape(-1)), cell_start


def _length_scale(p: np.ndarray, c: np.ndarray, kind: str) -> float:
    """Takes the points, cells and kind; returns ``h``, the mean edge length (InputError when 0)."""
    from ..volmesh.hexshapes import HEX_EDGES
    edges = {"tri": TRI_EDGES, "quad": QUAD_EDGES, "tet": _TET_EDGES, "hex": HEX_EDGES}[kind]
    q = p[c]
    scale = float(np.linalg.norm(q[:, edges[:, 1]] - q[:, edges[:, 0]], axis=2).mean())
    if not scale > 0:
        raise InputError("the mesh has zero-length edges only")
    return scale


def _jitter_constraints(p: np.ndarray, lay: _Layout, two_d: bool):
    """Takes the points and layout; returns ``(P, bnd)``, the jitter projections of the centres.

    ``P (N, 3, 3)`` is each centre's projection, ``bnd`` the boundary
    sub-entities (those of one cell), which stay on their boundary line or
    plane; segments follow their ends (``P = 0``). In 2D all motion stays in
    the plane and boundary vertices are fixed; in 3D see :func:`_vertex_constraints`.
    """
    N, off_sub = lay.n, lay.off_sub
    bnd = np.flatnonzero(lay.counts == 1)
    P = np.broadcast_to(np.eye(3), (N, 3, 3)).copy()
    if two_d:
        P[:] = np.diag([1.0, 1.0, 0.0])
        ed = lay.sub_rows[lay.first[bnd]]
        t = p[ed[:, 1]] - p[ed[:, 0]]
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
        P[off_sub + bnd] = np.einsum("ni,nj->nij", t, t)
        P[lay.vid[np.unique(ed)]] = 0.0
    else:
        # orient boundary faces by their owner (local faces are outward for valid cells)
        owner_rows = np.full(lay.n_sub, -1, np.int64)
        owner_rows[lay.inverse] = np.arange(len(lay.inverse))
        bf = lay.sub_rows[owner_rows[bnd]]
        nrm = _normal(p[bf])
        P[off_sub + bnd] = np.eye(3) - np.einsum("ni,nj->nij", nrm, nrm)
        _vertex_constraints(P, lay.vid[bf.reshape(-1)], np.repeat(nrm, bf.shape[1], axis=0))
    P[lay.off_seg:] = 0.0  # segments follow their ends
    return P, bnd


def _vertex_constraints(P: np.ndarray, flat_v: np.ndarray, flat_n: np.ndarray) -> None:
    """Set the 3D boundary vertices' rows of ``P`` in place; returns nothing.

    Takes each boundary face corner's centre index ``flat_v`` and its face normal ``flat_n``:
    a vertex moves in-plane where all its boundary faces are coplanar, else it is fixed.
    """
    order = np.argsort(flat_v, kind="stable")
    sv, sn = flat_v[order], flat_n[order]
    starts = np.flatnonzero(np.r_[True, sv[1:] != sv[:-1]])
    for s0, s1 in zip(starts, np.r_[starts[1:], len(sv)]):
        mean = sn[s0:s1].mean(axis=0)
        mean /= max(np.linalg.norm(mean), 1e-300)
        P[sv[s0]] = np.eye(3) - np.outer(mean, mean) if np.all(sn[s0:s1] @ mean > 1 - 1e-9) else 0.0


#: largest point file read (bytes)
MAX_POINT_FILE_BYTES = 1 << 30


def read_points(path):
    """Read a point cloud with values: ``x y z value`` per row.

    ``.npy`` holds an ``(N, 4)`` array; any other file is text (UTF-8) with
    four numbers per row separated by spaces, tabs, commas or semicolons;
    blank lines, ``#`` comments and one non-numeric header line are skipped.
    Returns ``(points (N, 3), values (N,))``; one-line errors.
    """
    import os
    from pathlib import Path
    p = Path(os.fspath(path))
    if not p.exists():
        raise InputError(f"{p}: no such file")
    if p.is_dir():
        raise InputError(f"{p}: is a directory, not a point file")
    from ..io.bounded import check_file_size, check_memory
    size = check_file_size(p, MAX_POINT_FILE_BYTES, "a point file")
    if p.suffix.lower() == ".npy":
        try:  # memory-mapped first: the header's shape is checked against the file before anything is read
            arr = np.load(p, allow_pickle=False, mmap_mode="r")
        except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's input
            raise InputError(f"{p}: cannot read as a .npy array ({type(exc).__name__})") from exc
        if not isinstance(arr, np.ndarray) or arr.ndim != 2 or arr.shape[1] != 4:
            raise InputError(f"{p}: expected an (N, 4) array of 'x y z value' rows, got shape "
                             f"{getattr(arr, 'shape', '?')}")
        check_memory(float(arr.shape[0]) * 4 * 8 * 3, f"{p}: {arr.shape[0]:,} points")
        arr = np.array(arr)
        if not np.issubdtype(arr.dtype, np.number):
            raise InputError(f"{p}: the array is not numeric (dtype {arr.dtype})")
        arr = arr.astype(np.float64)
    else:
        check_memory(size * 12.0, f"{p}: reading this point file")
        try:
            text = p.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            raise InputError(f"{p}: not a UTF-8 text file of 'x y z value' rows (or give a .npy file)") from None
        rows = []
        header_skipped = False
        for lineno, line in enumerate(text.splitlines(), 1):
            s = line.split("#", 1)[0].strip()
            if not s:
                continue
            parts = s.replace(",", " ").replace(";", " ").split()
            try:
                rows.append([float(v) for v in parts])
            except ValueError:
                if not rows and not header_skipped:
                    header_skipped = True
                    continue
                raise InputError(f"{p}: line {lineno} is not numeric") from None
            if len(parts) != 4:
                raise InputError(f"{p}: line {lineno} has {len(parts)} values; each row is 'x y z value'")
        arr = np.asarray(rows, dtype=np.float64).reshape(-1, 4)
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError(f"{p}: expected rows of 'x y z value' (N, 4), got shape {arr.shape}")
    if len(arr) == 0:
        raise InputError(f"{p}: the point cloud is empty")
    if not np.isfinite(arr).all():
        raise InputError(f"{p}: row {int(np.argmin(np.isfinite(arr).all(axis=1)))} has a non-finite value")
    return np.ascontiguousarray(arr[:, :3]), np.ascontiguousarray(arr[:, 3])


def point_cloud_centres(points, values) -> CellCentres:
    """Point centres with given values; every point is its own cell (its Voronoi cell, located by k-d tree).

    The length scale is the mean distance to the nearest other point.
    """
    from scipy.spatial import cKDTree
    p = np.asarray(points, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {p.shape}")
    if len(p) == 0:
        raise InputError("the point cloud is empty")
    if len(v) != len(p):
        raise InputError(f"{len(p)} points but {len(v)} values")
    if not (np.isfinite(p).all() and np.isfinite(v).all()):
        raise InputError("point coordinates and values must be finite")
    N = len(p)
    if N < 2:
        raise InputError("a point cloud needs at least 2 points")
    d, _ = cKDTree(p).query(p, k=2)
    nn = d[:, 1]
    scale = float(nn[nn > 0].mean()) if np.any(nn > 0) else 0.0
    if not scale > 0:
        raise InputError("all points of the point cloud coincide")
    centres = Centres(p.copy(), p.copy(), np.zeros(N, bool), v.copy(), np.full(N, KIND_POINT, np.int8),
                      np.full((N, 2), -1, np.int64), None)
    return CellCentres(centres, "points", p, np.arange(N, dtype=np.int64)[:, None],
                       np.arange(N + 1, dtype=np.int64), np.arange(N, dtype=np.int64), scale,
                       {"duplicate_points": int(np.sum(nn == 0))})


def side_table(kind: str) -> np.ndarray:
    """Local vertex ids of the sides (edges in 2D, faces in 3D) of one cell of ``kind``."""
    from ..volmesh.hexshapes import HEX_FACES
    return {"tri": TRI_EDGES, "quad": QUAD_EDGES, "tet": TET_FACES, "hex": HEX_FACES}[kind]
