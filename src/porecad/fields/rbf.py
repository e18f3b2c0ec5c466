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
The compiled kernels they run are in :mod:`porecad.fields.rbf_kernels`.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..errors import InputError, ResourceError
from .base import Field
from .rbf_kernels import eval_global, eval_local, fill_distance_matrix, fill_system

__all__ = ["BASES", "KIND_VERTEX", "KIND_FACE", "KIND_CELL", "KIND_SEGMENT", "KIND_POINT", "Centres",
           "CellCentres", "ARBFField", "basis_function", "point_point_distance", "point_segment_distance",
           "segment_segment_distance", "generalised_distance_matrix", "system_matrix", "mesh_centres",
           "point_cloud_centres", "read_points", "solve_global", "solve_local", "solve", "face_jumps",
           "CellLocator"]

#: basis names in the order of the numba kernels' codes
BASES = ("gaussian", "mq", "imq", "tps")
#: centre kinds
from .rbf_centres import (KIND_CELL, KIND_FACE, KIND_POINT, KIND_SEGMENT, KIND_VERTEX,  # noqa: E402,F401
                          CellCentres, Centres, mesh_centres, point_cloud_centres, read_points, side_table,
                          unique_rows)
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
        raise InputError(f"`shape` must be a number, got {shape!r}") from None
    if not math.isfinite(c) or c <= 0:
        raise InputError(f"`shape` must be positive (the basis shape parameter c), got {shape!r}")
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
    fill_distance_matrix(idx, *_arrays(centres), out)
    return out


def system_matrix(centres: Centres, basis: str, shape: float, scale: float = 1.0, idx=None) -> np.ndarray:
    """``A_ij = φ(‖l_i − l_j‖_L / h)`` (000 eq. 5.1.2) over the centres ``idx`` (default all)."""
    code, c = check_basis(basis), check_shape(shape)
    idx = np.arange(centres.n, dtype=np.int64) if idx is None else np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty((len(idx), len(idx)))
    fill_system(idx, *_arrays(centres), code, c, 1.0 / float(scale), out)
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
                            "fit it locally (`local`)")
    A = system_matrix(centres, BASES[code], c, scale)
    f = np.asarray(centres.values, dtype=np.float64)
    w, cond = _lu_solve(A, f)
    if w is None or cond > max_cond:
        raise InputError(f"the global ARBF system ({N} centres, basis {BASES[code]}, c = {c:g}) is singular or "
                         f"ill-conditioned (condition number {_fmt_cond(cond)}); try `local` or another "
                         "`basis` or `shape` (duplicate centres make it singular)")
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
        parts = side_table(cc.kind)
        rows = cc.cells[:, parts].reshape(-1, parts.shape[1])
        _, inverse, _ = unique_rows(rows)
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
        fill_system(idx, a, b, seg, code, c, inv_h, A)
        f = f_all[idx]
        w, cond = _lu_solve(A, f)
        if w is None or cond > max_cond:
            what = "point" if cc.kind == "points" else "cell"
            raise InputError(f"the local ARBF system of {what} {i} ({len(idx)} centres, basis {BASES[code]}, "
                             f"c = {c:g}) is singular or ill-conditioned (condition number {_fmt_cond(cond)}); "
                             "try another `basis` or `shape` (duplicate centres make it singular)")
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
    if field.patches is None or cc.kind == "points":
        return None
    parts = side_table(cc.kind)
    rows = cc.cells[:, parts].reshape(-1, parts.shape[1])
    _, inverse, counts = unique_rows(rows)
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
                eval_global(x, a, b, seg, self.weights, self.code, self.shape, inv_h, o)
            else:
                cell = self.locator(x)
                eval_local(x, cell, self.patches[0], self.patches[1], self.weights, a, b, seg, self.code,
                            self.shape, inv_h, o)
        return out

    def phi_in_cells(self, points, cells) -> np.ndarray:
        """``Φ`` at points with the weights of the given cells (local solve), e.g. both sides of a face."""
        if self.patches is None:
            return self.phi(points)
        X = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        out = np.empty(len(X))
        eval_local(X, np.ascontiguousarray(cells, dtype=np.int64), self.patches[0], self.patches[1],
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
