"""The ``arbf`` job: anisotropic-RBF pore networks over tet and hex meshes and point clouds (000 ch.5).

Steps (000 Figs. 5.4 and 5.5): a domain (a built-in tet or hex mesh, a
volume-mesh file, a closed body tetrahedralised on a BCC lattice, or a point
cloud with values), its centres and values (000 §5.3, see
:mod:`porecad.fields.rbf`), optionally moved at random (000 Fig. 5.10), the
weights by one global solve or per-cell local solves, the interpolant ``Φ``
sampled on a regular grid, the material ``{Φ ≥ iso}`` intersected with the
domain, ``max(iso − Φ, d_domain)`` with ``d_domain`` the signed distance to
the domain's boundary surface (negative inside), polygonised by the chunked
marching cubes of the Foundation into a closed solid, validated and written.

The domain is the volume of the mesh; for a closed body it is the body
itself (the scaffold is cut to it); for a point cloud it is the points'
axis-aligned bounding box. ``porosity`` is the void fraction of the domain,
``1 − V(solid) / V(domain)``, from the mesh volume; ``porosity_samples`` the
fraction of the grid samples inside the domain with ``Φ < iso``.

A recipe is a plain dict::

    job = "arbf"
    [domain]  kind = "tet" | "two-tets" | "icosahedron" | "hex" | "hex2x2x2" | "hex-rod"
                     | "mesh-file" | "body" | "points",  path, size = 10.0, tets = 1000
    [arbf]    basis = "imq", shape = 0.1, iso = 0.0, local = false, ring = "vertex",
              jitter = 0.0 (mm), seed = 0, table = true
    [mesh]    resolution = 24 (grid samples per mean element edge)
    [output]  mesh, report
"""

from __future__ import annotations

import time

import numpy as np

from . import __version__
from .errors import InputError, ResourceError
from .mesh.weld import compact

BUILTIN_TET = ("tet", "two-tets", "icosahedron")
BUILTIN_HEX = ("hex", "hex2x2x2", "hex-rod")
#: the iso-values of the porosity table (the chosen iso is added)
ISO_TABLE = (-0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75)
#: multiples of the shape parameter in the porosity table
SHAPE_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: largest sampling grid (samples)
MAX_SAMPLES = 40_000_000
#: inside-domain samples used for the shape-parameter column of the table
TABLE_SAMPLES = 20_000
#: cells re-solved for the shape-parameter column of the table after a local solve
TABLE_CELLS = 64


def _box_surface(lo, hi):
    """The outward triangle mesh of the box ``[lo, hi]``."""
    from .volmesh.hexshapes import HEX_FACES, single_hex
    p, h = single_hex(1.0)
    v = lo + p * (hi - lo)
    q = h[0][HEX_FACES]
    return v, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


def arbf_domain(spec: dict):
    """Build the domain of a recipe.

    Returns ``(cc, surface, outer, volume, info)``: the :class:`~porecad.fields.rbf.CellCentres`;
    the closed outward triangle surface ``(v, f)`` the material is cut to;
    the outer faces as ``(centroids (F, 3), kind)`` for the openness check
    (``kind`` "faces" or "box"); the domain volume (mm³); a dict for the report.
    """
    from . import volmesh as vm
    from .fields import rbf
    from .mesh.validate import signed_volume
    from .volmesh import hexshapes as hs

    kind = spec.get("kind", "tet")
    size = float(spec.get("size", 10.0))
    if not np.isfinite(size) or size <= 0:
        raise InputError(f"--size must be a positive length in mm, got {spec.get('size')!r}")
    info = {"kind": kind}
    t0 = time.perf_counter()
    body = None
    if kind in BUILTIN_TET or kind in ("mesh-file", "body"):
        if kind == "tet":
            points, cells = vm.regular_tetrahedron(size)
        elif kind == "two-tets":
            points, cells = vm.two_tetrahedra(size)
        elif kind == "icosahedron":
            points, cells = vm.icosahedron_tets(size)
        elif kind == "mesh-file":
            points, cells, ckind = read_volume_mesh(spec["path"])
            info["path"] = str(spec["path"])
        elif kind == "body":
            points, cells, body, _, binfo = vm.tetrahedralise_body(spec["path"], spec.get("tets", 1000))
            info.update(binfo)
            info["mesher"] += "; the scaffold is cut to the body"
        if kind != "mesh-file":
            points, cells = vm.check_tet_mesh(points, cells)
            ckind = "tet"
        if ckind == "tet":
            bfaces = vm.boundary_faces(cells)[0]
            surf = compact(points, bfaces)
            outer = points[bfaces].mean(axis=1)
            volume = float(vm.signed_volumes(points, cells).sum())
        else:
            quads = hs.hex_boundary_faces(cells)[0]
            surf = compact(points, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
            outer = points[quads].mean(axis=1)
            volume = float(signed_volume(*surf))
        cc = rbf.mesh_centres(points, cells, ckind)
        info.update(cells=ckind, n_cells=int(len(cells)), n_vertices=int(len(np.unique(cells))))
        if body is not None:
            surf = body
            volume = float(signed_volume(*body))
        outer_kind = "faces"
    elif kind in BUILTIN_HEX:
        points, cells = {"hex": lambda: hs.single_hex(size), "hex2x2x2": lambda: hs.hex_grid(2, 2, 2, size),
                         "hex-rod": lambda: hs.hex_rod(4, size)}[kind]()
        points, cells = hs.check_hex_mesh(points, cells)
        quads = hs.hex_boundary_faces(cells)[0]
        surf = compact(points, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
        outer = points[quads].mean(axis=1)
        volume = float(hs.hex_volumes(points, cells).sum())
        cc = rbf.mesh_centres(points, cells, "hex")
        info.update(cells="hex", n_cells=int(len(cells)), n_vertices=int(len(points)))
        outer_kind = "faces"
    elif kind == "points":
        pts, vals = rbf.read_points(spec["path"])
        cc = rbf.point_cloud_centres(pts, vals)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        if np.any(hi - lo <= 1e-9 * max(float(np.max(hi - lo)), 1e-300)):
            raise InputError(f"{spec['path']}: the points span no volume (their bounding box is flat)")
        surf = _box_surface(lo, hi)
        outer = np.stack([lo, hi])
        volume = float(np.prod(hi - lo))
        info.update(path=str(spec["path"]), cells="points", n_points=int(len(pts)),
                    values={"min": float(vals.min()), "max": float(vals.max())},
                    domain="the bounding box of the points", **cc.info)
        outer_kind = "box"
    else:
        raise InputError(f"unknown ARBF domain {kind!r}; use {', '.join(BUILTIN_TET + BUILTIN_HEX)}, "
                         "a mesh file or --points FILE")
    info["volume"] = volume
    info["length_scale"] = float(cc.scale)
    info["time_s"] = time.perf_counter() - t0
    return cc, surf, (outer, outer_kind), volume, info


def read_volume_mesh(path):
    """The tets or hexes of a volume-mesh file: ``(points, cells, "tet" | "hex")`` (one-line errors)."""
    from pathlib import Path

    from .volmesh import read_tet_mesh
    from .volmesh.hexshapes import read_hex_mesh
    from .volmesh.tetio import _read, _suffix
    p = Path(path)
    suffix = _suffix(p)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    if p.is_dir():
        raise InputError(f"{p}: is a directory, not a volume mesh file")
    types = {b.type for b in _read(p, suffix).cells if len(b.data)}
    if types & {"tetra", "tetra10"}:
        pts, tets = read_tet_mesh(p)
        return pts, tets, "tet"
    if types & {"hexahedron", "hexahedron20", "hexahedron27"}:
        pts, hexes = read_hex_mesh(p)
        return pts, hexes, "hex"
    raise InputError(f"{p} holds no tetrahedra or hexahedra (cell types: {', '.join(sorted(types)) or 'none'}); "
                     "the mesh is empty")


def _monotonic(values) -> bool:
    v = [x for x in values if x is not None]
    return bool(len(v) >= 2 and all(b >= a for a, b in zip(v, v[1:])))


def pore_network(phi, dom, iso, grid_axes, spacing, outer):
    """Connectivity and openness of the pores ``{Φ < iso}`` inside the domain, on the sample grid.

    6-connected components of the pore samples (``scipy.ndimage.label``);
    the *main* network is the largest. A component is *open* when it reaches
    the boundary layer (samples inside the domain within 1.5 samples of its
    surface). An outer face of the domain (a boundary triangle of a tet mesh,
    a boundary quad of a hex mesh, a face of a point cloud's box) is *opened*
    when a boundary-layer sample of the main network lies nearer to it
    (nearest face centroid, k-d tree; for a box, the nearest box plane) than
    to any other outer face. Percolation per axis (one pore component touching
    both opposite faces of the domain's bounding box) as in
    :func:`porecad.analysis.pores.percolates`.
    """
    from scipy import ndimage
    from scipy.spatial import cKDTree

    from .analysis.pores import percolates as _percolates
    inside = dom < 0
    pore = inside & (phi < iso)
    solid = inside & ~pore
    n_pore = int(pore.sum())
    out = {"pore_samples": n_pore}
    lab, n = ndimage.label(pore)
    slab, ns = ndimage.label(solid)
    ssz = np.bincount(slab.ravel(), minlength=ns + 1)[1:]
    out["solid_components"] = int(ns)
    out["solid_largest_fraction"] = float(ssz.max() / ssz.sum()) if ns else None
    if n == 0:
        out.update(pore_components=0, connected=False, open_pore_fraction=None, closed_pores=0,
                   opens_on_every_outer_face=False, outer_faces=int(len(outer[0]) if outer[1] == "faces" else 6),
                   open_outer_faces=0)
        return out
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    sizes[0] = 0
    main = int(np.argmax(sizes))
    layer = inside & (dom > -1.5 * spacing)
    touching = np.zeros(n + 1, bool)
    touching[np.unique(lab[layer & pore])] = True
    touching[0] = False
    out["pore_components"] = int(n)
    out["largest_fraction"] = float(sizes[main] / n_pore)
    out["connected"] = bool(n == 1)
    out["closed_pores"] = int(n - touching[1:].sum())
    out["open_pore_fraction"] = float(sizes[touching].sum() / n_pore)
    k, j, i = np.nonzero(layer & (lab == main))
    xs, ys, zs = grid_axes
    pts = np.column_stack([xs[i], ys[j], zs[k]])
    centroids, kind = outer
    if kind == "box":
        lo, hi = centroids
        d = np.concatenate([pts - lo, hi - pts], axis=1)  # distances to x0 y0 z0 x1 y1 z1
        n_faces = 6
        hit = np.unique(np.argmin(d, axis=1)) if len(pts) else np.zeros(0, np.int64)
    else:
        n_faces = len(centroids)
        hit = np.unique(cKDTree(centroids).query(pts)[1]) if len(pts) else np.zeros(0, np.int64)
    out["outer_faces"] = int(n_faces)
    out["open_outer_faces"] = int(len(hit))
    out["opens_on_every_outer_face"] = bool(len(hit) == n_faces)
    box = tuple(slice(int(ix.min()), int(ix.max()) + 1) for ix in np.nonzero(inside))
    out["percolation"] = _percolates(pore[box])
    return out


def mesh_shells(vertices, faces) -> dict:
    """Connected shells of the output mesh: outer shells (positive volume) and cavities (closed pores)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    nv = len(vertices)
    if len(faces) == 0:
        return {"shells": 0, "solid_pieces": 0, "cavities": 0}
    f = np.asarray(faces, np.int64)
    r = np.concatenate([f[:, 0], f[:, 1]])
    c = np.concatenate([f[:, 1], f[:, 2]])
    g = coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(nv, nv))
    n, lab = connected_components(g, directed=False)
    fl = lab[f[:, 0]]
    v = np.asarray(vertices, np.float64)
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])) / 6.0
    shell_vol = np.bincount(fl, weights=vol, minlength=n)
    used = np.bincount(fl, minlength=n) > 0
    sv = shell_vol[used]
    return {"shells": int(used.sum()), "solid_pieces": int(np.sum(sv > 0)), "cavities": int(np.sum(sv < 0))}


def porosity_table(field, cc, phi_inside, pts_inside, iso, local, ring, seed=0):
    """Porosity of the sample grid vs the iso-value (at the chosen ``c``) and vs ``c`` (at the chosen iso).

    The iso column uses every sample inside the domain; the ``c`` column
    re-solves the system for each ``c`` (same solve) and evaluates ``Φ`` at
    up to :data:`TABLE_SAMPLES` random samples inside the domain (for a local
    solve on more than :data:`TABLE_CELLS` cells, samples in that many random
    cells, whose systems alone are re-solved).
    """
    from .fields import rbf
    isos = sorted(set(ISO_TABLE) | {float(iso)})
    vs_iso = [{"iso": v, "porosity": float(np.mean(phi_inside < v))} for v in isos]
    rng = np.random.default_rng(seed)
    only = None
    if local and len(cc.cells) > TABLE_CELLS:
        only = np.sort(rng.choice(len(cc.cells), size=TABLE_CELLS, replace=False))
        keep = np.isin(field.locator(pts_inside), only)
        pts_inside = pts_inside[keep]
    take = rng.choice(len(pts_inside), size=min(TABLE_SAMPLES, len(pts_inside)), replace=False)
    sub = pts_inside[take]
    vs_c = []
    for fac in SHAPE_FACTORS:
        c = field.shape * fac
        row = {"shape": c}
        try:
            f2 = rbf.solve(cc, field.basis, c, local=local, ring=ring, **({"only": only} if local else {}))
            row["porosity"] = float(np.mean(f2.phi(sub) < iso))
        except InputError as exc:
            row["porosity"] = None
            row["error"] = str(exc)
        vs_c.append(row)
    return {"basis": field.basis, "vs_iso": {"shape": field.shape, "rows": vs_iso},
            "vs_shape": {"iso": float(iso), "samples": int(len(sub)),
                         "cells": None if only is None else int(len(only)), "rows": vs_c},
            "increases_with_iso": _monotonic([r["porosity"] for r in vs_iso]),
            "increases_with_shape": _monotonic([r["porosity"] for r in vs_c])}


def _check_number(value, name):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v):
        raise InputError(f"{name} must be finite, got {value!r}")
    return v


def run_arbf(recipe: dict, force: bool = False, progress=None) -> dict:
    """Run an ``arbf`` recipe; write its outputs atomically; return the report."""
    from .bodies.mesh import MeshBody
    from .fields import rbf
    from .mesh.polygonise import Grid, polygonise
    from .mesh.validate import signed_volume
    from .outputs import check_outputs, finish_job, validated_report

    t_start = time.perf_counter()
    out = dict(recipe.get("output", {}))
    check_outputs(out, ("mesh", "report"), force)
    spec = dict(recipe.get("arbf", {}))
    basis = rbf.BASES[rbf.check_basis(spec.get("basis", "imq"))]
    shape = rbf.check_shape(spec.get("shape", 0.1))
    iso = _check_number(spec.get("iso", 0.0), "--iso")
    local = bool(spec.get("local", False))
    ring = str(spec.get("ring", "vertex"))
    if ring not in ("vertex", "face"):
        raise InputError(f"unknown neighbour ring {ring!r}; use vertex or face")
    jitter = _check_number(spec.get("jitter", 0.0), "--jitter")
    if jitter < 0:
        raise InputError(f"--jitter must be a length ≥ 0 in mm, got {jitter:g}")
    seed = spec.get("seed", 0)
    if seed is not None and (isinstance(seed, bool) or int(seed) != seed or int(seed) < 0):
        raise InputError(f"--seed must be a non-negative integer, got {seed!r}")
    resolution = dict(recipe.get("mesh", {})).get("resolution", 24)
    if isinstance(resolution, bool) or int(resolution) != resolution or int(resolution) < 3:
        raise InputError(f"--resolution (grid samples per mean element edge) must be an integer ≥ 3, "
                         f"got {resolution!r}")
    resolution = int(resolution)
    warnings, timings = [], {}
    if not -1.0 < iso < 1.0:
        warnings.append(f"iso-value {iso:g} lies outside (-1, 1), the range between the skeleton (-1) and "
                        "vertex (+1) values: expect no pores or no material")

    def stage(name, done, total):
        if progress is not None:
            progress(name, done, total)

    cc, surf, outer, domain_volume, dinfo = arbf_domain(dict(recipe.get("domain", {})))
    timings["domain_s"] = dinfo.pop("time_s")
    if jitter > 0:
        cc = cc.with_centres(cc.centres.jittered(jitter, None if seed is None else int(seed)))
    report = {"job": "arbf", "porecad_version": __version__, "basis": basis, "shape": shape, "iso": iso,
              "domain": dinfo, "n_centres": int(cc.centres.n), "centres": cc.centres.counts(),
              "jitter": {"amount": jitter, "seed": None if seed is None else int(seed)} if jitter > 0 else None,
              "resolution": resolution}

    t = time.perf_counter()
    field = rbf.solve(cc, basis, shape, local=local, ring=ring,
                      progress=(lambda d, n: stage("solve", d, n)) if local else None)
    field = field.with_iso(iso)
    report["solve"] = dict(field.info)
    if local:
        jump = report["solve"]["face_jump"] = rbf.face_jumps(field, cc)
        if jump is not None and jump["rms"] > 0.1:
            warnings.append(f"the local systems disagree across cell faces (jump RMS {jump['rms']:.3g}, max "
                            f"{jump['max']:.3g}): the {basis} basis reaches beyond the neighbour ring; try "
                            + ("--ring face, " if ring == "vertex" else "") + "--basis gaussian or a smaller --shape")
    timings["solve_s"] = time.perf_counter() - t

    h = cc.scale / (resolution - 1)
    sv, sf = surf
    lo, hi = sv.min(axis=0) - 2 * h, sv.max(axis=0) + 2 * h
    grid = Grid.from_box(lo, hi, spacing=h)
    if grid.n_samples > MAX_SAMPLES:
        raise ResourceError(f"the sampling grid would have {grid.n_samples:,} samples (at most "
                            f"{MAX_SAMPLES:,}); lower --resolution")
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    t = time.perf_counter()
    phi = field.phi_grid(xs, ys, zs)
    timings["evaluate_s"] = time.perf_counter() - t
    t = time.perf_counter()
    hull = MeshBody(sv, sf, band=4 * max(grid.spacing))
    dom = hull.sample_grid(xs, ys, zs)
    timings["domain_distance_s"] = time.perf_counter() - t
    inside = dom < 0
    if not inside.any():
        raise InputError("no grid sample falls inside the domain; raise --resolution")
    phi_in = phi[inside]
    report["value_range"] = [float(phi_in.min()), float(phi_in.max())]
    report["porosity_samples"] = float(np.mean(phi_in < iso))
    report["grid"] = {"shape": list(grid.shape), "spacing": h, "samples": int(grid.n_samples)}

    t = time.perf_counter()
    material = np.maximum(np.float32(iso) - phi, dom).astype(np.float32)

    def sample(xx, yy, zz):
        idx = [np.rint((np.asarray(q) - ax[0]) / hh).astype(np.int64)
               for q, ax, hh in ((zz, zs, grid.spacing[2]), (yy, ys, grid.spacing[1]), (xx, xs, grid.spacing[0]))]
        return material[np.ix_(*idx)]

    res = polygonise(sample, grid, caps=True,
                     progress=(lambda d, n: stage("mesh", d, n)) if progress is not None else None)
    vertices, faces = res.vertices, res.faces.astype(np.int64)
    timings["polygonise_s"] = time.perf_counter() - t
    if len(faces) == 0:
        raise InputError(f"iso-value {iso:g} leaves no material in the domain (Φ spans "
                         f"{report['value_range'][0]:.3g} … {report['value_range'][1]:.3g}); lower --iso")

    t = time.perf_counter()
    network = pore_network(phi, dom, iso, (xs, ys, zs), h, outer)
    network.update({f"mesh_{k}": v for k, v in mesh_shells(vertices, faces).items()})
    report["network"] = network
    timings["network_s"] = time.perf_counter() - t
    if not network.get("opens_on_every_outer_face"):
        warnings.append(f"the pore network opens on {network.get('open_outer_faces', 0)} of "
                        f"{network.get('outer_faces')} outer faces; raise --iso or --shape for wider channels")
    if network.get("mesh_solid_pieces", 1) > 1:
        warnings.append(f"the material falls into {network['mesh_solid_pieces']} separate pieces; lower --iso "
                        "for thicker struts")
    if network.get("pore_components", 0) > 1:
        warnings.append(f"the pores form {network['pore_components']} separate networks "
                        f"({network['closed_pores']} closed)")

    t = time.perf_counter()
    mesh_rep, _ = validated_report(vertices, faces, domain_volume, check_intersections=len(faces) <= 2_000_000,
                                   what="the ARBF scaffold")
    report.update(mesh_rep)
    report["porosity"] = 1.0 - float(signed_volume(vertices, faces)) / domain_volume
    report["domain_volume"] = domain_volume
    timings["validate_s"] = time.perf_counter() - t

    if spec.get("table", True):
        t = time.perf_counter()
        k, j, i = np.nonzero(inside)
        pts_in = np.column_stack([xs[i], ys[j], zs[k]])
        report["porosity_table"] = porosity_table(field, cc, phi_in, pts_in, iso, local, ring)
        timings["table_s"] = time.perf_counter() - t

    if warnings:
        report["warnings"] = warnings
    return finish_job(report, vertices, faces, out, force, timings, t_start, domain_volume=domain_volume,
                      design=False)
