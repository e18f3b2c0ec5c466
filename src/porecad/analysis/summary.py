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


def _fmt(value, kind: str) -> str:
    if isinstance(value, bool) or kind == "flag":
        return "yes" if value else "no"
    if kind == "text" or not isinstance(value, (int, float)):
        return str(value)
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
