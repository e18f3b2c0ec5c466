"""Previews: the design's own job on a coarser sampling, a representative window, a display mesh.

A preview never has a code path of its own for the geometry: it runs the
recipe the export will run (:func:`porecad.jobs.parse` and the job's ``run``)
with only the sampling changed (:func:`coarse_recipe`: ``sampling.resolution``
or ``sampling.voxel``, ``mesh.resolution``, ``voxel``), bounded by a sample
budget so that a part of any size previews in about the same time. Lattice
designs (``tpms``, ``infill``) also get a *window*: the job's own solid field
(:func:`porecad.lattice.plan.plan_lattice`) polygonised at the export's
sample spacing in a box of two cells at the deepest point of the body, closed
on the box faces — the structure exactly as it will be built, small enough to
analyse. What is sent to the browser is a display mesh of at most a budget of
triangles (:func:`display_mesh`: vertex clustering, a level-of-detail mesh
that is for the eye only; the validity flags are those of the job's mesh).
"""

from __future__ import annotations

import copy
import json
import math
import struct

import numpy as np

from ..errors import InputError

#: sample budgets: the first (coarse) preview, the refined one, the window
COARSE_SAMPLES = 150_000
REFINED_SAMPLES = 2_000_000
WINDOW_SAMPLES = 400_000
#: triangles sent to the browser for one mesh
DISPLAY_FACES = 400_000
#: voxels of the pore/strut analysis
ANALYSIS_VOXELS = 150_000


class Superseded(Exception):
    """The preview or export was cancelled (a newer design, or the user)."""


def checked_progress(cancelled, progress=None):
    """A job ``progress(stage, done, total)`` that raises :class:`Superseded` once ``cancelled()`` is true."""
    def cb(stage, done, total):
        if cancelled():
            raise Superseded()
        if progress is not None:
            progress(stage, done, total)
    return cb


# ------------------------------------------------------------------------------------------------ sampling

def _per_cell(budget: float, n_cells: float, lo: int, hi: int) -> int:
    return int(min(hi, max(lo, math.floor((budget / max(n_cells, 1.0)) ** (1.0 / 3.0)) + 1)))


def coarse_recipe(recipe: dict, budget: float, bounds=None) -> tuple[dict, dict]:
    """The recipe with its sampling coarsened to about ``budget`` samples; and what was changed.

    Parameters
    ----------
    recipe : dict
        The design's recipe (as exported).
    budget : float
        Samples (or samples per period × periods) to aim for.
    bounds : (lo, hi), optional
        The body's box (``infill``: the voxel is chosen from it).

    Returns
    -------
    recipe : dict
        A copy; only sampling keys differ (and a box lattice may be cut to a
        window of cells, then ``info["window_cells"]`` says so).
    info : dict
        ``sampling`` (what the preview used) and ``export_sampling``.
    """
    r = copy.deepcopy(recipe)
    job = r["job"]
    info: dict = {}
    if job == "tpms":
        cells = [int(c) for c in r["domain"]["cells"]]
        res = int(r["sampling"]["resolution"])
        n = _per_cell(budget, float(np.prod(cells)), 4, res)
        if n < 8 and np.prod(cells) > 27 and "grading" not in r:
            # a uniform lattice: a representative window of cells rather than a mush of all of them
            win = [min(c, 3) for c in cells]
            info["window_cells"] = win
            r["domain"]["cells"] = win
            n = _per_cell(budget, float(np.prod(win)), 4, res)
        r["sampling"]["resolution"] = n
        info.update(sampling={"resolution": n}, export_sampling={"resolution": res})
    elif job == "infill":
        lo, hi = (np.asarray(b, float) for b in bounds)
        ext = hi - lo
        export_h = r["sampling"].get("voxel") or float(ext.min()) / 200.0
        h = max(float(export_h), float(np.prod(ext) / budget) ** (1.0 / 3.0))
        r["sampling"] = {"voxel": h}
        cell = r["tpms"]["cell_size"]
        if not isinstance(cell, dict):
            # samples per cell: below about 6 the whole-part preview is a sketch of the lattice
            info["per_cell"] = float(np.min(np.asarray(cell, float))) / h
        info.update(sampling={"voxel": h}, export_sampling={"voxel": export_h})
    elif job in ("tbss", "hex", "tis"):
        res = int(r["mesh"]["resolution"])
        if job == "tbss":
            n_cells = float(np.prod(r["tpms"]["periods"]))
        elif job == "hex":
            n_cells = float(np.prod(r["grid"]))
        else:
            n_cells = float(r["domain"].get("tets", 1) if r["domain"]["kind"] == "body" else 5)
        n = _per_cell(budget, n_cells, 4, res)
        r["mesh"]["resolution"] = n
        info.update(sampling={"resolution": n}, export_sampling={"resolution": res})
    elif job == "vessel":
        voxel = float(r["voxel"])
        if bounds is not None:
            lo, hi = (np.asarray(b, float) for b in bounds)
            voxel = max(voxel, float(np.prod(hi - lo) / budget) ** (1.0 / 3.0))
        r["voxel"] = voxel
        info.update(sampling={"voxel": voxel}, export_sampling={"voxel": float(recipe["voxel"])})
    return r, info


def run_job(recipe: dict, progress=None, threads=None):
    """Run a recipe's job without writing anything: ``(vertices, faces, report)`` (common report keys)."""
    from ..jobs import run_in_memory
    v, f, report = run_in_memory(recipe, threads=threads, progress=progress)
    return np.asarray(v), np.asarray(f), report


# ------------------------------------------------------------------------------------------------ window

def window_box(plan, cells: float = 2.0):
    """A box ``cells`` cells wide at the deepest point of the body (the centre of a box lattice).

    ``plan``: a :class:`~porecad.lattice.plan.LatticePlan`.
    """
    grid = plan.grid
    lo, hi = grid.box_min, grid.box_max
    cell = np.asarray(plan.cell_size, float)
    half = 0.5 * cells * cell
    if plan.body is None:
        centre = 0.5 * (lo + hi)
    else:
        n = 24
        axes = [np.linspace(lo[a], hi[a], n) for a in range(3)]
        d = plan.body.sample_grid(*axes)  # (z, y, x), negative inside
        k, j, i = np.unravel_index(int(np.argmin(d)), d.shape)
        centre = np.array([axes[0][i], axes[1][j], axes[2][k]])
    wlo = np.maximum(centre - half, lo)
    whi = np.minimum(centre + half, hi)
    return wlo, whi


def window_mesh(recipe: dict, progress=None, threads=None):
    """The design's solid in a two-cell window at the export's sampling: ``(vertices, faces, info)``.

    ``info`` has the window box, the sample spacing and the porosity of the
    window (void fraction of the body inside it, from the samples).
    """
    from ..jobs import parse
    from ..lattice.plan import plan_lattice
    from ..mesh.grid import Grid
    from ..mesh.polygonise import polygonise
    _, spec, _, _ = parse(recipe)
    plan = plan_lattice(spec)
    wlo, whi = window_box(plan)
    h = np.asarray(plan.grid.spacing, float)
    vol = float(np.prod(whi - wlo))
    h = np.maximum(h, (vol / WINDOW_SAMPLES) ** (1.0 / 3.0))
    grid = Grid.from_box(wlo, whi, spacing=h)
    field = plan.field if plan.body is None or plan.boundary != "whole" else plan.material & plan.body
    prog = None if progress is None else (lambda done, total: progress("window", done, total))
    res = polygonise(field.sample_grid, grid, caps=True, threads=threads, progress=prog)
    if len(res.faces) == 0:
        raise InputError("the window holds no material: the structure is empty here")
    inside_body = 1.0
    if plan.body is not None:
        b = polygonise(plan.body.sample_grid, grid, caps=True, threads=threads)
        inside_body = b.inside_fraction
    porosity = 1.0 - res.inside_fraction / inside_body if inside_body > 0 else None
    return res.vertices, res.faces, {"box": [wlo.tolist(), whi.tolist()], "spacing": list(map(float, grid.spacing)),
                                     "porosity": porosity, "cell_size": np.asarray(plan.cell_size).tolist()}


# ------------------------------------------------------------------------------------------------ display

def display_mesh(vertices, faces, max_faces: int = DISPLAY_FACES):
    """A level-of-detail mesh of at most ``max_faces`` triangles (vertex clustering; for display only).

    Vertices are merged in cubic cells whose size starts from the surface
    area (``F ≈ 2 A / s²``) and grows until the budget holds; faces that
    collapse are dropped. Returns ``(vertices, faces, cell)`` with ``cell``
    None when nothing was merged.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) <= max_faces:
        return v, f, None
    tri = v[f]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    s = math.sqrt(2.0 * area / max_faces) if area > 0 else float(np.ptp(v, axis=0).max()) / 100
    lo = v.min(axis=0)
    for _ in range(30):
        key = np.floor((v - lo) / s).astype(np.int64)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        nf = inverse[f]
        keep = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
        nf = nf[keep]
        if len(nf) <= max_faces:
            nv = np.zeros((len(counts), 3))
            np.add.at(nv, inverse, v)
            nv /= counts[:, None]
            return nv, nf, s
        s *= 1.3
    raise InputError("cannot reduce this mesh for display")  # pragma: no cover - s grows without bound


def pack_mesh(vertices, faces) -> bytes:
    """``b"PCM1"``, vertex and face counts (uint32), float32 positions, uint32 indices (little endian)."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    f = np.ascontiguousarray(faces, dtype="<u4")
    return b"PCM1" + struct.pack("<II", len(v), len(f)) + v.tobytes() + f.tobytes()


def pack_blob(meta: dict, *arrays) -> bytes:
    """A JSON header and raw arrays: uint32 header length, the header, then the arrays' bytes back to back."""
    head = json.dumps(meta).encode()
    pad = (-(4 + len(head))) % 4
    head += b" " * pad
    return struct.pack("<I", len(head)) + head + b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)


# ------------------------------------------------------------------------------------------------ analysis

def thickness_analysis(vertices, faces, min_feature: float | None = None, max_voxels: int = ANALYSIS_VOXELS):
    """Pore and strut sizes of a closed mesh, and its local-thickness volume for the section view.

    Runs :func:`porecad.analysis.pores.pore_analysis` (maximal inscribed
    spheres on a voxel grid of at most ``max_voxels``). Returns
    ``(stats, meta, strut, pore)``: the statistics, the section header
    (grid shape ``[nz, ny, nx]``, origin, spacing, thickness scales) and the
    strut and pore local thickness quantised to uint8 (``value × scale`` mm;
    0 is the other phase).
    """
    from ..analysis.pores import pore_analysis
    v = np.asarray(vertices, float)
    ext = np.ptp(v, axis=0)
    h = float(np.prod(np.maximum(ext, 1e-9)) / max_voxels) ** (1.0 / 3.0)
    h = max(h, float(ext.max()) / 400.0)
    stats = pore_analysis(v, faces, spacing=h, min_feature=min_feature or None, keep_fields=True)
    fields = stats.pop("_fields")
    strut, pore = fields["strut"], fields["pore"]
    s_max = float(strut.max()) or 1.0
    p_max = float(pore.max()) or 1.0
    q_strut = np.where(fields["solid"], np.clip(np.round(strut / s_max * 254) + 1, 1, 255), 0).astype(np.uint8)
    q_pore = np.where(~fields["solid"], np.clip(np.round(pore / p_max * 254) + 1, 1, 255), 0).astype(np.uint8)
    thin = None
    if min_feature:
        solid = fields["solid"]
        n_solid = int(solid.sum())
        thin = float((solid & (strut < min_feature)).sum() / n_solid) if n_solid else 0.0
    stats["thin_fraction"] = thin
    meta = {"shape": list(q_strut.shape), "origin": np.asarray(fields["origin"]).tolist(),
            "spacing": float(fields["spacing"]), "strut_scale": s_max / 254, "pore_scale": p_max / 254,
            "strut_max": s_max, "pore_max": p_max, "min_feature": min_feature}
    return stats, meta, q_strut, q_pore


def curve(tpms_type: str, structure: str, points: int = 121) -> dict:
    """The porosity–threshold curve of a type and structure, with its valid range (for the plot)."""
    from ..calibration import abs_phi_samples, phi_samples, porosity_of_threshold, valid_range
    v = abs_phi_samples(tpms_type) if structure == "sheet" else phi_samples(tpms_type)
    c = np.linspace(float(v[0]), float(v[-1]), points)
    p = np.asarray(porosity_of_threshold(tpms_type, structure, c), float)
    return {"type": tpms_type, "structure": structure, "threshold": c.tolist(), "porosity": p.tolist(),
            "valid": valid_range(tpms_type, structure)}


def operating_points(recipe: dict, report: dict | None) -> list[dict]:
    """The design's (threshold, porosity) points on its curve: one, or the two ends of a grading."""
    from ..calibration import porosity_of_threshold, threshold_for_porosity
    tp = recipe.get("tpms") or {}
    t, s = tp.get("type"), tp.get("structure")
    if not t or s not in ("pore", "rod", "sheet"):
        return []
    vals = []
    if tp.get("threshold") is not None:
        vals.append(("threshold", float(tp["threshold"])))
    elif tp.get("porosity") is not None:
        vals.append(("porosity", float(tp["porosity"])))
    for key in ("grading",):
        g = recipe.get(key)
        if isinstance(g, dict):
            for k in ("from", "to"):
                if g.get(k) is not None:
                    vals.append((g.get("of", "threshold"), float(g[k])))
            if g.get("kind") == "expression" and report:
                for k in ("porosity_min", "porosity_max"):
                    if report.get(k) is not None:
                        vals.append(("porosity", float(report[k])))
    tdf = recipe.get("tdf") or {}
    for k in ("porosity", "threshold"):
        if tdf.get(f"{k}_range"):
            vals += [(k, float(x)) for x in tdf[f"{k}_range"]]
    out = []
    for of, x in vals:
        try:
            if of == "threshold":
                out.append({"threshold": x, "porosity": float(porosity_of_threshold(t, s, x))})
            else:
                out.append({"threshold": float(threshold_for_porosity(t, s, x)), "porosity": x})
        except InputError:
            continue
    return out
