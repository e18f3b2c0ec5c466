"""`porecad analyze`: the metrics of a mesh and the report directory (JSON, HTML, PNG plots).

The HTML report is self-contained for offline use: one HTML file with the
tables, and PNG images beside it (matplotlib, Agg backend) — pore and strut
size histograms, a curvature histogram, three cross-sections through the
middle of the part coloured by local thickness, a shaded 3D preview
(a depth render of the voxelisation) and, when the design of the mesh is
known (a TPMS type, structure and threshold or porosity), the porosity-threshold
calibration curve of that type and structure with the design's operating
point(s) marked. The page references nothing outside its directory.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from .viewer import viewer_section

#: files always written into a report directory
REPORT_FILES = ("report.json", "report.html", "pore_sizes.png", "strut_sizes.png", "curvature.png",
                "sections.png", "preview.png")
#: files written only when ``write_report`` is given the mesh's ``design``
OPTIONAL_REPORT_FILES = ("porosity_threshold.png",)


def analyze_mesh(path, domain_volume=None, check_intersections=True, pores=False, voxel=None,
                 min_feature=None, min_pore=None, keep_fields=False, domain=None, skin=None):
    """Metrics of a mesh file; returns ``(report, fields)`` (fields: arrays for plots, or None).

    ``domain``: the design domain, a body mesh file's path or anything
    :func:`analyze_arrays` takes.
    """
    from ..io import read_mesh
    vertices, faces = read_mesh(path)
    if isinstance(domain, (str, os.PathLike)):
        domain = read_mesh(domain)
    return analyze_arrays(vertices, faces, path, domain_volume, check_intersections, pores, voxel,
                          min_feature, min_pore, keep_fields, domain=domain, skin=skin)


def analyze_arrays(vertices, faces, path="mesh", domain_volume=None, check_intersections=True, pores=False,
                   voxel=None, min_feature=None, min_pore=None, keep_fields=False, field=None, domain=None,
                   skin=None, check=None):
    """:func:`analyze_mesh` of a mesh in memory (``path`` names it in messages and the report).

    ``domain`` is the design domain the scaffold fills
    (:func:`porecad.analysis.domain.make_domain`: a body mesh ``(vertices,
    faces)``, a :class:`~porecad.bodies.mesh.MeshBody`, a field negative
    inside, a :class:`~porecad.analysis.domain.BoxDomain`; default the
    bounding box): porosity, pore and strut sizes and connectivity are
    measured inside it, and its volume is the porosity's reference unless
    ``domain_volume`` is given. ``skin``: thickness of a closing shell
    (:func:`porecad.analysis.pores.pore_analysis`). ``check``: the
    :func:`~porecad.mesh.validate.check_solid` of exactly these arrays when
    the caller has it (a job's validation), so it is not repeated.

    With the ``field`` the mesh was built from (negative inside), the mean and
    Gaussian curvature are also computed analytically from the field's
    derivatives at the vertices on its zero level set
    (``mean_curvature_analytic``, ``gaussian_curvature_analytic``; vertices of
    cap faces, where the field is not zero, are left out).
    """
    if len(faces) == 0:
        raise InputError(f"{path}: the mesh has no triangles")
    for name, value in (("voxel", voxel), ("min-feature", min_feature), ("min-pore", min_pore)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise InputError(f"--{name} must be a positive number of mm, got {value}")
    say("report: mesh quality and curvature")
    dom, domain_kind, domain_volume = _domain_of(domain, vertices, domain_volume)
    report, chk = _mesh_part(vertices, faces, path, domain_volume, domain_kind, check_intersections, check)
    H, area = _curvature_part(report, vertices, faces, field, bool(chk["closed"]))
    fields = None
    if pores:
        say("report: pore and strut sizes, connectivity")
        fields = _pore_part(report, vertices, faces, path, chk, dom, voxel, min_feature, min_pore, skin,
                            keep_fields)
    if keep_fields:
        fields = dict(fields or {})
        fields["mesh"] = (vertices, faces)
        fields["mean_curvature"] = H
        fields["vertex_area"] = area
    return report, fields


def _domain_of(domain, vertices, domain_volume):
    """The design domain of :func:`analyze_arrays` and the porosity's reference volume; returns
    ``(domain or None, its kind for the report, domain volume or None)``."""
    dom = None
    if domain is not None:
        from .domain import make_domain
        dom = make_domain(domain, vertices)
    if dom is not None:
        # the domain's own kind, also where the caller gives its volume (a job's exact domain volume)
        domain_kind = dom.kind
        if domain_volume is None and dom.volume:
            domain_volume = float(dom.volume)
    elif domain_volume is None:
        ext = vertices.max(axis=0) - vertices.min(axis=0)
        domain_volume = float(np.prod(ext)) if np.all(ext > 0) else None
        domain_kind = "bounding box"
    else:
        domain_kind = "given"
    return dom, domain_kind, domain_volume


def _mesh_part(vertices, faces, path, domain_volume, domain_kind, check_intersections, check):
    """The mesh report (validity, volume, porosity, quality, domain, file), reusing ``check`` when it
    has what is asked; returns ``(report, the check_solid result)``."""
    from ..mesh.validate import check_solid
    from .basic import mesh_report
    from .quality import mesh_quality

    chk = check
    if chk is None or (check_intersections and "self_intersections" not in chk):
        chk = check_solid(vertices, faces, check_self_intersections=check_intersections)
    report = mesh_report(vertices, faces, domain_volume=domain_volume, solid=True, check=chk)
    if check_intersections:
        report["self_intersections"] = int(chk["self_intersections"])
    report["outward"] = bool(chk["outward"])
    report["mesh_quality"] = mesh_quality(vertices, faces)
    report["min_angle_deg"] = report["mesh_quality"]["min_angle_deg"]
    report["domain"] = domain_kind
    report["file"] = str(path)
    return report, chk


def _curvature_part(report, vertices, faces, field, closed=None):
    """Add the discrete (and, with ``field``, analytic) curvature statistics to ``report``; returns
    ``(mean curvature per vertex, vertex area)``."""
    from .curvature import curvature_stats, vertex_curvatures

    H, K, area = vertex_curvatures(vertices, faces, closed)
    report["mean_curvature"] = curvature_stats(H, area)
    report["gaussian_curvature"] = curvature_stats(K, area)
    report["curvature_note"] = ("area weighted; min and max are single vertices (slivers, sharp cap edges): "
                                "read p01..p99 and the trimmed mean and std (1 % of the area dropped at each tail)")
    if field is not None:
        from .curvature import field_curvatures
        f = np.asarray(field.evaluate(vertices), dtype=np.float64)
        scale = float(np.max(np.abs(f))) or 1.0
        on = np.abs(f) <= 1e-3 * scale
        if on.any():
            Ha, Ka = field_curvatures(field, vertices[on], project=True)
            report["mean_curvature_analytic"] = curvature_stats(Ha, area[on])
            report["gaussian_curvature_analytic"] = curvature_stats(Ka, area[on])
            report["curvature_analytic_vertices"] = int(on.sum())
    return H, area


def _pore_part(report, vertices, faces, path, chk, dom, voxel, min_feature, min_pore, skin, keep_fields):
    """Add the pore analysis (:func:`porecad.analysis.pores.pore_analysis`) to ``report``; returns its
    ``_fields`` (or None); raises :class:`InputError` unless the solid is closed, outward and manifold."""
    closed = chk["closed"] and chk["manifold"] and chk["outward"]
    if not closed:
        raise InputError(f"{path}: the pore analysis (`pores`) needs a closed, outward, manifold solid "
                         "(see the validity fields of the plain report)")
    from .pores import pore_analysis
    res = pore_analysis(vertices, faces, voxel, min_feature, min_pore, keep_fields=keep_fields,
                        volume=chk["volume"], area=chk["area"], domain=dom, skin=skin)
    fields = res.pop("_fields", None)
    res.pop("domain", None)
    report.update(res)
    return fields


def require_matplotlib():
    """The report's plots need matplotlib (a base dependency): a one-line error if an install lacks it."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise InputError("the HTML report's plots need matplotlib, a porecad dependency that is missing: "
                         "pip install matplotlib") from None


# ---------------------------------------------------------------- plots
def preview_images(vertices, faces):
    """The part rendered from its triangles (:func:`porecad.analysis.render.render`): ``(whole, cut, y)``.

    ``cut`` is the part cut away at the plane ``y`` (mid-height in y). No
    plotting library: this can run on a worker thread.
    """
    from .render import render

    v = np.asarray(vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    whole = render(v, faces, 500, 375)
    cut = render(v, faces, 500, 375, cut=(0.5 * (lo + hi), (0.0, -1.0, 0.0)))
    return whole, cut, float(0.5 * (lo[1] + hi[1]))


def _design_points(design):
    """Normalise a design dict: ``(type, structure, thresholds, porosities, graded)``.

    Keys: ``type`` and ``structure`` (required); the operating point(s) from
    ``threshold`` (a number, or ``[lo, hi]`` for a graded part) or
    ``threshold_min``/``threshold_max``; else from ``target_porosity``,
    ``porosity_min``/``porosity_max`` or, last, ``porosity`` (the design's
    porosity, a number or ``[lo, hi]``; a build report's keys work as they
    are). Only one of thresholds/porosities is returned non-empty (thresholds
    win: a porosity design's threshold is computed from its porosity, so the
    two name the same point).
    """
    from ..fields.tpms import get_type
    from ..solids import check_structure

    if not isinstance(design, dict) or "type" not in design or "structure" not in design:
        raise InputError("a report design needs 'type' and 'structure'")
    ttype = get_type(str(design["type"])).name
    structure = check_structure(str(design["structure"]))

    def numbers(v):
        try:
            arr = [float(x) for x in np.ravel(np.asarray(v, dtype=object))]
        except (TypeError, ValueError):
            raise InputError(f"the report design's threshold/porosity must be numbers, got {v!r}") from None
        if not arr or not all(np.isfinite(arr)):
            raise InputError(f"the report design's threshold/porosity must be finite numbers, got {v!r}")
        return arr

    def values(first, lo, hi, last=None):
        for key in (first, (lo, hi), last):
            if isinstance(key, tuple):
                if design.get(lo) is not None and design.get(hi) is not None:
                    return numbers([design[lo], design[hi]]), True
            elif key is not None and design.get(key) is not None:
                arr = numbers(design[key])
                return arr, len(arr) > 1
        return [], False

    thresholds, graded = values("threshold", "threshold_min", "threshold_max")
    porosities = []
    if not thresholds:
        porosities, graded = values("target_porosity", "porosity_min", "porosity_max", "porosity")
    return ttype, structure, thresholds, porosities, graded


def _porosity_threshold(path, design):
    """Porosity against threshold of the design's type and structure, valid range shaded, design marked."""
    from ..calibration import (abs_phi_samples, phi_samples, porosity_of_threshold,
                               threshold_for_porosity, valid_range)

    ttype, structure, thresholds, porosities, graded = _design_points(design)
    if porosities:
        thresholds = [float(threshold_for_porosity(ttype, structure, p)) for p in porosities]
    pts_c = np.asarray(thresholds, dtype=np.float64)
    pts_p = np.asarray(porosity_of_threshold(ttype, structure, pts_c), dtype=np.float64)
    if porosities:
        pts_p = np.asarray(porosities, dtype=np.float64)
    v = abs_phi_samples(ttype) if structure == "sheet" else phi_samples(ttype)
    dom_lo, dom_hi = (0.0, float(v[-1])) if structure == "sheet" else (float(v[0]), float(v[-1]))
    valid = valid_range(ttype, structure)["threshold"]
    lo, hi = valid if valid is not None else (dom_lo, dom_hi)
    lo, hi = min([lo, *pts_c]), max([hi, *pts_c])
    pad = 0.08 * max(hi - lo, 1e-6)
    lo, hi = max(dom_lo, lo - pad), min(dom_hi, hi + pad)
    c = np.linspace(lo, hi, 400)
    p = porosity_of_threshold(ttype, structure, c)

    from .plots import new_figure
    fig, ax = new_figure((5.5, 3.8))
    if valid is not None:
        inside = (c >= valid[0]) & (c <= valid[1])
        ax.axvspan(valid[0], valid[1], color="#3b7dd8", alpha=0.10, lw=0,
                   label=f"valid range [{valid[0]:.3g}, {valid[1]:.3g}]")
        ax.plot(np.where(inside, c, np.nan), np.where(inside, p, np.nan), color="#1f4e99", lw=2)
        ax.plot(np.where(inside, np.nan, c), np.where(inside, np.nan, p), color="#888888", lw=1.2, ls="--",
                label="outside the valid range")
    else:
        ax.plot(c, p, color="#888888", lw=1.5, ls="--", label="no valid range (closed pores)")
    if graded and len(pts_c) >= 2:
        ax.axvspan(float(pts_c.min()), float(pts_c.max()), color="#d8703b", alpha=0.18, lw=0,
                   label="graded design range")
    label = "design" if len(pts_c) == 1 else "design (graded ends)" if graded else "design points"
    if len(pts_c):
        ax.plot(pts_c, pts_p, "o", color="#d8703b", mec="black", ms=7, zorder=5, label=label)
        for ci, pi in zip(pts_c, pts_p):
            ax.annotate(f"C={ci:.3g}, {100 * pi:.1f} %", (ci, pi), textcoords="offset points",
                        xytext=(6, -12 if pi > 0.5 else 6), fontsize=8)
    ax.set_xlim(lo, hi)
    ax.set_ylim(0, 1)
    ax.set_title(f"porosity vs threshold: {ttype} {structure}")
    ax.set_xlabel("threshold C" + (" (|φ − level| ≤ C)" if structure == "sheet" else ""))
    ax.set_ylabel("porosity (whole cells)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path)


def set_progress(step=None) -> None:
    """Have the report say each of its stages: ``step(message)`` (a command's progress lines); None: silent."""
    _progress[0] = step


_progress = [None]


def say(message: str) -> None:
    """One progress line of the report (see :func:`set_progress`)."""
    if _progress[0] is not None:
        _progress[0](message)


def write_report(directory, report, fields, force=False, design=None, about=None) -> Path:
    """Write report.json, the PNG plots and report.html into ``directory`` (atomically per file).

    ``design``: the TPMS design of the mesh when it is known (porecad built
    it) — a dict with ``type``, ``structure`` and the ``threshold`` (a number,
    or ``[lo, hi]`` / ``threshold_min`` + ``threshold_max`` for a graded part)
    or the ``porosity`` (likewise, also ``target_porosity`` or
    ``porosity_min`` + ``porosity_max``). Then ``porosity_threshold.png``
    (:data:`OPTIONAL_REPORT_FILES`) is written: the calibration curve over the
    valid range with the design's operating point(s). Without it (a mesh of
    unknown origin) that plot is left out and the page says so. ``about``:
    the page's *Design* rows (:func:`porecad.analysis.summary.design_rows`).
    """
    from ..io import atomic_write

    require_matplotlib()
    curve_note = ""
    if design is not None:
        # refuses a malformed design before anything is written
        if _design_points(design)[1] == "surface":
            curve_note = "No porosity–threshold curve: a bare surface has no porosity."
            design = None
    else:
        curve_note = ("No porosity–threshold curve: the design (TPMS type, structure, threshold) "
                      "of this mesh is not known.")
    from ..io.atomic import forget_temp, make_dirs, temp_dir
    d = make_dirs(directory)
    tmp = temp_dir(d / "porecad-plots", "tmp")  # a new folder of this run's own (removed whole at the end)
    try:
        images, viewer = _plots(tmp, fields, design)
        for name, _ in images:
            with atomic_write(d / name, force=force) as fh:
                fh.write((tmp / name).read_bytes())
    finally:
        forget_temp(tmp, remove=True)
    say("report: writing report.html")
    page = report_page(report, images, viewer, curve_note, about=about, base=d)
    with atomic_write(d / "report.html", force=force) as fh:
        fh.write(page.encode())
    with atomic_write(d / "report.json", force=force) as fh:
        fh.write((json.dumps(report, indent=1, default=_jsonable) + "\n").encode())
    return d


def _plots(tmp, fields, design):
    """The PNG plots into folder ``tmp`` and the 3D view; returns ``([(file, caption)], viewer html)``."""
    from . import plots
    images = []
    viewer = ""
    if fields and "solid" in fields:
        say("report: size histograms and sections")
        solid, pore, strut = fields["solid"], fields["pore"], fields["strut"]
        inside = fields.get("domain")
        if inside is None:
            inside = np.ones_like(solid)
        pores = fields.get("pore_samples", pore[inside & ~solid])
        struts = fields.get("strut_samples", strut[inside & solid])
        plots.histogram(tmp / "pore_sizes.png", pores, None, "pore size (local thickness)", "pore size (mm)",
                        "#3b7dd8", "voxels")
        plots.histogram(tmp / "strut_sizes.png", struts, None, "strut / wall thickness",
                        "strut / wall thickness (mm)", "#d8703b", "voxels")
        plots.sections(tmp / "sections.png", solid, pore, strut, inside, fields.get("origin", (0.0, 0.0, 0.0)),
                       float(fields.get("spacing", 1.0)))
        images += [("pore_sizes.png", "Pore size distribution"), ("strut_sizes.png", "Strut size distribution"),
                   ("sections.png", "Cross-sections")]
    if fields and "mesh" in fields:
        say("report: preview and 3D view")
        from .view_copy import view_copy
        mesh_v, mesh_f = fields["mesh"]
        view_v, view_f = fields["view"] if "view" in fields else view_copy(mesh_v, mesh_f)
        viewer = viewer_section(view_v, view_f, len(mesh_f))
        ext = np.ptp(np.asarray(mesh_v, dtype=np.float64), axis=0) if len(mesh_v) else None
        plots.preview(tmp / "preview.png", fields["preview"] if "preview" in fields else preview_images(view_v, view_f),
                      ext)
        images.insert(0, ("preview.png", "Preview: the mesh, whole and cut away"))
    if fields and "mean_curvature" in fields:
        plots.histogram(tmp / "curvature.png", fields["mean_curvature"], fields["vertex_area"],
                        "mean curvature (area weighted)", "mean curvature (1/mm)", "#5a9e5a")
        images.append(("curvature.png", "Mean curvature"))
    if design is not None:
        _porosity_threshold(tmp / "porosity_threshold.png", design)
        images.append(("porosity_threshold.png", "Porosity–threshold calibration"))
    return images, viewer


CURVATURE_WORDS = ("Curvature tells how sharply the surface bends (1/mm; a sphere of radius r has mean curvature "
                   "1/r, a TPMS sheet about 0 mean curvature). Read the trimmed mean and spread and the 1–99 % "
                   "range: they weigh each vertex by its area and drop 1 % of the area at each end. The min and "
                   "max are single vertices — a marching-cubes sliver or the sharp edge where a cap meets the "
                   "lattice gives thousands per mm there — and say nothing about the part.")


def _quality(report):
    """Mesh quality in words: the smallest angles and the slivers (what they mean is in the template)."""
    q = report.get("mesh_quality") or {}
    if not q:
        return None
    rows = [("smallest angle", f"{q['min_angle_deg']:.3g}°" if q.get("min_angle_deg") is not None else "–"),
            ("1 % of triangles have an angle below", f"{q['angle_p01_deg']:.3g}°"
             if q.get("angle_p01_deg") is not None else "–"),
            (f"slivers (an angle below {q.get('sliver_angle_deg', 5):g}°)",
             f"{q.get('slivers', 0):,} of {report.get('triangles', 0):,} ({100 * q.get('sliver_fraction', 0):.2g} %)")]
    return {"rows": rows, "note": str(q.get("note", ""))}


def _curvature(report):
    """Robust curvature statistics first (trimmed, percentiles), the extremes last, with what they mean."""
    from ..pages import num
    cols = (("trimmed_mean", "trimmed mean"), ("trimmed_std", "trimmed spread"), ("p01", "1 %"),
            ("median", "median"), ("p99", "99 %"), ("min", "min (one vertex)"), ("max", "max (one vertex)"))
    rows = []
    for name in ("mean_curvature", "gaussian_curvature", "mean_curvature_analytic", "gaussian_curvature_analytic"):
        st = report.get(name)
        if st:
            unit = "1/mm²" if "gaussian" in name else "1/mm"
            rows.append((f"{name.replace('_', ' ')} ({unit})",
                         [num(st[k]) if isinstance(st.get(k), (int, float)) else "–" for k, _ in cols]))
    return {"heads": [t for _, t in cols], "rows": rows, "words": CURVATURE_WORDS} if rows else None


def report_page(report, images, viewer: str = "", curve_note: str = "", about=None, base=None) -> str:
    """The report's HTML (template ``porecad/pages/templates/report.html``): what was designed, summary,
    preview and 3D view, mesh quality and curvature in words, plots.

    ``about``: the *Design* rows (:func:`porecad.analysis.summary.design_rows`); ``base``: the report's
    folder, which the files the page names are given relative to.
    """
    from markupsafe import Markup

    from ..pages import render
    from .summary import relative_name, summary_groups
    perc = report.get("percolation")
    preview = images[0] if images and images[0][0] == "preview.png" else None
    shown = dict(report)
    if "file" in report:
        shown["file"] = relative_name(report["file"], base)
    if about and any(k == "body" for k, _ in about):
        shown["domain"] = dict(about)["body"]
    return render("report.html", title=f"porecad report: {shown.get('file', '')}", report=report,
                  preview=preview, figures=images[1:] if preview else images, viewer=Markup(viewer),
                  about=about or [], groups=summary_groups(shown),
                  percolation=None if perc is None else [a for a, ok in perc.items() if ok],
                  flags=[(k.replace("_", " "), report[k]) for k in ("thin_struts", "small_pores") if k in report],
                  sizes=(report.get("size_sampling") or {}).get("note"), quality=_quality(report),
                  curvature=_curvature(report), curve_note=curve_note)


def _jsonable(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj).__name__)


def check_report_dir(report_dir, force=False, design=False):
    """Refuse to overwrite an existing report without ``force`` (before any work is done)."""
    from ..io import check_output_path
    require_matplotlib()
    if os.path.exists(report_dir) and not os.path.isdir(report_dir):
        raise InputError(f"{report_dir}: exists and is not a directory")
    if os.path.isdir(report_dir):
        for name in REPORT_FILES + (OPTIONAL_REPORT_FILES if design else ()):
            check_output_path(os.path.join(report_dir, name), force=force)


def is_report_dir(path) -> bool:
    """Whether a build command's ``--report PATH`` asks for a report directory (not a ``.json`` file)."""
    return not str(path).lower().endswith(".json")


def write_build_report(directory, vertices, faces, build_report, domain_volume=None, design=None,
                       force=False, field=None, domain=None, skin=None, check=None) -> Path:
    """The report directory of a build command: the build's report plus the full analysis.

    The analysis (validity, curvature, pore and strut sizes, interconnectivity,
    printability) runs on the mesh in memory; ``report.json`` holds it with the
    build's own report under ``"build"``; the HTML adds the porosity–threshold
    curve of the ``design`` (default: the build report's type, structure and
    threshold or porosity; ``False``: no curve, for designs that are not a
    TPMS threshold, such as TIS and ARBF). ``domain`` and ``skin``: the
    design domain the analysis measures in and the thickness of a closing
    shell (:func:`analyze_arrays`).
    """
    from concurrent.futures import ThreadPoolExecutor

    from .view_copy import view_copy

    def pictures():
        # mesh-only work beside the analysis on a worker thread: the pore analysis keeps about
        # 1.4 of 2 cores busy, and the decimation and the renders need no result of it
        view = view_copy(vertices, faces)
        return view, preview_images(*view)

    with ThreadPoolExecutor(1, thread_name_prefix="porecad-pictures") as pool:
        ahead = pool.submit(pictures)
        report, fields = analyze_arrays(vertices, faces, build_report.get("mesh_file", "scaffold"),
                                        domain_volume=domain_volume, check_intersections=False, pores=True,
                                        keep_fields=True, field=field, domain=domain, skin=skin,
                                        check=check)
        fields["view"], fields["preview"] = ahead.result()
    report["build"] = {k: v for k, v in build_report.items() if k not in ("report_dir",)}
    from .summary import design_rows
    return write_report(directory, report, fields, force=force,
                        design=build_report if design is None else (design or None),
                        about=design_rows(build_report, domain, directory))
