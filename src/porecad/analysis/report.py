"""`porecad analyze`: the metrics of a mesh and the report directory (JSON, HTML, PNG plots).

The HTML report is self-contained for offline use: one HTML file with the
tables, and PNG images beside it (matplotlib, Agg backend) — pore and strut
size histograms, a curvature histogram, three cross-sections through the
middle of the part coloured by local thickness, and a shaded 3D preview
(a depth render of the voxelisation).
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path

import numpy as np

from ..errors import InputError

#: files written into a report directory
REPORT_FILES = ("report.json", "report.html", "pore_sizes.png", "strut_sizes.png", "curvature.png",
                "sections.png", "preview.png")


def analyze_mesh(path, domain_volume=None, check_intersections=True, pores=False, voxel=None,
                 min_feature=None, min_pore=None, keep_fields=False):
    """Metrics of a mesh file; returns ``(report, fields)`` (fields: arrays for plots, or None)."""
    from ..io import read_mesh
    from ..mesh.validate import check_solid, smallest_angle
    from .basic import mesh_report
    from .curvature import curvature_stats, vertex_curvatures

    vertices, faces = read_mesh(path)
    if len(faces) == 0:
        raise InputError(f"{path}: the mesh has no triangles")
    for name, value in (("voxel", voxel), ("min-feature", min_feature), ("min-pore", min_pore)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise InputError(f"--{name} must be a positive number of mm, got {value}")
    if domain_volume is None:
        ext = vertices.max(axis=0) - vertices.min(axis=0)
        domain_volume = float(np.prod(ext)) if np.all(ext > 0) else None
        domain_kind = "bounding box"
    else:
        domain_kind = "given"
    chk = check_solid(vertices, faces, check_self_intersections=check_intersections)
    report = mesh_report(vertices, faces, domain_volume=domain_volume, solid=True, check=chk)
    if check_intersections:
        report["self_intersections"] = int(chk["self_intersections"])
    report["outward"] = bool(chk["outward"])
    report["min_angle_deg"] = float(smallest_angle(vertices, faces))
    report["domain"] = domain_kind
    report["file"] = str(path)
    H, K, area = vertex_curvatures(vertices, faces)
    report["mean_curvature"] = curvature_stats(H, area)
    report["gaussian_curvature"] = curvature_stats(K, area)
    fields = None
    if pores:
        closed = chk["closed"] and chk["manifold"] and chk["outward"]
        if not closed:
            raise InputError(f"{path}: --pores needs a closed, outward, manifold solid "
                             "(see the validity fields of the plain report)")
        from .pores import pore_analysis
        res = pore_analysis(vertices, faces, voxel, min_feature, min_pore, keep_fields=keep_fields,
                            volume=chk["volume"], area=chk["area"])
        fields = res.pop("_fields", None)
        report.update(res)
    if keep_fields:
        fields = dict(fields or {})
        fields["mean_curvature"] = H
        fields["vertex_area"] = area
    return report, fields


def require_matplotlib():
    """The report's plots need matplotlib (the ``report`` extra): a one-line error without it."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise InputError("the HTML report's plots need matplotlib: pip install 'porecad[report]'") from None


# ---------------------------------------------------------------- plots
def _histogram(path, values, weights, title, xlabel, color):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=110)
    ok = np.isfinite(values)
    ax.hist(values[ok], bins=40, weights=None if weights is None else weights[ok], color=color,
            edgecolor="white", linewidth=0.4)
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("volume fraction" if weights is not None else "count")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _sections(path, solid, pore, strut):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nz, ny, nx = solid.shape
    cuts = [("xy (z mid)", np.s_[nz // 2, :, :]), ("xz (y mid)", np.s_[:, ny // 2, :]),
            ("yz (x mid)", np.s_[:, :, nx // 2])]
    vmax = float(max(pore.max(), strut.max(), 1e-9))
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.9), dpi=110)
    for ax, (name, sl) in zip(axes, cuts):
        img = np.where(solid[sl], strut[sl], -pore[sl])
        im = ax.imshow(img, origin="lower", cmap="RdBu_r", vmin=-vmax, vmax=vmax, interpolation="nearest")
        ax.set_title(name)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes, shrink=0.85, label="strut thickness (+) / pore size (−), mm")
    fig.savefig(path)
    plt.close(fig)


def _preview(path, solid, max_pixels: int = 700):
    """Isometric view of the voxel solid: surface voxels projected, z-buffered, Lambert shaded.

    Software rendering (numpy, no GPU or display): normals from the gradient
    of the Gaussian-smoothed solid mask, a light from the upper left.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import ndimage

    step = max(1, int(np.ceil(max(solid.shape) / 350)))
    sol = np.pad(solid[::step, ::step, ::step], 2, constant_values=False)
    surface = sol & ~ndimage.binary_erosion(sol)
    k, j, i = np.nonzero(surface)
    smooth = ndimage.gaussian_filter(sol.astype(np.float32), 1.0)
    gz, gy, gx = np.gradient(smooth)
    nrm = -np.stack([gx[k, j, i], gy[k, j, i], gz[k, j, i]], axis=1)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-9)[:, None]
    # isometric camera: view direction (-1, -1, -1) normalised; screen axes u, w
    view = -np.ones(3) / np.sqrt(3.0)
    u = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    w = np.cross(view, u)  # screen up: +z tilted towards the viewer
    pts = np.stack([i, j, k], axis=1).astype(np.float64)
    su, sw, depth = pts @ u, pts @ w, pts @ view
    scale = min(max_pixels / max(np.ptp(su), 1.0), max_pixels / max(np.ptp(sw), 1.0), 2.0)
    px = ((su - su.min()) * scale).astype(np.int64)
    py = ((sw - sw.min()) * scale).astype(np.int64)
    W, Hh = px.max() + 2, py.max() + 2
    order = np.argsort(-depth)  # far to near: nearer voxels overwrite
    light = np.array([0.3, 0.6, 0.75])
    light /= np.linalg.norm(light)
    shade = np.clip(0.25 + 0.75 * np.abs(nrm @ light), 0, 1)
    img = np.ones((Hh, W, 3))
    colour = np.array([0.80, 0.84, 0.95])
    r = max(1, int(np.ceil(scale)))
    for dy in range(r):
        for dx in range(r):
            img[py[order] + dy, px[order] + dx] = shade[order, None] * colour
    fig, ax = plt.subplots(figsize=(5.5, 5.5 * Hh / max(W, 1) + 0.3), dpi=110)
    ax.imshow(img, origin="lower", interpolation="bilinear")
    ax.set_title("preview (isometric, voxel render)")
    ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _rows(report, keys):
    out = []
    for k in keys:
        if k in report and report[k] is not None and not isinstance(report[k], (dict, list)):
            val = report[k]
            out.append(f"<tr><th>{html.escape(k)}</th><td>{html.escape(f'{val:.6g}' if isinstance(val, float) else str(val))}</td></tr>")
    return "\n".join(out)


def write_report(directory, report, fields, force=False) -> Path:
    """Write report.json, the PNG plots and report.html into ``directory`` (atomically per file)."""
    from ..io import atomic_write

    require_matplotlib()
    d = Path(os.fspath(directory))
    d.mkdir(parents=True, exist_ok=True)
    tmp = d / ".porecad-plots"
    tmp.mkdir(exist_ok=True)
    images = []
    try:
        if fields and "solid" in fields:
            solid, pore, strut = fields["solid"], fields["pore"], fields["strut"]
            _histogram(tmp / "pore_sizes.png", pore[~solid], None, "pore size (local thickness)", "mm",
                       "#3b7dd8")
            _histogram(tmp / "strut_sizes.png", strut[solid], None, "strut / wall thickness", "mm", "#d8703b")
            _sections(tmp / "sections.png", solid, pore, strut)
            _preview(tmp / "preview.png", solid)
            images += [("pore_sizes.png", "Pore size distribution"), ("strut_sizes.png", "Strut size distribution"),
                       ("sections.png", "Cross-sections"), ("preview.png", "Preview")]
        if fields and "mean_curvature" in fields:
            _histogram(tmp / "curvature.png", fields["mean_curvature"], fields["vertex_area"],
                       "mean curvature (area weighted)", "1/mm", "#5a9e5a")
            images.append(("curvature.png", "Mean curvature"))
        for name, _ in images:
            with atomic_write(d / name, force=force) as fh:
                fh.write((tmp / name).read_bytes())
    finally:
        for p in tmp.glob("*"):
            p.unlink()
        tmp.rmdir()
    keys = ["file", "triangles", "vertices", "closed", "manifold", "oriented", "outward", "self_intersections",
            "min_angle_deg", "volume", "surface_area", "specific_surface", "porosity", "domain",
            "porosity_voxel", "voxel", "pore_size_mean", "pore_size_d50", "pore_size_d10", "pore_size_d90",
            "strut_size_mean", "strut_size_d50", "open_pore_fraction", "closed_pores", "closed_pore_volume",
            "permeability_kozeny_carman_mm2"]
    curv = ""
    for name in ("mean_curvature", "gaussian_curvature"):
        if report.get(name):
            cells = "".join(f"<td>{v:.4g}</td>" for v in report[name].values())
            heads = "".join(f"<th>{html.escape(k)}</th>" for k in report[name])
            curv += f"<h3>{name.replace('_', ' ')}</h3><table><tr>{heads}</tr><tr>{cells}</tr></table>"
    perc = ""
    if "percolation" in report:
        perc = "<p>Void percolates along: " + ", ".join(a for a, ok in report["percolation"].items() if ok) + \
               (" (none)" if not any(report["percolation"].values()) else "") + "</p>"
    flags = ""
    for key in ("thin_struts", "small_pores"):
        if key in report:
            r = report[key]
            flags += (f"<p><b>{key.replace('_', ' ')}</b>: {r['regions']} regions, {r['volume']:.4g} mm³"
                      + "".join(f"<br>at {', '.join(f'{c:.3g}' for c in loc['centre'])} mm: {loc['volume']:.3g} mm³"
                                for loc in r["locations"][:10]) + "</p>")
    figs = "\n".join(f'<figure><img src="{n}" alt="{html.escape(t)}"><figcaption>{html.escape(t)}</figcaption></figure>'
                     for n, t in images)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>porecad report: {html.escape(str(report.get('file', '')))}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:left}}
figure{{display:inline-block;margin:0.5em}}img{{max-width:100%}}</style></head>
<body><h1>porecad scaffold report</h1>
<table>{_rows(report, keys)}</table>
{perc}{flags}{curv}
<p><i>{html.escape(report.get('permeability_note', ''))}</i></p>
{figs}
</body></html>
"""
    with atomic_write(d / "report.html", force=force) as fh:
        fh.write(page.encode())
    with atomic_write(d / "report.json", force=force) as fh:
        fh.write((json.dumps(report, indent=1, default=_jsonable) + "\n").encode())
    return d


def _jsonable(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj).__name__)
