"""Anisotropic radial basis functions (ARBF) over meshes and point clouds (document 000, chapter 5).

The ARBF interpolant (000 eq. 5.2.1) is

.. math:: \\Phi(u) = \\sum_{j=1}^{N} \\omega_j\\, \\varphi\\!\\left(\\|u - l_j\\|_L / h\\right),

a sum over *centres* ``l_j`` that are points or line segments, with the
weights from the interpolation conditions ``Φ(l_i) = f_i`` (000 eq. 5.1.2,
``A ω = f``, ``A_ij = φ(‖l_i − l_j‖_L / h)``; no polynomial term, as in 000).

Basis functions (000 Table 5.1), shape parameter ``c``:

=========  ==========================  ================================
name       ``φ(r)``                    note
=========  ==========================  ================================
gaussian   ``exp(−(c r)²)``            larger ``c``: narrower
mq         ``√(r² + c²)``              multiquadric
imq        ``1 / √(r² + c²)``          inverse multiquadric (000 §5.4: ``c = 0.1``)
tps        ``(c r)² ln(c r)``          thin-plate spline, ``φ(0) = 0``
=========  ==========================  ================================

Generalised distance ``‖·‖_L`` (000 §5.2, Fig. 5.2):

* point–point: Euclidean;
* point ``x`` – segment ``(a, b)``, the three cases of 000: 0 when ``x`` is
  on the segment; the perpendicular distance when ``x, a, b`` form an acute
  triangle (the foot of the perpendicular falls inside the segment); and
  ``min(‖x − a‖, ‖x − b‖)`` when the triangle is obtuse at ``a`` or ``b``.
  Together this is the distance to the closest point
  ``a + t (b − a)``, ``t = clamp((x − a)·(b − a) / ‖b − a‖², 0, 1)``;
* segment ``(a, b)`` – segment ``(c, d)``: as 000 defines it,
  ``min(‖a − c‖, ‖a − d‖, ‖b − c‖, ‖b − d‖)`` — the smallest endpoint
  distance, not the true distance between the segments.

**Length scale.** Distances enter ``φ`` divided by ``h``, the mean element
edge length of the mesh (for a point cloud the mean nearest-neighbour
distance), so ``c`` is dimensionless and one value (000 uses ``c = 0.1``)
gives the same pore shapes on a 10 mm tetrahedron and a femur meshed with
8 mm tets. ``h`` is reported as ``length_scale``.

Centres and values (000 §5.3, Fig. 5.3): every mesh vertex gets ``+1``.
In 2D meshes (triangles, quads) the edge midpoints, the face centre and the
segments face centre → edge midpoints get ``−1``; in 3D meshes (tets, hexes)
the face centres, the cell centre and the segments cell centre → face centres
get ``−1`` — 13 centres per tet and 21 per hex; shared vertices, edge
midpoints and face centres are stored once. The pore network is the region
``Φ < iso`` (``−1 < iso < 1``; the pores grow with ``iso``), the material
``Φ ≥ iso``; :class:`ARBFField` returns ``iso − Φ``, porecad's field
convention (negative in the material).

Solvers: :func:`solve_global` (one system over all centres, with a
condition-number check) and :func:`solve_local` (000 Fig. 5.5, femur
variant: per cell a system of the cell's centres plus those of its first
ring of neighbours — the cells sharing a vertex, or a face; points are
assigned to cells by point location, with a k-d tree for points outside).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field as dc_field, replace

import numpy as np
from numba import njit, prange

from ..errors import InputError, ResourceError
from .base import Field

__all__ = ["BASES", "KIND_VERTEX", "KIND_FACE", "KIND_CELL", "KIND_SEGMENT", "KIND_POINT", "Centres",
           "CellCentres", "ARBFField", "basis_function", "point_point_distance", "point_segment_distance",
           "segment_segment_distance", "generalised_distance_matrix", "system_matrix", "mesh_centres",
           "point_cloud_centres", "read_points", "solve_global", "solve_local", "solve", "face_jumps",
           "CellLocator"]

#: basis names in the order of the numba kernels' codes
BASES = ("gaussian", "mq", "imq", "tps")
#: centre kinds
KIND_VERTEX, KIND_FACE, KIND_CELL, KIND_SEGMENT, KIND_POINT = 0, 1, 2, 3, 4
#: default largest condition number (1-norm estimate) accepted for a system
MAX_COND = 1e12
#: largest global system (centres); beyond it use the local solve
MAX_GLOBAL = 8000


def check_basis(basis) -> int:
    """The kernel code of a basis name (one-line error for an unknown one)."""
    name = str(basis).lower()
    if name not in BASES:
        raise InputError(f"unknown basis {basis!r}; use one of {', '.join(BASES)}")
    return BASES.index(name)


def check_shape(shape) -> float:
    try:
        c = float(shape)
    except (TypeError, ValueError):
        raise InputError(f"--shape must be a number, got {shape!r}") from None
    if not math.isfinite(c) or c <= 0:
        raise InputError(f"--shape (the basis shape parameter c) must be positive, got {shape!r}")
    return c


# ---------------------------------------------------------------------------
# basis functions and distances
# ---------------------------------------------------------------------------


def basis_function(basis: str, r, c: float) -> np.ndarray:
    """``φ(r)`` of 000 Table 5.1 (module docstring) with shape parameter ``c``, elementwise."""
    code = check_basis(basis)
    r = np.asarray(r, dtype=np.float64)
    c = float(c)
    if code == 0:
        return np.exp(-(c * r) ** 2)
    if code == 1:
        return np.sqrt(r * r + c * c)
    if code == 2:
        return 1.0 / np.sqrt(r * r + c * c)
    s = c * r
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0, s * s * np.log(np.where(s > 0, s, 1.0)), 0.0)


def point_point_distance(x, y) -> np.ndarray:
    """Euclidean distance ``‖x − y‖`` of ``(..., 3)`` arrays."""
    return np.linalg.norm(np.asarray(x, float) - np.asarray(y, float), axis=-1)


def point_segment_distance(x, a, b) -> np.ndarray:
    """000 §5.2 distance from points ``x`` to segments ``(a, b)`` (broadcast ``(..., 3)``).

    Case 1, ``x`` on the segment: 0. Case 2, acute triangle ``x a b`` (the
    perpendicular foot inside the segment): the perpendicular distance.
    Case 3, obtuse at ``a`` or ``b``: ``min(‖x − a‖, ‖x − b‖)``. This is the
    distance to ``a + t (b − a)`` with ``t`` the projection clamped to
    ``[0, 1]``; a zero-length segment is a point.
    """
    x, a, b = (np.asarray(v, dtype=np.float64) for v in (x, a, b))
    d = b - a
    L2 = np.sum(d * d, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(L2 > 0, np.sum((x - a) * d, axis=-1) / np.where(L2 > 0, L2, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(x - (a + t[..., None] * d), axis=-1)


def segment_segment_distance(a, b, c, d) -> np.ndarray:
    """000 §5.2 distance between segments ``(a, b)`` and ``(c, d)``: the smallest endpoint distance.

    ``min(‖a − c‖, ‖a − d‖, ‖b − c‖, ‖b − d‖)`` — 000's definition (Fig. 5.2d),
    which is not the true distance between two crossing segments.
    """
    a, b, c, d = (np.asarray(v, dtype=np.float64) for v in (a, b, c, d))
    return np.minimum(np.minimum(point_point_distance(a, c), point_point_distance(a, d)),
                      np.minimum(point_point_distance(b, c), point_point_distance(b, d)))


@njit(cache=True, inline="always")
def _phi(r, basis, c):
    if basis == 0:
        s = c * r
        return math.exp(-s * s)
    if basis == 1:
        return math.sqrt(r * r + c * c)
    if basis == 2:
        return 1.0 / math.sqrt(r * r + c * c)
    s = c * r
    if s <= 0.0:
        return 0.0
    return s * s * math.log(s)


@njit(cache=True, inline="always")
def _dist_x(x0, x1, x2, a, b, seg, j):
    """Generalised distance from the point ``x`` to centre ``j``."""
    ax, ay, az = a[j, 0], a[j, 1], a[j, 2]
    if not seg[j]:
        return math.sqrt((x0 - ax) ** 2 + (x1 - ay) ** 2 + (x2 - az) ** 2)
    dx, dy, dz = b[j, 0] - ax, b[j, 1] - ay, b[j, 2] - az
    L2 = dx * dx + dy * dy + dz * dz
    t = 0.0
    if L2 > 0.0:
        t = ((x0 - ax) * dx + (x1 - ay) * dy + (x2 - az) * dz) / L2
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    return math.sqrt((x0 - ax - t * dx) ** 2 + (x1 - ay - t * dy) ** 2 + (x2 - az - t * dz) ** 2)


@njit(cache=True, inline="always")
def _pp(a, i, b, j):
    return math.sqrt((a[i, 0] - b[j, 0]) ** 2 + (a[i, 1] - b[j, 1]) ** 2 + (a[i, 2] - b[j, 2]) ** 2)


@njit(cache=True, inline="always")
def _dist_cc(i, j, a, b, seg):
    """Generalised distance between centres ``i`` and ``j`` (000 §5.2)."""
    if seg[i] and seg[j]:
        return min(min(_pp(a, i, a, j), _pp(a, i, b, j)), min(_pp(b, i, a, j), _pp(b, i, b, j)))
    if seg[j]:
        return _dist_x(a[i, 0], a[i, 1], a[i, 2], a, b, seg, j)
    return _dist_x(a[j, 0], a[j, 1], a[j, 2], a, b, seg, i)


@njit(cache=True, parallel=True)
def _distance_matrix(idx, a, b, seg, out):
    n = idx.shape[0]
    for p in prange(n):
        for q in range(n):
            out[p, q] = _dist_cc(idx[p], idx[q], a, b, seg)


@njit(cache=True, parallel=True)
def _system(idx, a, b, seg, basis, c, inv_h, out):
    n = idx.shape[0]
    for p in prange(n):
        for q in range(p, n):
            v = _phi(_dist_cc(idx[p], idx[q], a, b, seg) * inv_h, basis, c)
            out[p, q] = v
            out[q, p] = v


@njit(cache=True, parallel=True)
def _eval_global(X, a, b, seg, w, basis, c, inv_h, out):
    n = X.shape[0]
    m = w.shape[0]
    for i in prange(n):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        s = 0.0
        for j in range(m):
            s += w[j] * _phi(_dist_x(x0, x1, x2, a, b, seg, j) * inv_h, basis, c)
        out[i] = s


@njit(cache=True, parallel=True)
def _eval_local(X, cell, start, items, w, a, b, seg, basis, c, inv_h, out):
    n = X.shape[0]
    for i in prange(n):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        k = cell[i]
        s = 0.0
        for q in range(start[k], start[k + 1]):
            s += w[q] * _phi(_dist_x(x0, x1, x2, a, b, seg, items[q]) * inv_h, basis, c)
        out[i] = s


# ---------------------------------------------------------------------------
# centres
# ---------------------------------------------------------------------------


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
            raise InputError(f"--jitter must be a length ≥ 0 in mm, got {amount!r}")
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


_TRI_EDGES = np.array([[0, 1], [1, 2], [2, 0]], dtype=np.int64)
_QUAD_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64)
_TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)  # FACE_LOCAL
_TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


def _unique_rows(rows: np.ndarray):
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
    from ..volmesh.hexshapes import HEX_EDGES, HEX_FACES
    kind = str(kind)
    sub = {"tri": (3, _TRI_EDGES), "quad": (4, _QUAD_EDGES), "tet": (4, _TET_FACES), "hex": (8, HEX_FACES)}
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
    C = len(c)
    two_d = kind in ("tri", "quad")
    # vertices
    used = np.unique(c)
    vid = np.full(len(p), -1, np.int64)
    vid[used] = np.arange(len(used))
    # sub-entities: edges (2D) or faces (3D) of every cell
    sub_rows = c[:, parts].reshape(-1, parts.shape[1])  # (C * m, 2 | 3 | 4)
    m = parts.shape[0]
    first, inverse, counts = _unique_rows(sub_rows)
    sub_pts = p[sub_rows[first]].mean(axis=1)
    n_sub = len(first)
    cell_pts = p[c].mean(axis=1)
    nv = len(used)
    off_sub, off_cell, off_seg = nv, nv + n_sub, nv + n_sub + C
    N = off_seg + C * m
    a = np.empty((N, 3))
    a[:nv] = p[used]
    a[off_sub:off_cell] = sub_pts
    a[off_cell:off_seg] = cell_pts
    ends = np.full((N, 2), -1, np.int64)
    ends[off_seg:, 0] = np.repeat(off_cell + np.arange(C), m)
    ends[off_seg:, 1] = off_sub + inverse
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
    # per-cell centres: k vertices, m sub-entities, the cell centre, m segments
    own = np.concatenate([vid[c], off_sub + inverse.reshape(C, m), (off_cell + np.arange(C))[:, None],
                          off_seg + np.arange(C * m).reshape(C, m)], axis=1)
    cell_start = np.arange(C + 1, dtype=np.int64) * own.shape[1]
    # length scale: mean edge length
    edges = {"tri": _TRI_EDGES, "quad": _QUAD_EDGES, "tet": _TET_EDGES, "hex": HEX_EDGES}[kind]
    q = p[c]
    scale = float(np.linalg.norm(q[:, edges[:, 1]] - q[:, edges[:, 0]], axis=2).mean())
    if not scale > 0:
        raise InputError("the mesh has zero-length edges only")
    # jitter constraints: boundary sub-entities stay on their boundary line/plane
    bnd = np.flatnonzero(counts == 1)
    P = np.broadcast_to(np.eye(3), (N, 3, 3)).copy()
    if two_d:
        P[:] = np.diag([1.0, 1.0, 0.0])
        ed = sub_rows[first[bnd]]
        t = p[ed[:, 1]] - p[ed[:, 0]]
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
        P[off_sub + bnd] = np.einsum("ni,nj->nij", t, t)
        P[vid[np.unique(ed)]] = 0.0
    else:
        # orient boundary faces by their owner (local faces are outward for valid cells)
        owner_rows = np.full(n_sub, -1, np.int64)
        owner_rows[inverse] = np.arange(len(inverse))
        bf = sub_rows[owner_rows[bnd]]
        nrm = _normal(p[bf])
        P[off_sub + bnd] = np.eye(3) - np.einsum("ni,nj->nij", nrm, nrm)
        # boundary vertices: in-plane where all their boundary faces are coplanar, else fixed
        flat_v = vid[bf.reshape(-1)]
        flat_n = np.repeat(nrm, bf.shape[1], axis=0)
        order = np.argsort(flat_v, kind="stable")
        sv, sn = flat_v[order], flat_n[order]
        starts = np.flatnonzero(np.r_[True, sv[1:] != sv[:-1]])
        for s0, s1 in zip(starts, np.r_[starts[1:], len(sv)]):
            mean = sn[s0:s1].mean(axis=0)
            mean /= max(np.linalg.norm(mean), 1e-300)
            P[sv[s0]] = np.eye(3) - np.outer(mean, mean) if np.all(sn[s0:s1] @ mean > 1 - 1e-9) else 0.0
    P[off_seg:] = 0.0  # segments follow their ends
    centres = Centres(a, b, segment, values, kinds, ends, P)
    info = {"boundary_entities": int(len(bnd)), "sub_entities": int(n_sub)}
    return CellCentres(centres, kind, p, c, cell_start, np.ascontiguousarray(own.reshape(-1)), scale, info)


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
    if p.suffix.lower() == ".npy":
        try:
            arr = np.load(p, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's input
            raise InputError(f"{p}: cannot read as a .npy array ({type(exc).__name__})") from exc
        arr = np.asarray(arr)
        if not np.issubdtype(arr.dtype, np.number):
            raise InputError(f"{p}: the array is not numeric (dtype {arr.dtype})")
        arr = arr.astype(np.float64)
    else:
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
                raise InputError(f"{p}: line {lineno} is not numeric: {s[:60]!r}") from None
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


# ---------------------------------------------------------------------------
# systems
# ---------------------------------------------------------------------------


def _arrays(centres: Centres):
    return (np.ascontiguousarray(centres.a, dtype=np.float64), np.ascontiguousarray(centres.b, dtype=np.float64),
            np.ascontiguousarray(centres.segment, dtype=np.bool_))


def generalised_distance_matrix(centres: Centres, idx=None) -> np.ndarray:
    """``‖l_i − l_j‖_L`` between the centres ``idx`` (default all), mm."""
    idx = np.arange(centres.n, dtype=np.int64) if idx is None else np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty((len(idx), len(idx)))
    _distance_matrix(idx, *_arrays(centres), out)
    return out


def system_matrix(centres: Centres, basis: str, shape: float, scale: float = 1.0, idx=None) -> np.ndarray:
    """``A_ij = φ(‖l_i − l_j‖_L / h)`` (000 eq. 5.1.2) over the centres ``idx`` (default all)."""
    code, c = check_basis(basis), check_shape(shape)
    idx = np.arange(centres.n, dtype=np.int64) if idx is None else np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty((len(idx), len(idx)))
    _system(idx, *_arrays(centres), code, c, 1.0 / float(scale), out)
    return out


def _lu_solve(A: np.ndarray, f: np.ndarray):
    """Solve ``A w = f`` by LU; returns ``(w, cond)`` with ``cond`` the 1-norm estimate (inf when singular)."""
    from scipy.linalg import LinAlgWarning, lapack, lu_factor, lu_solve
    if not np.isfinite(A).all():
        return None, math.inf
    anorm = float(np.abs(A).sum(axis=0).max())
    if anorm == 0:
        return None, math.inf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LinAlgWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        lu, piv = lu_factor(A, check_finite=False)
        if not np.all(np.abs(np.diag(lu)) > 0):
            return None, math.inf
        rcond, info = lapack.dgecon(lu, anorm, norm="1")
        w = lu_solve((lu, piv), f, check_finite=False)
    cond = 1.0 / rcond if rcond > 0 else math.inf
    if info != 0 or not np.isfinite(w).all():
        return None, math.inf
    return w, cond


def _fmt_cond(c: float) -> str:
    return "infinite" if not math.isfinite(c) else f"{c:.3g}"


def solve_global(centres: Centres, basis: str = "imq", shape: float = 0.1, scale: float = 1.0,
                 max_cond: float = MAX_COND, max_centres: int = MAX_GLOBAL) -> "ARBFField":
    """Weights of all centres from one system ``A ω = f`` (000 eq. 5.1.2, Fig. 5.4).

    The system is factorised by LU and its 1-norm condition number estimated
    (LAPACK ``dgecon``). A singular or ill-conditioned system (condition
    number above ``max_cond``: duplicate centres, a TPS with too few points,
    a very flat basis) raises a one-line :class:`InputError` suggesting the
    local solve or another basis or shape.

    Returns
    -------
    ARBFField
        ``info``: ``solve = "global"``, ``condition_number``,
        ``rms_residual`` (``‖A ω − f‖`` RMS), ``n_centres``.
    """
    code, c = check_basis(basis), check_shape(shape)
    N = centres.n
    if N == 0:
        raise InputError("no RBF centres: the mesh or point cloud is empty")
    if N > max_centres:
        raise ResourceError(f"the global ARBF system would have {N} centres (at most {max_centres}); "
                            "use --local")
    A = system_matrix(centres, BASES[code], c, scale)
    f = np.asarray(centres.values, dtype=np.float64)
    w, cond = _lu_solve(A, f)
    if w is None or cond > max_cond:
        raise InputError(f"the global ARBF system ({N} centres, basis {BASES[code]}, c = {c:g}) is singular or "
                         f"ill-conditioned (condition number {_fmt_cond(cond)}); try --local or another "
                         "--basis or --shape (duplicate centres make it singular)")
    res = float(np.sqrt(np.mean((A @ w - f) ** 2)))
    info = {"solve": "global", "condition_number": float(cond), "rms_residual": res, "n_centres": N}
    return ARBFField(centres, BASES[code], c, scale, weights=w, info=info)


def _rings(cc: CellCentres, ring: str, k_points: int):
    """The cells of each cell's first ring (itself included), as a list of arrays."""
    C = len(cc.cells)
    if cc.kind == "points":
        from scipy.spatial import cKDTree
        k = int(min(max(k_points, 1), C))
        _, nb = cKDTree(cc.points).query(cc.points, k=k)
        nb = np.asarray(nb).reshape(C, k)
        return [np.unique(np.r_[i, nb[i]]) for i in range(C)]
    if ring == "face":
        from ..volmesh.hexshapes import HEX_FACES
        parts = {"tri": _TRI_EDGES, "quad": _QUAD_EDGES, "tet": _TET_FACES, "hex": HEX_FACES}[cc.kind]
        rows = cc.cells[:, parts].reshape(-1, parts.shape[1])
        _, inverse, _ = _unique_rows(rows)
        m = parts.shape[0]
        owner = np.arange(len(rows)) // m
        order = np.argsort(inverse, kind="stable")
        inv_s, own_s = inverse[order], owner[order]
        nb = [[i] for i in range(C)]
        pair = np.flatnonzero(inv_s[1:] == inv_s[:-1])
        for i in pair:
            a_, b_ = own_s[i], own_s[i + 1]
            nb[a_].append(b_)
            nb[b_].append(a_)
        return [np.unique(x) for x in nb]
    if ring != "vertex":
        raise InputError(f"unknown neighbour ring {ring!r}; use vertex or face")
    flat = cc.cells.reshape(-1)
    owner = np.repeat(np.arange(C), cc.cells.shape[1])
    order = np.argsort(flat, kind="stable")
    fv, fo = flat[order], owner[order]
    start = np.searchsorted(fv, np.arange(len(cc.points) + 1))
    return [np.unique(np.concatenate([fo[start[v]:start[v + 1]] for v in cc.cells[i]])) for i in range(C)]


def solve_local(cc: CellCentres, basis: str = "imq", shape: float = 0.1, ring: str = "vertex",
                k_points: int = 27, max_cond: float = MAX_COND, progress=None, only=None) -> "ARBFField":
    """Per-cell weights (000 Fig. 5.5, femur variant): a small system per cell.

    Cell ``i``'s system holds the centres of ``i`` and of its first ring of
    neighbours — the cells sharing a vertex with it (``ring="vertex"``) or a
    face (``"face"``); for a point cloud the ``k_points`` nearest points
    (k-d tree). A point is evaluated with the weights of the cell that
    contains it (tet point location; hexes through their six tets); points
    outside every cell use the cell with the nearest centre
    (``scipy.spatial.cKDTree``). Values are continuous inside a cell and
    jump slightly across cell faces (the neighbouring systems differ).

    ``only`` (cell indices) solves those cells' systems only; the others
    get no centres (``Φ = 0`` there) — for sampling a few cells cheaply.

    Returns
    -------
    ARBFField
        ``info``: ``solve = "local"``, ``cells``, ``ring``, ``patch_size``
        (mean, max centres per system), ``condition_number`` (largest),
        ``rms_residual`` (over all systems).
    """
    code, c = check_basis(basis), check_shape(shape)
    cen = cc.centres
    if cen.n == 0 or len(cc.cells) == 0:
        raise InputError("no RBF centres: the mesh or point cloud is empty")
    rings = _rings(cc, ring, k_points)
    a, b, seg = _arrays(cen)
    f_all = np.asarray(cen.values, dtype=np.float64)
    inv_h = 1.0 / float(cc.scale)
    C = len(cc.cells)
    starts = np.zeros(C + 1, np.int64)
    items_l, w_l = [], []
    cond_max, sq, n_eq, sizes = 0.0, 0.0, 0, np.zeros(C, np.int64)
    todo = np.zeros(C, bool)
    todo[np.arange(C) if only is None else np.asarray(only, dtype=np.int64)] = True
    for i in range(C):
        if not todo[i]:
            starts[i + 1] = starts[i]
            continue
        idx = np.unique(np.concatenate([cc.own(j) for j in rings[i]]))
        A = np.empty((len(idx), len(idx)))
        _system(idx, a, b, seg, code, c, inv_h, A)
        f = f_all[idx]
        w, cond = _lu_solve(A, f)
        if w is None or cond > max_cond:
            what = "point" if cc.kind == "points" else "cell"
            raise InputError(f"the local ARBF system of {what} {i} ({len(idx)} centres, basis {BASES[code]}, "
                             f"c = {c:g}) is singular or ill-conditioned (condition number {_fmt_cond(cond)}); "
                             "try another --basis or --shape (duplicate centres make it singular)")
        cond_max = max(cond_max, cond)
        r = A @ w - f
        sq += float(r @ r)
        n_eq += len(idx)
        items_l.append(idx)
        w_l.append(w)
        sizes[i] = len(idx)
        starts[i + 1] = starts[i] + len(idx)
        if progress is not None and (i % 64 == 0 or i == C - 1):
            progress(i + 1, C)
    info = {"solve": "local", "ring": "nearest points" if cc.kind == "points" else ring, "cells": C,
            "patch_size": {"mean": float(sizes[todo].mean()), "max": int(sizes.max())},
            "condition_number": float(cond_max), "rms_residual": float(np.sqrt(sq / max(n_eq, 1))),
            "n_centres": cen.n}
    return ARBFField(cen, BASES[code], c, cc.scale, weights=np.concatenate(w_l),
                     patches=(starts, np.concatenate(items_l)), locator=CellLocator(cc), info=info)


def solve(cc: CellCentres, basis: str = "imq", shape: float = 0.1, local: bool = False, **kw) -> "ARBFField":
    """:func:`solve_local` or :func:`solve_global` (with the mesh's length scale)."""
    if local:
        return solve_local(cc, basis, shape, **kw)
    kw.pop("ring", None)
    kw.pop("k_points", None)
    kw.pop("progress", None)
    return solve_global(cc.centres, basis, shape, cc.scale, **kw)


def face_jumps(field: "ARBFField", cc: CellCentres, max_faces: int = 2000, seed: int = 0):
    """How far a local solve is from continuous: ``Φ`` from both cells at points of shared faces.

    At the centroid of up to ``max_faces`` random interior faces (edges in
    2D) and the midpoints between it and the face's corners, ``Φ`` is
    evaluated with the weights of each of the two cells; returns the RMS and
    largest difference (None for a global solve or a point cloud).
    """
    from ..volmesh.hexshapes import HEX_FACES
    if field.patches is None or cc.kind == "points":
        return None
    parts = {"tri": _TRI_EDGES, "quad": _QUAD_EDGES, "tet": _TET_FACES, "hex": HEX_FACES}[cc.kind]
    rows = cc.cells[:, parts].reshape(-1, parts.shape[1])
    _, inverse, counts = _unique_rows(rows)
    order = np.argsort(inverse, kind="stable")
    inv_s = inverse[order]
    pair = np.flatnonzero(inv_s[1:] == inv_s[:-1])
    if len(pair) == 0:
        return {"faces": 0, "rms": 0.0, "max": 0.0}
    rng = np.random.default_rng(seed)
    if len(pair) > max_faces:
        pair = np.sort(rng.choice(pair, size=max_faces, replace=False))
    r1, r2 = order[pair], order[pair + 1]
    c1, c2 = r1 // parts.shape[0], r2 // parts.shape[0]
    corners = cc.points[rows[r1]]  # (F, k, 3)
    cen = corners.mean(axis=1, keepdims=True)
    pts = np.concatenate([cen, 0.5 * (cen + corners)], axis=1)  # (F, 1 + k, 3)
    m = pts.shape[1]
    X = pts.reshape(-1, 3)
    d = field.phi_in_cells(X, np.repeat(c1, m)) - field.phi_in_cells(X, np.repeat(c2, m))
    return {"faces": int(len(pair)), "rms": float(np.sqrt(np.mean(d * d))), "max": float(np.abs(d).max())}


class CellLocator:
    """The cell holding each point: tet location (hexes through their six tets), k-d tree outside.

    For triangle and quad meshes and point clouds every point goes to the
    cell (point) with the nearest centroid (k-d tree).
    """

    def __init__(self, cc: CellCentres):
        from scipy.spatial import cKDTree
        self.kind = cc.kind
        centroid = cc.points[cc.cells].mean(axis=1)
        self.tree = cKDTree(centroid)
        self.tets = None
        if cc.kind == "tet":
            from ..volmesh import TetLocator
            self.tets, self.per = TetLocator(cc.points, cc.cells), 1
        elif cc.kind == "hex":
            from ..volmesh import TetLocator
            from ..volmesh.hexshapes import HEX_TETS
            t = cc.cells[:, HEX_TETS].reshape(-1, 4)
            self.tets, self.per = TetLocator(cc.points, t), len(HEX_TETS)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float64)
        if self.tets is None:
            return np.asarray(self.tree.query(x)[1], dtype=np.int64)
        t, _ = self.tets.locate(x, tol=1e-9)
        cell = np.where(t >= 0, t // self.per, -1).astype(np.int64)
        out = cell < 0
        if out.any():
            cell[out] = self.tree.query(x[out])[1]
        return cell


# ---------------------------------------------------------------------------
# the field
# ---------------------------------------------------------------------------


class ARBFField(Field):
    """The ARBF interpolant ``Φ`` (000 eq. 5.2.1) as a porecad field ``iso − Φ`` (negative in the material).

    Build with :func:`solve_global` or :func:`solve_local`. :meth:`phi`
    gives ``Φ`` itself; :meth:`evaluate` and :meth:`sample_grid` give
    ``iso − Φ``, so the material ``Φ ≥ iso`` is the field's inside and the
    pores ``Φ < iso`` its outside. Evaluation is a numba kernel, parallel over
    points (``O(points × centres)`` globally, ``O(points × patch)`` locally).
    """

    def __init__(self, centres: Centres, basis: str, shape: float, scale: float, weights, iso: float = 0.0,
                 patches=None, locator=None, info=None):
        self.centres = centres
        self.basis = BASES[check_basis(basis)]
        self.code = check_basis(basis)
        self.shape = check_shape(shape)
        self.scale = float(scale)
        self.weights = np.ascontiguousarray(weights, dtype=np.float64)
        self.iso = float(iso)
        self.patches = patches
        self.locator = locator
        self.info = dict(info or {})
        self._arr = _arrays(centres)

    @property
    def local(self) -> bool:
        return self.patches is not None

    def with_iso(self, iso: float) -> "ARBFField":
        """The same interpolant with another iso-value."""
        out = ARBFField.__new__(ARBFField)
        out.__dict__.update(self.__dict__)
        out.iso = float(iso)
        return out

    def phi(self, points, chunk: int = 1 << 18) -> np.ndarray:
        """``Φ`` at ``(N, 3)`` points (float64)."""
        X = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        out = np.empty(len(X))
        a, b, seg = self._arr
        inv_h = 1.0 / self.scale
        for s in range(0, len(X), chunk):
            x = X[s:s + chunk]
            o = out[s:s + chunk]
            if self.patches is None:
                _eval_global(x, a, b, seg, self.weights, self.code, self.shape, inv_h, o)
            else:
                cell = self.locator(x)
                _eval_local(x, cell, self.patches[0], self.patches[1], self.weights, a, b, seg, self.code,
                            self.shape, inv_h, o)
        return out

    def phi_in_cells(self, points, cells) -> np.ndarray:
        """``Φ`` at points with the weights of the given cells (local solve), e.g. both sides of a face."""
        if self.patches is None:
            return self.phi(points)
        X = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        out = np.empty(len(X))
        _eval_local(X, np.ascontiguousarray(cells, dtype=np.int64), self.patches[0], self.patches[1],
                    self.weights, *self._arr, self.code, self.shape, 1.0 / self.scale, out)
        return out

    def evaluate(self, points):
        return self.iso - self.phi(points)

    def phi_grid(self, xs, ys, zs) -> np.ndarray:
        """``Φ`` on the tensor grid ``zs × ys × xs`` as ``(len(zs), len(ys), len(xs))`` float32."""
        xs, ys, zs = (np.asarray(v, dtype=np.float64) for v in (xs, ys, zs))
        out = np.empty((len(zs), len(ys), len(xs)), dtype=np.float32)
        gx, gy = np.meshgrid(xs, ys)
        plane = gx.size
        per = max(1, (1 << 18) // max(plane, 1))
        for k0 in range(0, len(zs), per):
            kk = zs[k0:k0 + per]
            pts = np.empty((len(kk) * plane, 3))
            pts[:, 0] = np.tile(gx.ravel(), len(kk))
            pts[:, 1] = np.tile(gy.ravel(), len(kk))
            pts[:, 2] = np.repeat(kk, plane)
            out[k0:k0 + len(kk)] = self.phi(pts).reshape(len(kk), len(ys), len(xs))
        return out

    def sample_grid(self, xs, ys, zs) -> np.ndarray:
        return (np.float32(self.iso) - self.phi_grid(xs, ys, zs)).astype(np.float32)
