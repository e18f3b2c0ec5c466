"""TIS over a tetrahedral mesh, polygonised per tetrahedron in barycentric space.

Document 002 (§3) evaluates a periodic implicit function in every
tetrahedron in the tetrahedron's own coordinates ``θ = 2πλ·b`` (``b`` the
barycentric coordinates; :mod:`porecad.fields.tis`) and extracts the surface by
marching cubes. Here every tetrahedron is sampled on its barycentric lattice
``b = w / n`` (``w`` integer, ``Σ w = n``) and polygonised by marching
tetrahedra over its Freudenthal subdivision (:mod:`porecad.maps._tet_lattice`):

* The lattice of a face is the same from both of its tetrahedra (the
  subdivision follows the global vertex ids), so the two sides produce the
  same crossing vertices on it: the surface is welded, not stitched.
* A lattice point shared by several tetrahedra takes its value from the first
  of them, so the piecewise-linear field is C⁰ by construction. For P and D
  (symmetric in α…δ) and for G on a rainbow-coloured mesh (every tet puts the
  same vertex colour in the same coordinate) the TIS values of the two sides
  agree exactly on a shared face (002 §3.2); ``face_jump`` measures it.
* The material is closed on the boundary faces of the mesh by marching
  triangles, so the result is one closed, outward-oriented solid.

Slots: the cyclic G of 002 is not symmetric in its four coordinates, so which
vertex feeds which coordinate matters across a face. With a vertex colouring
in four colours in which every tetrahedron is rainbow
(:func:`porecad.volmesh.rainbow_coloring`; BCC lattice meshes always have one),
the vertex of colour k feeds coordinate k in every tetrahedron and G is C⁰
like P and D. Without one the sorted local order is used and ``face_jump``
reports how far the two sides of the worst face disagree.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, ResourceError
from ..fields.tis import TYPE_CODES, check_lambda, check_type, relative_threshold
from . import _tet_lattice as K

_FACE_OPP = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], np.int64)
_PAIRS = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], np.int64)


@dataclass
class TISLatticeResult:
    """A TIS solid over a tet mesh and what was measured on the way."""

    vertices: np.ndarray
    faces: np.ndarray
    threshold: float
    value_range: tuple
    sample_porosity: float
    lattice_points: int
    subdivisions: int
    slots: str
    face_jump: float
    n_cap_faces: int
    times: dict = field(default_factory=dict)
    #: (V,) bool: vertices on the body's cut surface (with ``clip``)
    cut_vertices: np.ndarray | None = None
    #: the body alone on the same lattice, ``(vertices, faces)`` (with ``clip``): the porosity's domain
    domain: tuple | None = None


def _unique_rows(rows):
    """Ids of the rows of a sorted (N, k) int array among its unique rows."""
    uniq, inv, cnt = np.unique(rows, axis=0, return_inverse=True, return_counts=True)
    return uniq, inv.reshape(-1), cnt


def tet_topology(tets):
    """Sorted tets, their edge ids (T, 6), face ids (T, 4) and the boundary faces.

    Returns
    -------
    tv : (T, 4) int64
        Each tetrahedron's global vertex ids in increasing order.
    order : (T, 4) int64
        ``tv = take_along_axis(tets, order)``.
    edge_ids, face_ids : (T, 6), (T, 4) int64
        Edge ``(p, q)`` in the order of ``_PAIRS``; face opposite sorted local vertex k.
    n_edges, n_faces : int
    boundary : (B, 2) int64
        (tet, sorted local vertex opposite the boundary face).
    """
    tets = np.asarray(tets, dtype=np.int64)
    order = np.argsort(tets, axis=1, kind="stable")
    tv = np.take_along_axis(tets, order, axis=1)
    e = tv[:, _PAIRS].reshape(-1, 2)
    ue, einv, _ = _unique_rows(e)
    f = tv[:, _FACE_OPP].reshape(-1, 3)
    uf, finv, fcnt = _unique_rows(f)
    if fcnt.max(initial=0) > 2:
        bad = int(np.flatnonzero(fcnt > 2)[0])
        raise InputError(f"tet mesh is not conforming: face {tuple(int(x) for x in uf[bad])} "
                         f"is shared by {int(fcnt[bad])} tetrahedra")
    face_ids = finv.reshape(-1, 4)
    on_boundary = fcnt[face_ids] == 1
    bt, bk = np.nonzero(on_boundary)
    return (tv, order, einv.reshape(-1, 6), face_ids, len(ue), len(uf),
            np.stack([bt, bk], axis=1).astype(np.int64))


def stored_slots(tets, kind, colors=None):
    """TIS coordinate (0..3) of each stored vertex of each tet, and a label of how it was chosen.

    With a rainbow colouring (given, or found for G) the vertex of colour k
    feeds coordinate k; otherwise a vertex feeds the coordinate of its rank
    among the tet's global ids (P and D do not care which).
    """
    tets = np.asarray(tets, np.int64)
    if colors is None and kind == "G":
        from ..volmesh import rainbow_coloring
        colors = rainbow_coloring(tets)
    if colors is not None:
        c = np.asarray(colors, dtype=np.int64)[tets]
        if np.any(np.sort(c, axis=1) != np.arange(4)):
            raise InputError("vertex colours must give every tetrahedron the four colours 0..3")
        return c, "rainbow colouring"
    return np.argsort(np.argsort(tets, axis=1, kind="stable"), axis=1).astype(np.int64), "sorted vertex ids"


def _lambda_per_vertex(lam, T, slots):
    """λ per tet and sorted local vertex from a scalar, (4,) per coordinate, (T,) or (T, 4)."""
    a = check_lambda(lam)
    if a.ndim == 0 or a.size == 1:
        return np.full((T, 4), float(a.reshape(-1)[0]))
    if a.shape == (4,) and T != 4:
        return a[slots]
    if a.shape == (T,):
        return np.repeat(a[:, None], 4, axis=1)
    if a.shape == (T, 4):
        return np.take_along_axis(a, slots, axis=1)
    raise InputError(f"lambda must be a number, 4 values (one per coordinate) or one per tetrahedron; "
                     f"got shape {a.shape}")


def _owners(tv, edge_ids, face_ids, V, E, F, n):
    """The owner tet of every lattice point: the lowest-index tet containing it."""
    T = len(tv)
    tid = np.arange(T, dtype=np.int64)
    big = np.int64(T)
    vo = np.full(V, big)
    np.minimum.at(vo, tv.reshape(-1), np.repeat(tid, 4))
    eo = np.full(E, big)
    np.minimum.at(eo, edge_ids.reshape(-1), np.repeat(tid, 6))
    fo = np.full(F, big)
    np.minimum.at(fo, face_ids.reshape(-1), np.repeat(tid, 4))
    nf = (n - 1) * (n - 2) // 2
    ni = (n - 1) * (n - 2) * (n - 3) // 6
    owner = np.concatenate([vo, np.repeat(eo, n - 1), np.repeat(fo, nf), np.repeat(tid, ni)])
    unused = owner == big
    return owner, unused


def estimate_lattice(n_tets, n_edges, n_faces, n_vertices, n):
    """Lattice points and small tetrahedra of an n-subdivision (for memory checks)."""
    pts = (n_vertices + n_edges * (n - 1) + n_faces * (n - 1) * (n - 2) // 2
           + n_tets * (n - 1) * (n - 2) * (n - 3) // 6)
    return int(pts), int(n_tets) * n ** 3


def tis_lattice_mesh(points, tets, kind="P", lam=1.0, *, threshold=None, relative=None, subdivisions=16,
                     structure="pore", colors=None, memory_limit=None, clip=None):
    """Polygonise a TIS over a positively oriented tet mesh, one closed solid.

    Parameters
    ----------
    points : (V, 3) float
    tets : (T, 4) int
        Conforming, positively oriented (see :func:`porecad.volmesh.check_tet_mesh`).
    kind : {'P', 'D', 'G'}
    lam : float or array
        λ of 002 eq. 2: periods along each coordinate (scalar, (4,), (T,), (T, 4)).
    threshold, relative : float
        Exactly one: the absolute level C, or the relative threshold R of 002
        eq. 7, ``C = min + R (max − min)`` over the lattice values.
    subdivisions : int
        n: lattice points per tet edge minus one (n³ small tets per tet).
    structure : {'pore', 'rod'}
        Material where φ ≥ C (pore: void fraction grows with C, as in 002
        Table 3) or where φ ≤ C (rod).
    colors : (V,) int, optional
        A rainbow vertex colouring fixing the coordinate of each vertex.
    clip : callable, optional
        ``clip(points (m, 3)) -> (m,)`` signed distance to a body (negative
        inside, e.g. :class:`porecad.bodies.MeshBody`, exact to a few lattice
        spacings). The solid is cut to the body in field space: the
        marched field is ``min(φ − C, −k d)`` (:func:`_clip_values`), so the
        cut surface is made of marching-tetrahedra triangles like the rest
        and cannot intersect it (a mesh Boolean leaves slivers where the
        body's triangles graze the scaffold's). The body alone on the same
        lattice is marched too (``domain``).

    Returns
    -------
    TISLatticeResult
    """
    kind, n = _check_tis_arguments(kind, structure, threshold, relative, subdivisions)
    P = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    times = {}
    lat = _sample_lattice(P, tets, kind, lam, colors, n, memory_limit, times)
    lv = _levels(lat, structure, threshold, relative, clip)
    verts, faces, n_caps, on_cut, domain = _march_solid(lat, lv, P, n, clip, times)
    jump = _face_jump(lat["tv"], lat["slots"], lat["lam_v"], kind, lat["face_ids"]) \
        if kind == "G" and lat["slot_how"] != "rainbow colouring" else 0.0
    return TISLatticeResult(verts, faces, lv["C"], (lv["lo"], lv["hi"]), lv["sample_porosity"], lat["n_pts"], n,
                            lat["slot_how"], jump, n_caps, times, cut_vertices=on_cut, domain=domain)


def _check_tis_arguments(kind, structure, threshold, relative, subdivisions):
    """The checked TIS type and the subdivisions per tet edge ``n``; raises InputError on a bad argument."""
    kind = check_type(kind)
    if structure not in ("pore", "rod"):
        raise InputError(f"TIS structures are 'pore' and 'rod', got {structure!r}")
    if (threshold is None) == (relative is None):
        raise InputError("give exactly one of a threshold C or a relative threshold R")
    n = int(subdivisions)
    if n < 2 or n != subdivisions:
        raise InputError(f"subdivisions per tet edge must be an integer ≥ 2, got {subdivisions!r}")
    return kind, n


def _sample_lattice(P, tets, kind, lam, colors, n, memory_limit, times):
    """The field sampled on the lattice of every tet (after a memory check that raises ResourceError).

    Takes the mesh, the TIS type and λ, the colouring and ``n``; records ``times["sample"]``. Returns a
    dict: the topology (``tv``, ``edge_ids``, ``face_ids``, ``E``, ``F``, ``boundary``), ``slots``,
    ``slot_how``, ``lam_v``, ``tables``, ``n_pts``, the lattice ``vals`` and ``pos`` (NaN and 0 at
    unused mesh vertices) and the ``unused`` mask.
    """
    T = len(tets)
    t0 = time.perf_counter()
    tv, order, edge_ids, face_ids, E, F, boundary = tet_topology(tets)
    n_pts, n_small = estimate_lattice(T, E, F, len(P), n)
    need = n_pts * (8 + 24 + 8 + 8) + T * (n + 1) * (n + 2) * (n + 3) // 6 * 8 + n_small * 0.6 * 48
    if memory_limit is None:
        import psutil
        memory_limit = int(0.8 * psutil.virtual_memory().available)
    if need > memory_limit:
        raise ResourceError(f"{T} tetrahedra at {n} subdivisions need about {need / 2**30:.1f} GiB "
                            f"({n_pts:,} lattice points); {memory_limit / 2**30:.1f} GiB available: "
                            f"lower the resolution")
    slots, slot_how = stored_slots(tets, kind, colors)
    slots = np.take_along_axis(slots, order, axis=1)  # per sorted local vertex
    lam_v = _lambda_per_vertex(lam, T, slots)
    tables = K.lattice_tables(tv, edge_ids, face_ids, n, len(P), E, F)
    owner, unused = _owners(tv, edge_ids, face_ids, len(P), E, F, n)
    vals = np.empty(n_pts)
    pos = np.empty((n_pts, 3))
    K.lattice_values(P, tv, slots, lam_v, tables, n, TYPE_CODES[kind], owner, vals, pos)
    times["sample"] = time.perf_counter() - t0
    vals[unused] = np.nan  # mesh vertices that no tet references
    pos[unused] = 0.0
    return {"tv": tv, "edge_ids": edge_ids, "face_ids": face_ids, "E": E, "F": F, "boundary": boundary,
            "slots": slots, "slot_how": slot_how, "lam_v": lam_v, "tables": tables, "n_pts": n_pts,
            "vals": vals, "pos": pos, "unused": unused}


def _levels(lat, structure, threshold, relative, clip):
    """The level the solid is marched at, from the sampled lattice ``lat`` (:func:`_sample_lattice`).

    Returns a dict: ``C``, the value range ``lo``, ``hi``, ``sample_porosity``, the marched ``field_vals``
    (φ for pores, −φ for rods) and their ``level``, and ``eps`` (how close to the level a sample is moved
    off it). Raises InputError on a non-finite threshold.
    """
    vals = lat["vals"]
    used_vals = vals[~lat["unused"]]
    lo, hi = float(used_vals.min()), float(used_vals.max())
    C = relative_threshold(used_vals, relative) if relative is not None else float(threshold)
    if not np.isfinite(C):
        raise InputError(f"threshold must be a finite number, got {threshold!r}")
    field_vals = vals if structure == "pore" else -vals
    level = C if structure == "pore" else -C
    # samples on the level (or within 1e-3 of the values' spread: a crossing that close to a lattice point
    # would fall on another edge's crossing once written in single precision) count as material, moved off it
    eps = (1e-3 if clip is not None else 1e-9) * max(hi - lo, 1e-12)
    sample_porosity = float(np.mean(used_vals < C) if structure == "pore" else np.mean(used_vals > C))
    return {"C": C, "lo": lo, "hi": hi, "sample_porosity": sample_porosity, "field_vals": field_vals,
            "level": level, "eps": eps}


def _tet_signs(P, tv):
    """Orientation sign (+1/−1) of every tet of the sorted vertex table ``tv``; raises InputError on a flat tet."""
    tet_sign = np.sign(np.einsum("ij,ij->i", np.cross(P[tv[:, 1]] - P[tv[:, 0]], P[tv[:, 2]] - P[tv[:, 0]]),
                                 P[tv[:, 3]] - P[tv[:, 0]])).astype(np.int64)
    if np.any(tet_sign == 0):
        bad = int(np.flatnonzero(tet_sign == 0)[0])
        raise InputError(f"tet {bad} has zero volume")
    return tet_sign


def _march_solid(lat, lv, P, n, clip, times):
    """March the solid (cut to the body by ``clip``) over the lattice ``lat`` at the levels ``lv``.

    Records ``times["clip"]``, ``["march"]``, ``["domain"]``; drops ``lat["tables"]`` when done. Returns
    the vertices, faces, number of caps, the cut vertices (or None) and the body's own ``domain`` mesh
    ``(vertices, faces)`` (or None).
    """
    tv, pos, level, eps = lat["tv"], lat["pos"], lv["level"], lv["eps"]
    work = lv["field_vals"].copy()
    cut = None
    if clip is not None:
        t_c = time.perf_counter()
        cut = _clip_values(clip, pos, lat["unused"], work, level, P, tv, n)
        work = np.minimum(work, cut)
        times["clip"] = time.perf_counter() - t_c
    t1 = time.perf_counter()
    tet_sign = _tet_signs(P, tv)
    topo = (P, tv, lat["edge_ids"], lat["face_ids"], lat["E"], lat["F"], lat["boundary"])

    def surface(w, tabs):
        w = w.copy()
        w[np.abs(w - level) < eps] = level + eps
        return _march_surface(tabs, n, tet_sign, w, level, pos, topo)

    verts, faces, n_caps, ends = surface(work, lat["tables"])
    times["march"] = time.perf_counter() - t1
    on_cut, domain = None, None
    if cut is not None:
        t2 = time.perf_counter()
        active = cut < lv["field_vals"]  # lattice points where the body, not the structure, decides
        on_cut = active[ends[:, 0]] | active[ends[:, 1]]
        # the body alone on the same lattice: the domain the porosity refers to
        dv, df, _, _ = surface(cut, lat["tables"])
        domain = (dv, df)
        times["domain"] = time.perf_counter() - t2
    del lat["tables"]
    return verts, faces, n_caps, on_cut, domain


def _clip_values(clip, pos, unused, work, level, P, tv, n):
    """``level − k d(x)`` at every lattice point: at least ``level`` where ``x`` is inside the body.

    ``min(work, level − k d)`` is the R-function intersection of the
    material ``{work ≥ level}`` with the body ``{d ≤ 0}`` (Ricci 1973). ``k``
    makes the body term win one lattice spacing ``δ`` inside the body
    against every structure value: ``k = 2 max |work − level| / δ``, so away
    from the body's surface the structure is interpolated as without the
    cut. ``d`` must be exact to at least ``δ`` near the surface.
    """
    d = np.full(len(work), np.inf)
    used = np.flatnonzero(~unused)
    d[used] = np.asarray(clip(pos[used]), np.float64).reshape(-1)
    X = P[tv]
    edge = float(np.mean(np.linalg.norm(X[:, _PAIRS[:, 0]] - X[:, _PAIRS[:, 1]], axis=2)))
    delta = edge / n
    top = float(np.nanmax(np.abs(work[used] - level)))
    k = 2.0 * max(top, 1e-12) / delta
    out = level - k * d
    out[unused] = np.nan
    return out


def _march_surface(tables, n, tet_sign, work, level, pos, topo):
    """Marching tetrahedra over the lattice, caps on the mesh boundary, welded crossing vertices.

    Returns ``(vertices, faces, n_cap_faces, ends)``: ``ends[i]`` are the two
    lattice points whose edge vertex ``i`` lies on.
    """
    P, tv, edge_ids, face_ids, E, F, boundary = topo
    n_pts = len(work)
    keys = K.march_tets(tables, n, tet_sign, work, level, K.CASE_NTRI, K.CASE_EDGES)
    caps = K.cap_faces(P, tv, edge_ids, face_ids, n, len(P), E, F, boundary[:, 0].copy(),
                       boundary[:, 1].copy(), work, level)
    allk = np.concatenate([keys, caps]).reshape(-1, 2)
    code = allk[:, 0] * np.int64(n_pts) + allk[:, 1]
    ucode, inv = np.unique(code, return_inverse=True)
    a = ucode // n_pts
    b = ucode % n_pts
    va, vb = work[a], work[b]
    same = a == b
    denom = np.where(same, 1.0, vb - va)
    tpar = np.where(same, 0.0, (level - va) / denom)
    verts = pos[a] + tpar[:, None] * (pos[b] - pos[a])
    return verts, inv.reshape(-1, 3).astype(np.int64), len(caps), np.stack([a, b], axis=1)


def _face_jump(tv, slots, lam_v, kind, face_ids, samples=7):
    """Largest |φ₁ − φ₂| between the two tets of any shared face (sampled on the face)."""
    from ..fields.tis import tis_value

    F = int(face_ids.max()) + 1
    first = np.full(F, -1, np.int64)
    firstk = np.full(F, -1, np.int64)
    worst = 0.0
    # barycentric samples on a face
    g = [(i, j, samples - i - j) for i in range(samples + 1) for j in range(samples + 1 - i)]
    wf = np.array(g, np.float64) / samples
    for t in range(len(tv)):
        for k in range(4):
            f = face_ids[t, k]
            if first[f] < 0:
                first[f], firstk[f] = t, k
                continue
            vals = []
            for tt, kk in ((first[f], firstk[f]), (t, k)):
                loc = _FACE_OPP[kk]
                # face vertices in increasing global id are the same for both tets
                w = np.zeros((len(wf), 4))
                w[:, loc] = wf
                theta = np.zeros_like(w)
                theta[:, slots[tt]] = 2 * np.pi * lam_v[tt] * w
                vals.append(tis_value(theta, kind))
            worst = max(worst, float(np.max(np.abs(vals[0] - vals[1]))))
    return worst


def tis_field_values(locator, slots, lam, kind, pts):
    """TIS values at points: ``(values, inside)``; NaN outside the tet mesh.

    ``locator``: a :class:`porecad.volmesh.TetLocator`; ``slots[t, i]`` /
    ``lam[t, i]``: coordinate and λ of the tet's i-th stored vertex.
    """
    from ..fields.tis import tis_value
    tet, bary = locator.locate(pts)
    inside = tet >= 0
    rows = np.flatnonzero(inside)
    t = tet[rows]
    th = np.zeros((len(rows), 4))
    np.put_along_axis(th, slots[t], 2 * np.pi * lam[t] * bary[rows], axis=1)
    vals = np.full(len(bary), np.nan)
    vals[rows] = tis_value(th, kind)
    return vals, inside


def body_clip(body, points, tets, resolution):
    """The body's signed distance (a :class:`porecad.bodies.MeshBody`) exact to 4 samples of a tet mesh's lattice.

    ``body = (vertices, faces)``; the sample spacing is the mean tet edge over
    ``resolution − 1`` (the lattice of :func:`tis_lattice_mesh`, the grid of
    :func:`tis_grid_mesh`).
    """
    from ..bodies.mesh import MeshBody
    X = np.asarray(points, np.float64)[np.asarray(tets, np.int64)]
    edge = float(np.mean(np.linalg.norm(X[:, _PAIRS[:, 0]] - X[:, _PAIRS[:, 1]], axis=2)))
    return MeshBody(body[0], body[1], band=4.0 * edge / max(float(resolution) - 1.0, 1.0))


def tis_grid_mesh(points, tets, kind="P", lam=1.0, *, threshold=None, relative=None, resolution=17,
                  structure="pore", colors=None, clip=None):
    """TIS over a tet mesh sampled on a Cartesian grid (point location) and polygonised by marching cubes.

    The grid spacing is the mean tet edge over ``resolution − 1``. The
    material ``{φ ≥ C}`` (pore) is intersected with the tet domain through the
    signed distance to the domain's boundary surface, and the chunked
    polygoniser closes it; the relative threshold takes min/max over the
    samples inside the domain (002 §4). With ``clip`` (a body's signed
    distance field, negative inside) the material is also cut to the body
    in field space, and the dict holds the body alone on the same grid
    (``domain``) and the vertices on its surface (``cut_vertices``). Returns a dict.
    """
    from ..bodies.mesh import MeshBody
    from ..fields.tis import check_type
    from ..mesh.polygonise import Grid, GridArraySampler, polygonise
    from ..volmesh import boundary_faces
    kind = check_type(kind)
    if (threshold is None) == (relative is None):
        raise InputError("give exactly one of a threshold C or a relative threshold R")
    P = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    T = len(tets)
    slots, how = stored_slots(tets, kind, colors)
    lam_v = _lambda_per_vertex(lam, T, slots)
    from ..volmesh import TetLocator
    loc = TetLocator(P, tets)
    X = P[tets]
    mean_edge = float(np.linalg.norm(X[:, _PAIRS[:, 0]] - X[:, _PAIRS[:, 1]], axis=2).mean())
    if not float(resolution) >= 3:
        raise InputError(f"resolution must be at least 3 samples per tet edge, got {resolution!r}")
    h = mean_edge / (float(resolution) - 1)
    lo, hi = P.min(axis=0) - 2 * h, P.max(axis=0) + 2 * h
    grid = Grid.from_box(lo, hi, spacing=h)
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    Z, Y, Xg = np.meshgrid(zs, ys, xs, indexing="ij")
    pts = np.stack([Xg.ravel(), Y.ravel(), Z.ravel()], axis=1)
    vals, inside = tis_field_values(loc, slots, lam_v, kind, pts)
    if not inside.any():
        raise InputError("no grid sample falls inside the tet mesh; raise the resolution")
    C = relative_threshold(vals[inside], relative) if relative is not None else float(threshold)
    vmin, vmax = float(np.nanmin(vals[inside])), float(np.nanmax(vals[inside]))
    phi = np.where(np.isnan(vals), C, vals)
    mat = (C - phi) if structure == "pore" else (phi - C)
    bf = boundary_faces(tets)[0]
    hull = MeshBody(P, bf, band=4 * h)
    dom = hull.sample_grid(xs, ys, zs).reshape(-1)
    if clip is not None:
        dom = np.maximum(dom, np.asarray(clip.sample_grid(xs, ys, zs), np.float64).reshape(-1))
    shape = (len(zs), len(ys), len(xs))
    res = polygonise(GridArraySampler(np.maximum(mat, dom).astype(np.float32).reshape(shape), grid), grid, caps=True)
    por = float(np.mean(vals[inside] < C) if structure == "pore" else np.mean(vals[inside] > C))
    out = {"vertices": res.vertices, "faces": res.faces.astype(np.int64), "threshold": C,
           "value_range": (vmin, vmax), "sample_porosity": por, "slots": how,
           "grid": {"shape": list(grid.shape), "spacing": h}}
    if clip is not None:
        d = polygonise(GridArraySampler(dom.astype(np.float32).reshape(shape), grid), grid, caps=True)
        out["domain"] = (d.vertices, d.faces.astype(np.int64))
        out["cut_vertices"] = np.abs(np.asarray(clip(res.vertices), np.float64)) < 0.25 * h
    return out


def tis_curvatures(points, tets, kind, lam, query, colors=None, structure="pore"):
    """Exact mean and Gaussian curvature of the TIS level set through each query point.

    In a tet, ``θ = 2πλ (B x + b₀)`` with ``B`` the barycentric rows of the
    inverse vertex matrix, so ``∇ₓφ = Jᵀ ∇_θ φ`` and ``Hₓ = Jᵀ H_θ J`` with
    ``J = 2πλ B`` (rows permuted to the tet's coordinate slots); the level-set
    formulas of :func:`porecad.analysis.curvature.implicit_curvatures` give H
    and K. The sign follows the material: for a pore solid (material φ ≥ C)
    the outward normal is ``−∇φ``. Returns ``(H, K, bary_min)``; ``bary_min``
    (the smallest barycentric coordinate) tells how close a point is to a
    tet face, where the surface is only C⁰.
    """
    from ..analysis.curvature import implicit_curvatures
    from ..fields.tis import check_type, tis_derivatives
    kind = check_type(kind)
    P = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    slots, _ = stored_slots(tets, kind, colors)
    lam_v = _lambda_per_vertex(lam, len(tets), slots)
    from ..volmesh import TetLocator
    loc = TetLocator(P, tets)
    q = np.asarray(query, dtype=np.float64).reshape(-1, 3)
    tet, bary = loc.locate(q)
    t = np.where(tet >= 0, tet, 0)
    bary = np.where(np.isnan(bary), 0.25, bary)
    # J[n, s, :] = d theta_s / dx for the slot s fed by stored vertex i
    scale = 2 * np.pi * lam_v[t]  # (N, 4) per stored vertex
    dbdx = np.concatenate([-loc.inv.sum(axis=1, keepdims=True), loc.inv], axis=1)  # (T, 4, 3): d b_i / dx
    rows = dbdx[t] * scale[:, :, None]  # (N, 4, 3), row i = d(2πλ b_i)/dx
    J = np.zeros_like(rows)
    np.put_along_axis(J, slots[t][:, :, None], rows, axis=1)
    theta = np.zeros_like(bary)
    np.put_along_axis(theta, slots[t], scale * bary, axis=1)
    _, g, H = tis_derivatives(theta, kind)
    gx = np.einsum("ns,nsj->nj", g, J)
    Hx = np.einsum("nsi,nst,ntj->nij", J, H, J)
    sign = -1.0 if structure == "pore" else 1.0
    Hm, Kg = implicit_curvatures(sign * gx, sign * Hx)
    Hm[tet < 0] = np.nan
    Kg[tet < 0] = np.nan
    return Hm, Kg, bary.min(axis=1)
