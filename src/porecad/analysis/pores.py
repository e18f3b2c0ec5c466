"""Pore and strut analysis of a scaffold inside its design domain.

A closed mesh (the solid) and its design domain (:mod:`porecad.analysis.domain`:
a box, a body, a field) are sampled at voxel centres (inside by winding
number, :meth:`porecad.bodies.mesh.MeshBody.inside_grid`). The pore space is
the domain minus the solid — the air around a body never counts.

* **Porosity (voxels)** — void voxels over domain voxels, to compare with
  the mesh porosity ``1 − V_solid / V_domain``.
* **Pore and strut size** — local thickness with exact distances to the
  mesh and sub-voxel medial balls (:mod:`porecad.analysis.thickness`);
  statistics are volume weighted (every voxel counts once). The voxel is
  chosen from the feature size (:func:`default_voxel`). When the grid over
  the domain would be too large, sizes are measured on sample blocks at the
  fine voxel (cubes placed at the largest pore, the thickest strut and at
  random in the domain, fixed seed) and the report says so
  (``size_sampling``); connectivity is then measured on a coarser grid of
  the whole domain (``voxel_connectivity``).
* **Interconnectivity, percolation, skin** — :mod:`porecad.analysis.connectivity`.
* **Printability** — struts thinner than ``min_feature`` and pores smaller
  than ``min_pore`` are flagged as connected regions with their volume and
  centroid (mm).
* **Permeability (estimate)** — Kozeny–Carman, ``k = ε³ / (5 S² (1 − ε)²)``
  with porosity ε and the specific surface ``S`` (area per solid volume):
  a labelled estimate for comparing designs, not a measurement.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import InputError, ResourceError

#: largest grid analysed in one piece (about 40 bytes a voxel)
MAX_VOXELS = 16_000_000
#: largest connectivity grid over the whole domain when sizes are sampled in blocks
MAX_COARSE_VOXELS = 12_000_000
#: most voxels of one sample block, margins included
BLOCK_VOXELS = 2_000_000
#: a sample block's core spans this many of the largest ball diameters
BLOCK_DIAMETERS = 2.0
#: most voxels of a sample block's core
BLOCK_CORE_VOXELS = 400_000
#: voxels across the smaller of the mean wall thickness and mean pore width (2 V / S). Two are
#: enough with exact distances and sub-voxel medial balls: gyroid sheet wall mean -1.1 %, d50 -1.2 %,
#: max +0.8 %; 0.5-2 mm channels -0.1 % (3 gave -0.3 %, -0.5 %, +0.5 % for 3.4x the voxels)
VOXELS_PER_FEATURE = 2.0


def kozeny_carman_permeability(porosity: float, specific_surface: float) -> float:
    """Kozeny–Carman permeability estimate ``k = ε³ / (5 S² (1 - ε)²)`` (mm²).

    ``ε`` is the porosity and ``S`` the specific surface (surface area per
    solid volume, 1/mm); the Kozeny constant 5 is Carman's for packed beds
    (P. C. Carman, *Trans. Inst. Chem. Eng.* 15 (1937) 150). An estimate for
    comparing designs, not a measurement.
    """
    eps = float(porosity)
    s = float(specific_surface)
    if not (0 < eps < 1) or not s > 0:
        raise InputError(f"Kozeny-Carman needs 0 < porosity < 1 and a positive specific surface, got {eps}, {s}")
    return float(eps ** 3 / (5.0 * s * s * (1.0 - eps) ** 2))


def default_voxel(volume, area, domain_volume=None, extent=None, per_feature: float = VOXELS_PER_FEATURE) -> float:
    """Voxel from the feature size: ``min(2 V_solid, 2 V_void) / S / per_feature``.

    ``2 V / S`` is the thickness of a slab of volume V and area S/2 a side
    (a cylinder's radius, a third of a sphere's diameter): the mean wall
    thickness of the solid and the mean width of the pores. Without a domain
    volume only the solid counts. Capped at the smallest extent / 20.
    """
    v = float(volume)
    s = float(area)
    if not (v > 0 and s > 0):
        raise InputError("the mesh has no positive volume or area to choose a voxel from")
    feat = 2.0 * v / s
    if domain_volume is not None and float(domain_volume) > v:
        feat = min(feat, 2.0 * (float(domain_volume) - v) / s)
    h = feat / float(per_feature)
    if extent is not None:
        h = min(h, float(np.min(extent)) / 20.0)
    return h


def _axes(lo, n, h):
    return [lo[a] + h * np.arange(n[a]) for a in range(3)]


def _grid(lo, hi, h, pad=1):
    """Voxel-centre axes over ``[lo, hi]`` with ``pad`` voxels outside each face: (origin, n)."""
    n = np.ceil((hi - lo) / h).astype(np.int64) + 1 + 2 * pad
    # centred, nudged off the lattice of round numbers a CAD part's faces and edges lie on
    origin = 0.5 * (lo + hi) - 0.5 * (n - 1) * h + h * np.array([0.0123, 0.0234, 0.0345])
    return origin, n


class _Walls:
    """Exact distance to the walls of the analysed region: the mesh and (unless a box) the domain boundary.

    Two indices of the mesh near the region: cells of 2 voxels for queries
    within a few voxels of the surface, of 8 voxels for the long ones (ball
    centres deep in a pore or strut; made when first needed), so neither scans many cells.
    """

    def __init__(self, vertices, faces, domain, lo, hi, h, reach, boxes=None):
        from .surface_index import SurfaceIndex, face_boxes
        lo, hi = lo - reach - h, hi + reach + h
        if boxes is None:
            boxes = face_boxes(vertices, faces)
        keep = np.flatnonzero(np.all((boxes[1] >= lo) & (boxes[0] <= hi), axis=1))
        faces, boxes = faces[keep], (boxes[0][keep], boxes[1][keep])
        self.fine = SurfaceIndex(vertices, faces, cell=2.0 * h, lo=lo, hi=hi, boxes=boxes)
        self._mesh = (vertices, faces, lo, hi, boxes)
        self._coarse = None
        self.long = 8.0 * h
        self.domain = domain

    @property
    def coarse(self):
        """The index for long queries, made when first asked (most blocks never ask)."""
        if self._coarse is None:
            from .surface_index import SurfaceIndex
            v, f, lo, hi, boxes = self._mesh
            self._coarse = SurfaceIndex(v, f, cell=self.long, lo=lo, hi=hi, boxes=boxes)
        return self._coarse

    def __call__(self, points, upper):
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        ub = np.broadcast_to(np.asarray(upper, dtype=np.float64), (len(p),))
        far = ub > self.long
        if far.any() and not far.all():
            d = np.empty(len(p))
            c = np.empty((len(p), 3))
            d[~far], c[~far] = self.fine.nearest(p[~far], ub[~far])
            d[far], c[far] = self.coarse.nearest(p[far], ub[far])
        else:
            d, c = (self.coarse if len(p) and far.all() else self.fine).nearest(p, ub)
        if not self.domain.walls:
            return d, c
        dd, cd = self.domain.wall(p, d)
        nearer = dd < d
        d = np.where(nearer, dd, d)
        c[nearer] = cd[nearer]
        return d, c


def _sizes_on_block(body, vertices, faces, domain, mesh_box, origin, n, h, reach, masks=None, boxes=None):
    """Solid/domain masks, local thickness of both phases and largest radii on one block of voxels.

    Ball centres lie in the domain when its boundary is a wall, else (a box
    window) anywhere in the mesh's bounding box ``mesh_box`` — so a window
    smaller than the mesh sees the structure around it.
    """
    from .thickness import phase_thickness, wall_transform

    xs, ys, zs = _axes(origin, n, h)
    if masks is None:
        solid = body.inside_grid(xs, ys, zs)
        inside = domain.inside_grid(xs, ys, zs)
    else:
        solid, inside = masks
    hi = origin + (n - 1) * h
    walls = _Walls(vertices, faces, domain, origin, hi, h, reach, boxes)
    known = np.zeros(solid.shape, dtype=bool)       # exact already: not asked again on the ridge
    dist, cp = wall_transform(solid, inside if domain.walls else None, origin, h, walls, known=known)
    region = inside if domain.walls else mesh_box.inside_grid(xs, ys, zs)
    pore_lt, pore_r = phase_thickness(region & ~solid, dist, cp, origin, h, walls, known)
    strut_lt, strut_r = phase_thickness(region & solid, dist, cp, origin, h, walls, known)
    return solid, inside, pore_lt, strut_lt, pore_r, strut_r


def _largest_balls(void, solid, inside, origin, h, max_voxels=3_000_000):
    """Largest inscribed radius (mm) and its centre for the void and the solid, from voxel EDTs.

    On every ``s``-th voxel (``s`` keeping the grid under ``max_voxels``):
    the radius is then good to about ``s`` voxels, enough to place a block
    and size its margin (the block measures the ball exactly).
    """
    from scipy import ndimage
    s = max(1, int(np.ceil((void.size / max_voxels) ** (1 / 3))))
    out = []
    for ph in (void & inside, solid & inside):
        ph = ph[::s, ::s, ::s]
        if ph.any():
            d = ndimage.distance_transform_edt(ph)
            k, j, i = np.unravel_index(int(np.argmax(d)), d.shape)
            out.append(((float(d[k, j, i]) + 1.0) * s * h, origin + np.array([i, j, k]) * s * h))
            del d
    return out


def _stats(values, prefix):
    if values.size == 0:
        return {f"{prefix}_mean": None, f"{prefix}_d10": None, f"{prefix}_d50": None,
                f"{prefix}_d90": None, f"{prefix}_max": None}
    q = np.percentile(values, [10, 50, 90])
    return {f"{prefix}_mean": float(values.mean()), f"{prefix}_d10": float(q[0]),
            f"{prefix}_d50": float(q[1]), f"{prefix}_d90": float(q[2]), f"{prefix}_max": float(values.max())}


def _flag_regions(mask, origin, h, limit=20):
    from scipy import ndimage

    lab, n = ndimage.label(mask)
    if n == 0:
        return {"regions": 0, "volume": 0.0, "locations": []}
    counts = np.bincount(lab.ravel())[1:]
    order = np.argsort(counts)[::-1][:limit]
    cents = ndimage.center_of_mass(mask, lab, order + 1)
    locs = [{"centre": (origin + np.asarray(c)[::-1] * h).tolist(), "volume": float(counts[i] * h ** 3)}
            for c, i in zip(cents, order)]
    return {"regions": int(n), "volume": float(counts.sum() * h ** 3), "locations": locs}


def percolates(phase):
    """Per axis: does one 6-connected component of ``phase`` ([z, y, x]) touch both opposite faces of the grid?"""
    from scipy import ndimage

    lab, n = ndimage.label(phase)
    out = {}
    for name, ax in (("x", 2), ("y", 1), ("z", 0)):
        a = np.unique(np.take(lab, 0, axis=ax))
        b = np.unique(np.take(lab, -1, axis=ax))
        common = np.intersect1d(a[a > 0], b[b > 0])
        out[name] = bool(common.size)
    return out


def _pick_blocks(balls, inside, origin_c, h_c, core, rng, max_blocks):
    """Block core centres (mm): the largest pore, the thickest strut, then random domain voxels (no overlap)."""
    centres = [c for _, c in balls][:max_blocks]
    idx = np.flatnonzero(inside)
    tries = 0
    while len(centres) < max_blocks and tries < 50 * max_blocks and len(idx):
        tries += 1
        k, j, i = np.unravel_index(int(idx[rng.integers(len(idx))]), inside.shape)
        c = origin_c + np.array([i, j, k]) * h_c
        if all(np.max(np.abs(c - o)) >= core for o in centres):
            centres.append(c)
    return centres


def pore_analysis(vertices, faces, spacing: float | None = None, min_feature: float | None = None,
                  min_pore: float | None = None, keep_fields: bool = False, volume: float | None = None,
                  area: float | None = None, domain=None, skin: float | None = None,
                  max_voxels: int = MAX_VOXELS, max_blocks: int = 8, block_voxels: int = BLOCK_VOXELS,
                  seed: int = 0) -> dict:
    """Porosity, pore/strut sizes, interconnectivity and printability of a scaffold in its domain.

    Parameters
    ----------
    vertices, faces : arrays
        A closed, outward mesh (the solid).
    spacing : float, optional
        Voxel size (mm) of the size measurement; default :func:`default_voxel`.
    min_feature, min_pore : float, optional
        Printability limits (mm): struts/walls thinner, pores smaller are flagged.
    volume, area : float, optional
        The mesh's volume and area when the caller has them (else computed).
    domain : None, (vertices, faces), MeshBody or Field, optional
        The design domain (:func:`porecad.analysis.domain.make_domain`);
        default the mesh's bounding box.
    skin : float, optional
        Thickness (mm) of a solid shell that closes the part (``boundary =
        "skin"``): closed pores are split into those the skin closes and those
        the lattice closes, and the lattice's openness is measured without the shell.
    max_voxels, max_blocks, block_voxels, seed
        Above ``max_voxels`` voxels sizes are measured on at most
        ``max_blocks`` sample blocks of ``block_voxels`` voxels (random
        placement from ``seed``).
    keep_fields : bool
        Also return arrays for plots (``"_fields"``).

    Returns
    -------
    dict
        ``voxel``, ``grid``, ``domain``, ``porosity_voxel``,
        ``pore_size_mean/d10/d50/d90/max``, ``strut_size_...``,
        ``open_pore_fraction``, ``closed_pores``, ``closed_pore_volume``,
        ``percolation`` {x, y, z} (void), ``solid_percolation``,
        ``size_sampling`` (how sizes were measured), skin entries,
        printability flags and ``permeability_kozeny_carman_mm2`` (estimate).
    """
    g = _analysis_grid(vertices, faces, spacing, volume, area, domain, skin, max_voxels)
    out, coarse = _whole_domain(g, skin)
    reach = _reach(g, coarse)
    if g.sampled:
        pores, struts, fields_grid = _sizes_in_blocks(g, out, coarse, reach, max_blocks, block_voxels, seed)
    else:
        pores, struts, fields_grid = _sizes_whole(g, out, coarse, reach)
    out.update(_stats(pores, "pore_size"))
    out.update(_stats(struts, "strut_size"))
    _printability(out, fields_grid, min_feature, min_pore)
    eps = out["porosity_voxel"]
    if g.volume > 0 and 0 < eps < 1:
        s = g.area / g.volume
        out["permeability_kozeny_carman_mm2"] = kozeny_carman_permeability(eps, s)
        out["permeability_note"] = "estimate: Kozeny-Carman from porosity and specific surface (k = e^3 / (5 S^2 (1-e)^2))"
    if keep_fields:
        origin_f, h_f, solid_f, inside_f, pore_f, strut_f = fields_grid
        out["_fields"] = {"solid": solid_f, "domain": inside_f, "pore": pore_f, "strut": strut_f,
                          "origin": origin_f, "spacing": h_f, "pore_samples": pores, "strut_samples": struts}
    return out


class _Layout(NamedTuple):
    """What :func:`pore_analysis` measures on: the mesh, its domain and the fine and connectivity grids."""
    v: np.ndarray        # vertices (float64)
    f: np.ndarray        # faces (int64)
    volume: float        # mesh volume
    area: float          # mesh area
    dom: object          # the design domain
    box: bool            # is the domain a box
    lo: np.ndarray       # analysed bounds
    hi: np.ndarray
    ext: np.ndarray      # hi - lo
    h: float             # fine voxel (sizes)
    body: object         # the solid as a MeshBody
    origin: np.ndarray   # fine grid
    n: np.ndarray
    sampled: bool        # sizes measured in sample blocks
    h_c: float           # connectivity grid (the fine one unless sampled)
    origin_c: np.ndarray
    n_c: np.ndarray


def _analysis_grid(vertices, faces, spacing, volume, area, domain, skin, max_voxels) -> _Layout:
    """Check the arguments of :func:`pore_analysis` and lay out its grids; returns a :class:`_Layout`.

    Raises :class:`InputError` (flat mesh, bad skin or voxel) or :class:`ResourceError` (a domain too
    large to analyse at this voxel)."""
    from ..bodies.mesh import MeshBody
    from ..mesh.validate import signed_volume, surface_area
    from .domain import BoxDomain, make_domain

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    if volume is None or area is None:
        volume, area = float(signed_volume(v, f)), float(surface_area(v, f))
    dom = make_domain(domain, v)
    box = isinstance(dom, BoxDomain)
    lo, hi = dom.bounds
    if not box:
        lo, hi = np.minimum(lo, v.min(axis=0)), np.maximum(hi, v.max(axis=0))
    ext = hi - lo
    if not np.all(ext > 0):
        raise InputError("the mesh is flat: there is no volume to analyse")
    if skin is not None and not (np.isfinite(skin) and skin > 0):
        raise InputError(f"skin thickness must be a positive number of mm, got {skin}")
    if spacing is None:
        h = default_voxel(volume, area, dom.volume, ext)
    else:
        h = float(spacing)
        if not (np.isfinite(h) and h >= 1e-6 * float(ext.max())):  # finer has over 1e18 voxels: no grid to lay
            raise InputError(f"voxel size must be at least a millionth of the domain's extent "
                             f"({1e-6 * float(ext.max()):.3g} mm), got {spacing}")
    body = MeshBody(v, f, band=max(float(ext.max()) / 48.0, 1e-6))
    origin, n = _grid(lo, hi, h)
    n_fine = float(np.prod(n.astype(float)))
    sampled = n_fine > max_voxels
    if sampled:
        h_c = max(h, float((np.prod(ext + 2 * h) / MAX_COARSE_VOXELS) ** (1.0 / 3.0)))
        origin_c, n_c = _grid(lo, hi, h_c)
        if h_c > 0.5 * min(ext.min(), 1e300) or np.prod(n_c.astype(float)) > 2 * MAX_COARSE_VOXELS:
            raise ResourceError(f"the domain is too large to analyse at a {h:.3g} mm voxel: give a larger voxel")
    else:
        h_c, origin_c, n_c = h, origin, n
    return _Layout(v, f, volume, area, dom, box, lo, hi, ext, h, body, origin, n, sampled, h_c, origin_c, n_c)


def _whole_domain(g: _Layout, skin):
    """Porosity and connectivity (open and closed pores, percolation, skin split) on the connectivity grid;
    returns ``(report dict so far, (solid, inside, void) masks of that grid)``."""
    from .connectivity import components, skin_split

    xs, ys, zs = _axes(g.origin_c, g.n_c, g.h_c)
    solid_c = g.body.inside_grid(xs, ys, zs)
    inside_c = g.dom.inside_grid(xs, ys, zs)
    void_c = inside_c & ~solid_c
    n_dom = int(inside_c.sum())
    if n_dom == 0:
        raise InputError("no voxel lies inside the analysis domain: is the domain the right body?")
    n = g.n
    out = {"voxel": g.h, "grid": [int(n[0]), int(n[1]), int(n[2])], "domain": g.dom.kind,
           "porosity_voxel": float(void_c.sum() / n_dom)}
    if g.dom.volume:
        out["domain_volume_mesh"] = float(g.dom.volume)
    out["domain_volume_voxel"] = float(n_dom * g.h_c ** 3)
    con = components(void_c, inside_c, g.origin_c, g.h_c, g.box)
    out["open_pore_fraction"] = con["open_fraction"]
    out["closed_pores"] = con["closed"]
    out["closed_pore_volume"] = con["closed_volume"]
    out["percolation"] = con["percolation"]
    out["solid_percolation"] = components(solid_c, inside_c, g.origin_c, g.h_c, g.box)["percolation"]
    if skin is not None:
        out.update(skin_split(void_c, inside_c, g.origin_c, g.h_c, float(skin), con))
    return out, (solid_c, inside_c, void_c)


class _Reach(NamedTuple):
    """How far size blocks must see: the mesh's bounding box, the largest balls, their reach and margin."""
    mesh_box: object     # BoxDomain of the mesh
    balls: list          # [(radius, centre)] of the void and the solid (when sampled or a window)
    reach: float         # mm
    margin: int          # voxels around a block


def _reach(g: _Layout, coarse) -> _Reach:
    """From the connectivity grid's ``(solid, inside, void)`` masks: the largest balls (when sizes are
    sampled or the box is a window smaller than the mesh), the reach of a wall query and the block
    margin; returns a :class:`_Reach`."""
    from .domain import BoxDomain

    solid_c, inside_c, void_c = coarse
    v, h = g.v, g.h
    mesh_box = BoxDomain(v.min(axis=0), v.max(axis=0))
    window = g.box and bool(np.any(v.min(axis=0) < g.lo - h) or np.any(v.max(axis=0) > g.hi + h))
    balls = _largest_balls(void_c, solid_c, inside_c, g.origin_c, g.h_c) if (g.sampled or window) else []
    reach = max([r for r, _ in balls], default=0.0) + g.h_c if balls else h
    margin = int(np.ceil(reach / h)) + 2 if window or g.sampled else 0
    return _Reach(mesh_box, balls, reach, margin)


def _sizes_whole(g: _Layout, out, coarse, r: _Reach):
    """Pore and strut sizes on one block: the domain and a margin at the fine voxel; records
    ``size_sampling`` in ``out``; returns ``(pore sizes, strut sizes, fields grid)``."""
    solid_c, inside_c, _ = coarse
    h, margin = g.h, r.margin
    o = g.origin - margin * h
    nb = g.n + 2 * margin
    masks = None if margin else (solid_c, inside_c)
    solid, inside, p_lt, s_lt, pore_r, strut_r = _sizes_on_block(g.body, g.v, g.f, g.dom, r.mesh_box, o, nb, h,
                                                                r.reach, masks)
    sl = tuple(slice(margin, margin + int(m)) for m in g.n[::-1])
    cs, ci, cp_, cst = solid[sl], inside[sl], p_lt[sl], s_lt[sl]
    pores, struts = cp_[ci & ~cs], cst[ci & cs]
    out["size_sampling"] = {"method": "whole domain", "blocks": 1, "fraction": 1.0}
    return pores, struts, (g.origin, h, cs, ci, cp_, cst)


def _sizes_in_blocks(g: _Layout, out, coarse, r: _Reach, max_blocks, block_voxels, seed):
    """Pore and strut sizes on sample blocks at the fine voxel (the largest pore, the thickest strut,
    random places from ``seed``); records ``voxel_connectivity`` and ``size_sampling`` in ``out``;
    returns ``(pore sizes, strut sizes, fields grid of a random block)``."""
    from .surface_index import face_boxes

    _, inside_c, _ = coarse
    h, margin = g.h, r.margin
    n_dom = int(inside_c.sum())
    core = max(24, min(int(round(block_voxels ** (1 / 3))) - 2 * margin,
                       int(round(BLOCK_CORE_VOXELS ** (1 / 3))),
                       int(np.ceil(BLOCK_DIAMETERS * 2.0 * r.reach / h))))
    core_mm = core * h
    boxes = face_boxes(g.v, g.f)
    rng = np.random.default_rng(seed)
    centres = _pick_blocks(r.balls, inside_c, g.origin_c, g.h_c, core_mm, rng, max_blocks)
    pore_parts, strut_parts = [], []
    sampled_vox = 0
    fields_grid = None
    for c in centres:
        o = c - 0.5 * (core - 1) * h - margin * h
        nb = np.full(3, core + 2 * margin, dtype=np.int64)
        solid, inside, p_lt, s_lt, pr, sr = _sizes_on_block(g.body, g.v, g.f, g.dom, r.mesh_box, o, nb, h,
                                                            r.reach, boxes=boxes)
        sl = (slice(margin, margin + core),) * 3
        cs, ci, cp_, cst = solid[sl], inside[sl], p_lt[sl], s_lt[sl]
        pore_parts.append(cp_[ci & ~cs])
        strut_parts.append(cst[ci & cs])
        sampled_vox += int(ci.sum())
        if fields_grid is None and (len(pore_parts) == min(3, len(centres))):
            fields_grid = (o + margin * h, h, cs, ci, cp_, cst)   # a random block (the first two are extremes)
    pores = np.concatenate(pore_parts) if pore_parts else np.zeros(0, np.float32)
    struts = np.concatenate(strut_parts) if strut_parts else np.zeros(0, np.float32)
    out["voxel_connectivity"] = g.h_c
    out["size_sampling"] = {"method": "blocks", "blocks": len(centres), "block_edge_mm": core_mm,
                            "fraction": float(sampled_vox * h ** 3 / (n_dom * g.h_c ** 3)), "seed": int(seed),
                            "note": "sizes measured in sample blocks at the fine voxel: the largest pore, "
                                    "the thickest strut and random places in the domain"}
    return pores, struts, fields_grid


def _printability(out, fields_grid, min_feature, min_pore):
    """Flag struts thinner than ``min_feature`` and pores smaller than ``min_pore`` on the fields grid
    ``(origin, h, solid, inside, pore, strut)`` into ``out``; returns nothing."""
    origin_f, h_f, solid_f, inside_f, pore_f, strut_f = fields_grid
    if min_feature is not None:
        out["thin_struts"] = {"min_feature": float(min_feature),
                              **_flag_regions(inside_f & solid_f & (strut_f < min_feature), origin_f, h_f)}
    if min_pore is not None:
        out["small_pores"] = {"min_pore": float(min_pore),
                              **_flag_regions(inside_f & ~solid_f & (pore_f < min_pore), origin_f, h_f)}


def voxelize(vertices, faces, spacing: float):
    """Solid mask ``[z, y, x]`` at voxel centres over the mesh's bounding box, with distances to the surface.

    Returns ``(solid, origin, spacing, distance)``: voxel ``(i, j, k)`` has
    its centre at ``origin + (i, j, k) * spacing``; ``distance`` (mm) is that
    of every voxel centre to the surface (exact next to it, closest points
    passed on beyond: :func:`porecad.analysis.thickness.wall_transform`).
    """
    from ..bodies.mesh import MeshBody
    from .domain import BoxDomain
    from .thickness import wall_transform

    v = np.asarray(vertices, dtype=np.float64)
    h = float(spacing)
    if not np.isfinite(h) or h <= 0:
        raise InputError(f"voxel size must be positive, got {spacing}")
    lo, hi = v.min(axis=0), v.max(axis=0)
    n = np.maximum(np.ceil((hi - lo) / h).astype(np.int64), 1)
    if float(np.prod(n.astype(float))) > MAX_VOXELS:
        raise ResourceError(f"a {n[0]}x{n[1]}x{n[2]} voxel grid is too large to analyse "
                            f"(at most {MAX_VOXELS:,} voxels): give a larger voxel")
    origin = lo + 0.5 * (hi - lo - (n - 1) * h)
    xs, ys, zs = _axes(origin, n, h)
    body = MeshBody(v, faces, band=max(float(np.ptp(v, axis=0).max()) / 48.0, 1e-6))
    solid = body.inside_grid(xs, ys, zs)
    walls = _Walls(v, np.asarray(faces, dtype=np.int64), BoxDomain(lo, hi), origin,
                   origin + (n - 1) * h, h, h)
    dist, _ = wall_transform(solid, None, origin, h, walls)
    return solid, origin, h, dist
