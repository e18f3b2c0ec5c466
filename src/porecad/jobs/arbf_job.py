"""The ``arbf`` job: anisotropic-RBF pore networks over tet and hex meshes and point clouds (000 ch.5).

Steps (000 Figs. 5.4 and 5.5): a domain (a built-in tet or hex mesh, a
volume-mesh file, a closed body tetrahedralised on a BCC lattice, or a point
cloud with values), its centres and values (000 §5.3, see
:mod:`porecad.fields.rbf`), optionally moved at random (000 Fig. 5.10), the
weights by one global solve or per-cell local solves, the interpolant ``Φ``
sampled on a regular grid, the material ``{Φ ≥ iso}`` intersected with the
domain, ``max(iso − Φ, d_domain)`` with ``d_domain`` the signed distance to
the domain's boundary surface (negative inside), polygonised by the chunked
marching cubes of the Foundation into a closed solid; validated and written.
Pieces of material that do not touch the largest one (islands, which a
printer cannot hold in place) are dropped and reported by the runner's
promise check (:mod:`porecad.jobs.promise`) unless ``islands = "keep"``.

The domain is the volume of the mesh; for a closed body it is the body
itself (the scaffold is cut to it); for a point cloud it is the points'
axis-aligned bounding box. ``porosity`` is the void fraction of the domain,
``1 − V(solid) / V(domain)``, from the mesh volume; ``porosity_samples`` the
fraction of the grid samples inside the domain with ``Φ < iso``.

Recipe::

    job = "arbf"
    [domain]  kind = "tet" | "two-tets" | "icosahedron" | "hex" | "hex2x2x2" | "hex-rod"
                     | "mesh-file" | "body" | "points",  path, size = 10.0, tets = 1000
    [arbf]    basis = "imq", shape = 0.1, iso = 0.0, local = false, ring = "vertex",
              jitter = 0.0 (mm), seed = 0, table = true,
              islands = "drop" | "keep" (loose pieces of material besides the largest)
    [mesh]    resolution = 24 (grid samples per mean element edge)
    [output]  mesh, report, recipe
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import InputError, ResourceError
from ..findings import Finding
from ..mesh.weld import compact
from .contract import Job, Result, RunOptions, Timer, Validation

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
    from ..volmesh.hexshapes import HEX_FACES, single_hex
    p, h = single_hex(1.0)
    v = lo + p * (hi - lo)
    q = h[0][HEX_FACES]
    return v, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


def arbf_domain(kind: str, path=None, size: float = 10.0, tets: int = 1000):
    """Build the domain of a recipe.

    Returns ``(cc, surface, outer, volume, info)``: the :class:`~porecad.fields.rbf.CellCentres`;
    the closed outward triangle surface ``(v, f)`` the material is cut to;
    the outer faces as ``(centroids (F, 3), kind)`` for the openness check
    (``kind`` "faces" or "box"); the domain volume (mm³); a dict for the report.
    """
    from .. import volmesh as vm
    from ..fields import rbf
    from ..mesh.validate import signed_volume
    from ..volmesh import hexshapes as hs

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
            points, cells, ckind = vm.read_volume_mesh(path)
            info["path"] = str(path)
        elif kind == "body":
            points, cells, body, _, binfo = vm.tetrahedralise_body(path, tets)
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
        pts, vals = rbf.read_points(path)
        cc = rbf.point_cloud_centres(pts, vals)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        if np.any(hi - lo <= 1e-9 * max(float(np.max(hi - lo)), 1e-300)):
            raise InputError(f"{path}: the points span no volume (their bounding box is flat)")
        surf = _box_surface(lo, hi)
        outer = np.stack([lo, hi])
        volume = float(np.prod(hi - lo))
        info.update(path=str(path), cells="points", n_points=int(len(pts)),
                    values={"min": float(vals.min()), "max": float(vals.max())},
                    domain="the bounding box of the points", **cc.info)
        outer_kind = "box"
    else:
        raise InputError(f"unknown ARBF domain {kind!r}; use {', '.join(BUILTIN_TET + BUILTIN_HEX)}, "
                         "a mesh file, or `points` from a file")
    info["volume"] = volume
    info["length_scale"] = float(cc.scale)
    info["time_s"] = time.perf_counter() - t0
    return cc, surf, (outer, outer_kind), volume, info


def _monotonic(values) -> bool:
    v = [x for x in values if x is not None]
    return bool(len(v) >= 2 and all(b >= a for a, b in zip(v, v[1:])))


def porosity_table(field, cc, phi_inside, pts_inside, iso, local, ring, seed=0):
    """Porosity of the sample grid vs the iso-value (at the chosen ``c``) and vs ``c`` (at the chosen iso).

    The iso column uses every sample inside the domain; the ``c`` column
    re-solves the system for each ``c`` (same solve) and evaluates ``Φ`` at
    up to :data:`TABLE_SAMPLES` random samples inside the domain (for a local
    solve on more than :data:`TABLE_CELLS` cells, samples in that many random
    cells, whose systems alone are re-solved).
    """
    from ..fields import rbf
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




DOMAIN_KINDS = BUILTIN_TET + BUILTIN_HEX + ("mesh-file", "body", "points")


@dataclasses.dataclass(frozen=True)
class ArbfSpec:
    """A checked ``arbf`` recipe (see the module docstring for the keys)."""

    domain_kind: str
    domain_path: str | None
    size: float
    tets: int
    basis: str
    shape: float
    iso: float
    local: bool
    ring: str
    jitter: float
    seed: int
    table: bool
    resolution: int
    islands: str = "drop"

    @classmethod
    def from_recipe(cls, r):
        from ..fields import rbf
        d = r.table("domain")
        kind = d.get("kind")
        needs_path = kind in ("mesh-file", "body", "points")
        path = d.get("path") if needs_path else None
        if needs_path and path is None:
            raise d.error("path", f"a {kind} domain needs a path")
        size = d.get("size")
        tets = d.get("tets")
        if d.has("tets") and kind != "body":
            raise d.error("tets", "sets the tet count of a tetrahedralised surface body; this domain is given")
        d.done()
        a = r.table("arbf")
        basis = rbf.BASES[a.get("basis", check=rbf.check_basis)]
        shape = a.get("shape", check=rbf.check_shape)
        iso = a.get("iso")
        local = a.get("local")
        ring = a.get("ring")
        jitter = a.get("jitter")
        seed = a.get("seed")
        if a.has("seed") and not jitter:
            raise a.error("seed", "needs a jitter (the random displacement of the centres, mm)")
        table = a.get("table")
        islands = a.get("islands")
        a.done()
        m = r.table("mesh")
        resolution = m.get("resolution")
        m.done()
        return cls(kind, path, size, tets, basis, shape, iso, local, ring, jitter, seed, table, resolution, islands)

    def inputs(self) -> list:
        return [self.domain_path] if self.domain_path else []


def run(spec: ArbfSpec, progress=None, options=None) -> Result:
    """Build the ARBF scaffold of ``spec`` (nothing written).

    The stages: the domain (:func:`arbf_domain`: centres, its surface) → :func:`_solve` (the RBF
    field at the iso-value, with how well the local systems agree) → :func:`_sample` (the field and
    the domain on one grid) → polygonise the material → :func:`_network_findings` (the pore network
    and whether it opens) → the porosity table; the runner then checks the solid.
    """
    from ..mesh.polygonise import GridArraySampler, polygonise
    from .contract import stage_progress

    timer = (options or RunOptions()).stages  # the runner's stage clock: it reports the timings
    warnings = []
    iso = spec.iso
    if not -1.0 < iso < 1.0:
        warnings.append(Finding("iso-outside", f"iso-value {iso:g} lies outside (-1, 1), the range between the "
                                "skeleton (-1) and vertex (+1) values: expect no pores or no material", {"iso": iso}))
    memory_limit = getattr(options, "memory_limit", None)
    if spec.domain_kind == "body":  # sized from the target tet count before the body is tetrahedralised
        require_size(spec, spec.tets * (spec.resolution - 1) ** 3 / 8.5, memory_limit)
    with timer("domain"):
        cc, surf, outer, domain_volume, dinfo = arbf_domain(spec.domain_kind, spec.domain_path, spec.size,
                                                            spec.tets)
    dinfo.pop("time_s", None)
    if spec.jitter > 0:
        cc = cc.with_centres(cc.centres.jittered(spec.jitter, spec.seed))
    report = {"basis": spec.basis, "shape": spec.shape, "iso": iso, "domain": dinfo,
              "n_centres": int(cc.centres.n), "centres": cc.centres.counts(),
              "jitter": {"amount": spec.jitter, "seed": spec.seed} if spec.jitter > 0 else None,
              "resolution": spec.resolution}
    field = _solve(spec, cc, report, warnings, timer, progress)
    grid, phi, dom, inside = _sample(spec, field, cc, surf, report, timer, memory_limit)
    with timer("polygonise"):
        material = np.maximum(np.float32(iso) - phi, dom).astype(np.float32)
        res = polygonise(GridArraySampler(material, grid), grid, caps=True, progress=stage_progress(progress, "mesh"))
        vertices, faces = res.vertices, res.faces.astype(np.int64)
    if len(faces) == 0:
        raise InputError(f"iso-value {iso:g} leaves no material in the domain (Φ spans "
                         f"{report['value_range'][0]:.3g} … {report['value_range'][1]:.3g}); lower the iso-value")
    warnings += _network_findings(phi, dom, iso, grid, outer, vertices, faces, report, timer)
    check = options.check_intersections if options and options.check_intersections is not None \
        else len(faces) <= 2_000_000
    if spec.table:
        with timer("table"):
            xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
            k, j, i = np.nonzero(inside)
            pts_in = np.column_stack([xs[i], ys[j], zs[k]])
            report["porosity_table"] = porosity_table(field, cc, phi[inside], pts_in, iso, spec.local, spec.ring)
    report["warnings"] = warnings
    return Result(report, vertices, faces, domain_volume=domain_volume, domain=surf, design=False,
                  body=surf if spec.domain_kind == "body" else None,
                  validation=Validation("the ARBF scaffold", domain_volume, intersections=check))


def _solve(spec: ArbfSpec, cc, report: dict, warnings: list, timer: Timer, progress):
    """The RBF field of the centres at the iso-value; ``cells-disagree`` where local systems jump across faces."""
    from ..fields import rbf
    from .contract import stage_progress
    with timer("solve"):
        field = rbf.solve(cc, spec.basis, spec.shape, local=spec.local, ring=spec.ring,
                          progress=stage_progress(progress, "solve") if spec.local else None)
        field = field.with_iso(spec.iso)
    report["solve"] = dict(field.info)
    if spec.local:
        jump = report["solve"]["face_jump"] = rbf.face_jumps(field, cc)
        if jump is not None and jump["rms"] > 0.1:
            warnings.append(Finding(
                "cells-disagree", f"the local systems disagree across cell faces (jump RMS {jump['rms']:.3g}, max "
                f"{jump['max']:.3g}): the {spec.basis} basis reaches beyond the neighbour ring; try "
                + ("the face ring, " if spec.ring == "vertex" else "") + "the gaussian basis or a smaller shape",
                {"jump_rms": jump["rms"], "jump_max": jump["max"], "limit": 0.1}))
    return field


#: ARBF triangles per (sample spacing)² of area: :data:`porecad.resources.TRIS_PER_AREA`, over the pores' walls
#: (:data:`porecad.resources.MAPPED_AREA_PER_CELL` per element edge, per element volume) and the caps where the
#: solid meets the domain's boundary (half its area). Measured (bench/estimates.md) 1.14-1.39 times the triangles
#: made by one tet, one hex, a rod of 4 hexes and 321 tets in a blob; the grid's box alone (the bound before)
#: made 1.5-4.9 times them, the most for one tet (a sixth of its box)
ARBF_CAP_FRACTION = 0.5


def require_size(spec: ArbfSpec, samples: float, memory_limit=None, domain=None) -> None:
    """Refuse (ResourceError, one line with the estimate) a grid over :data:`MAX_SAMPLES` or the memory.

    A tet of mean edge ``a`` holds about ``(resolution - 1)³ / 8.5`` samples; the triangles are bounded as a
    TPMS's of cells of edge ``a`` (:func:`porecad.resources.mapped_estimate`); each sample holds Φ, the
    domain's distance, the material and the inside mask (24 bytes). With ``domain`` (its volume, its boundary's
    area and the mean element edge ``a``, mm) the triangles are those of the pores' walls in the domain and of
    the caps on its boundary (:data:`ARBF_CAP_FRACTION`).
    """
    from ..resources import (BYTES_PER_MAPPED_TRIANGLE, MAPPED_AREA_PER_CELL, SECONDS_PER_MAPPED_TRIANGLE,
                             TRIS_PER_AREA, mapped_estimate, require_fits, work_estimate)
    change = "lower the `resolution` or the tet count (`tets`)"
    if samples > MAX_SAMPLES:
        raise ResourceError(f"the sampling grid would have about {samples:,.0f} samples (at most {MAX_SAMPLES:,}); "
                            f"{change}")
    r = spec.resolution - 1
    if domain is None:
        est = mapped_estimate([samples / r ** 3], r, sample_bytes=24)
    else:
        volume, area, a = (float(x) for x in domain)
        h = a / r
        tris = TRIS_PER_AREA * (MAPPED_AREA_PER_CELL * volume / a + ARBF_CAP_FRACTION * area) / (h * h)
        est = work_estimate(samples, tris, sample_bytes=24, triangle_bytes=BYTES_PER_MAPPED_TRIANGLE,
                            triangle_seconds=SECONDS_PER_MAPPED_TRIANGLE)
    require_fits(est, memory_limit, change, "the ARBF scaffold")


def _sample(spec: ArbfSpec, field, cc, surf, report: dict, timer: Timer, memory_limit=None):
    """The field and the domain's signed distance on one grid (bounded): ``(grid, phi, dom, inside)``."""
    from ..bodies.mesh import MeshBody
    from ..mesh.polygonise import Grid
    h = cc.scale / (spec.resolution - 1)
    sv, sf = surf
    grid = Grid.from_box(sv.min(axis=0) - 2 * h, sv.max(axis=0) + 2 * h, spacing=h)
    tri = sv[sf]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    volume = abs(float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum())) / 6.0
    require_size(spec, grid.n_samples, memory_limit, domain=(volume, area, cc.scale))
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    with timer("evaluate"):
        phi = field.phi_grid(xs, ys, zs)
    with timer("domain_distance"):
        dom = MeshBody(sv, sf, band=4 * max(grid.spacing)).sample_grid(xs, ys, zs)
    inside = dom < 0
    if not inside.any():
        raise InputError("no grid sample falls inside the domain; raise the resolution")
    phi_in = phi[inside]
    report["value_range"] = [float(phi_in.min()), float(phi_in.max())]
    report["porosity_samples"] = float(np.mean(phi_in < spec.iso))
    report["grid"] = {"shape": list(grid.shape), "spacing": h, "samples": int(grid.n_samples)}
    return grid, phi, dom, inside


def _network_findings(phi, dom, iso, grid, outer, vertices, faces, report: dict, timer: Timer) -> list:
    """The pore network (``report["network"]``); ``pores-shut`` and ``pores-split`` where it does not open as one."""
    from ..analysis.networks import pore_network
    from ..mesh.shells import mesh_shells
    with timer("network"):
        network = pore_network(phi, dom, iso, (grid.axis(0), grid.axis(1), grid.axis(2)), report["grid"]["spacing"],
                               outer)
        network.update({f"mesh_{k}": v for k, v in mesh_shells(vertices, faces).items()})
    report["network"] = network
    found = []
    if not network.get("opens_on_every_outer_face"):
        found.append(Finding(
            "pores-shut", f"the pore network opens on {network.get('open_outer_faces', 0)} of "
            f"{network.get('outer_faces')} outer faces; raise the iso-value or the shape parameter for wider "
            "channels", {"open_faces": network.get("open_outer_faces", 0), "faces": network.get("outer_faces")}))
    if network.get("pore_components", 0) > 1:
        found.append(Finding("pores-split", f"the pores form {network['pore_components']} separate networks "
                             f"({network['closed_pores']} closed)",
                             {"networks": network["pore_components"], "closed": network["closed_pores"]}))
    return found


JOB = Job("arbf", ArbfSpec, run, summary=("basis", "shape", "iso", "porosity"),
          title="anisotropic-RBF pore networks over tet/hex meshes and point clouds (000 ch.5)")
