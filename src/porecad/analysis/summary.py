"""The report's summary for people: readable names, units and sensible precision, grouped.

The raw keys stay in ``report.json``; the HTML page shows, e.g., ``porosity 69.0 %``,
``surface area 13,150 mm²`` and ``pore size d50 1.73 mm`` under *Part*, *Pores*,
*Struts and walls* and *Mesh*.
"""

from __future__ import annotations

#: (group, [(key, name, kind)]); kind: "pct" (a fraction shown in %), "mm", "mm2", "mm3", "per_mm", "mm2perm",
#: "count", "flag", "text"
GROUPS = [
    ("Part", [("file", "file", "text"), ("domain", "design domain", "text"), ("volume", "material volume", "mm3"),
              ("surface_area", "surface area", "mm2"), ("specific_surface", "specific surface", "per_mm"),
              ("porosity", "porosity (by mesh volume)", "pct"), ("porosity_voxel", "porosity (by voxels)", "pct"),
              ("voxel", "analysis voxel", "mm")]),
    ("Pores", [("pore_size_mean", "pore size, mean", "mm"), ("pore_size_d10", "pore size d10", "mm"),
               ("pore_size_d50", "pore size d50", "mm"), ("pore_size_d90", "pore size d90", "mm"),
               ("open_pore_fraction", "open pore space", "pct"), ("closed_pores", "closed pores", "count"),
               ("closed_pore_volume", "closed pore volume", "mm3"), ("closed_by_skin", "closed by the skin", "count"),
               ("closed_in_lattice", "closed in the lattice", "count"),
               ("lattice_open_pore_fraction", "lattice open pore space", "pct"),
               ("permeability_kozeny_carman_mm2", "permeability (Kozeny–Carman estimate)", "mm2perm")]),
    ("Struts and walls", [("strut_size_mean", "strut/wall thickness, mean", "mm"),
                          ("strut_size_d50", "strut/wall thickness d50", "mm")]),
    ("Mesh", [("triangles", "triangles", "count"), ("vertices", "vertices", "count"), ("closed", "closed", "flag"),
              ("manifold", "manifold", "flag"), ("oriented", "consistently oriented", "flag"),
              ("outward", "normals outward", "flag"), ("self_intersections", "self-intersecting face pairs", "count")]),
]


#: values smaller than this (in the unit shown) are shown as 0: rounding noise, not a measurement
TINY = 1e-9


def _fmt(value, kind: str) -> str:
    if isinstance(value, bool) or kind == "flag":
        return "yes" if value else "no"
    if kind == "text" or not isinstance(value, (int, float)):
        return str(value)
    if abs(value) < TINY:
        value = 0
    if kind == "count":
        return f"{int(value):,}"
    if kind == "pct":
        return f"{100 * value:.1f} %"
    unit = {"mm": "mm", "mm2": "mm²", "mm3": "mm³", "per_mm": "1/mm", "mm2perm": "mm²"}[kind]
    if kind in ("mm2", "mm3") and abs(value) >= 100:
        return f"{value:,.0f} {unit}"
    return f"{value:.3g} {unit}"


def summary_groups(report: dict) -> list:
    """``[(group, [(name, value shown)])]`` of what ``report`` holds, groups without a value left out."""
    out = []
    for group, items in GROUPS:
        cells = [(name, _fmt(report[key], kind)) for key, name, kind in items
                 if key in report and report[key] is not None and not isinstance(report[key], (dict, list))]
        if cells:
            out.append((group, cells))
    return out


def summary_html(report: dict) -> str:
    """The grouped summary table rows (HTML) of what ``report`` holds."""
    from ..pages import render
    return render("summary.html", groups=summary_groups(report))


def relative_name(path, base=None) -> str:
    """``path`` relative to the folder ``base`` (a report names its files so; as given without ``base``)."""
    import os
    if base is None:
        return str(path)
    try:
        return os.path.relpath(os.path.abspath(path), os.path.abspath(base)).replace(os.sep, "/")
    except ValueError:     # another drive (Windows): no relative name
        return str(path)


def _pct(x) -> str:
    return f"{100 * float(x):.3g} %"


def _grading_words(build: dict) -> tuple:
    """``(name, words)`` of the design's porosity target, grading or threshold; None when there is none."""
    g = build.get("grading")
    if isinstance(g, dict):
        of = g.get("of", "porosity")
        text = f"{g.get('kind', '?')} grading of the {of}"
        if g.get("kind") == "radial" and all(k in g for k in ("from", "to", "r0", "r1")):
            val = _pct if of == "porosity" else (lambda x: f"{float(x):.3g}")
            plane = f" in the {g['axes']} plane" if g.get("axes") else ""
            text += (f" by the distance r{plane} from the centre: {val(g['from'])} for r ≤ {float(g['r0']):.3g} mm, "
                     f"{val(g['to'])} for r ≥ {float(g['r1']):.3g} mm")
        elif build.get("porosity_min") is not None and build.get("porosity_max") is not None:
            text += f": porosity {_pct(build['porosity_min'])} to {_pct(build['porosity_max'])}"
        return "grading", text
    for key in ("target_porosity", "porosity_target", "requested_porosity"):
        if isinstance(build.get(key), (int, float)):
            return "target porosity", _pct(build[key])
    if isinstance(build.get("threshold"), (int, float)):
        return "threshold", f"C = {float(build['threshold']):.3g}"
    return None


def _body_words(domain, build: dict):
    """The body the scaffold fills, in words (its kind and size), or None."""
    import numpy as np
    if domain is None:
        return None
    import re
    doc = (type(domain).__doc__ or "").strip().splitlines()
    # the first words of the class's summary line: "Analytic lumbar intervertebral disc (kidney-...)"
    words = re.split(r"\(|:|``|,|\.(?:\s|$)", doc[0])[0].strip() if doc else ""
    words = words or type(domain).__name__
    words = words[:1].lower() + words[1:] if words[:2] != words[:2].upper() else words
    bounds = getattr(domain, "bounds", None)
    try:
        ext = np.asarray(bounds[1], dtype=float) - np.asarray(bounds[0], dtype=float)
        if ext.shape == (3,) and np.all(np.isfinite(ext)):
            words += ", " + " × ".join(f"{e:.3g}" for e in ext) + " mm"
    except (TypeError, IndexError, ValueError):
        pass
    if isinstance(build.get("body_volume"), (int, float)):
        words += f", {float(build['body_volume']):,.0f} mm³"
    return words


def design_rows(build: dict, domain=None, base=None) -> list:
    """``[(name, value)]``: what a build designed — TPMS type, structure, cell size, target porosity or
    grading, body, porecad version and its files (relative to the report folder ``base``)."""
    from ..version import __version__
    rows = []
    if build.get("type"):
        try:
            from ..fields.tpms import get_type
            t = get_type(str(build["type"]))
            rows.append(("type", f"{t.title} ({t.name})"))
        except Exception:       # not a TPMS type name (another job's design): as given
            rows.append(("type", str(build["type"])))
    if build.get("structure"):
        rows.append(("structure", str(build["structure"])))
    cell = build.get("cell_size")
    if cell is not None:
        cells = [float(c) for c in (cell if isinstance(cell, (list, tuple)) else [cell])]
        rows.append(("cell size", (f"{cells[0]:.3g} mm" if len(set(cells)) == 1
                                   else " × ".join(f"{c:.3g}" for c in cells) + " mm")))
    target = _grading_words(build)
    if target:
        rows.append(target)
    body = _body_words(domain, build)
    if body:
        rows.append(("body", body))
    rows.append(("porecad version", str(build.get("porecad_version") or __version__)))
    for key, name in (("mesh_file", "mesh"), ("recipe_file", "recipe"), ("report_file", "JSON report")):
        if build.get(key):
            rows.append((name, relative_name(build[key], base)))
    return rows
