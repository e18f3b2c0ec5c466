"""The "Mechanics and flow" HTML page of a properties report (``porecad properties --report X.html``).

One self-contained page (plots embedded as PNG data, nothing fetched): the
homogenised stiffness tensor and engineering constants with the
Hashin–Shtrikman check, a map of the directional Young's modulus over all
directions, the permeability tensor with the tortuosity and the
Kozeny–Carman estimate beside it, and a porosity sweep as a table and a
log–log plot with its Gibson–Ashby fit and the published exponents.
Arrays in, a string out: :func:`properties_page` takes the dict of
:func:`porecad.jobs.design_source.design_properties`.
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from pathlib import Path

import numpy as np

from porecad.io.atomic import atomic_write
from porecad.io.jsonable import json_default

__all__ = ["properties_page", "write_properties_report"]

_STYLE = """body{font-family:system-ui,sans-serif;max-width:960px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:.6em 0}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f3f3f3}caption{text-align:left;font-weight:600;padding:.3em 0}img{max-width:100%}
p.note{color:#555;font-size:.92em}"""


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _num(x, digits: int = 4) -> str:
    return "–" if x is None else f"{float(x):.{digits}g}"


def _matrix(rows, caption: str, labels) -> str:
    a = np.asarray(rows, dtype=np.float64)
    # round-off entries (below 1e-9 of the largest) are shown as 0, as a symmetric tensor's zeros
    rows = np.where(np.abs(a) < 1e-9 * float(np.abs(a).max() or 1.0), 0.0, a).tolist()
    head = "".join(f"<th>{html.escape(x)}</th>" for x in labels)
    body = "".join("<tr><th>" + html.escape(labels[i]) + "</th>" + "".join(f"<td>{_num(v)}</td>" for v in row)
                   + "</tr>" for i, row in enumerate(rows))
    return f"<table><caption>{html.escape(caption)}</caption><tr><th></th>{head}</tr>{body}</table>"


def _pairs(items, caption: str) -> str:
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in items)
    return f"<table><caption>{html.escape(caption)}</caption>{body}</table>"


def _directional_plot(d) -> str:
    from matplotlib.figure import Figure

    E = np.asarray(d["E"], dtype=np.float64)
    fig = Figure(figsize=(7.5, 3.6), dpi=110)
    ax = fig.add_subplot()
    im = ax.imshow(E, origin="lower", aspect="auto", cmap="viridis",
                   extent=(d["phi_deg"][0], d["phi_deg"][-1], d["theta_deg"][0], d["theta_deg"][-1]))
    ax.set_xlabel("azimuth φ from x (degrees)")
    ax.set_ylabel("polar angle θ from z (degrees)")
    ax.set_title("directional Young's modulus E(d), MPa")
    fig.colorbar(im, ax=ax)
    fig.subplots_adjust(left=0.09, right=0.97, bottom=0.14, top=0.9)
    return _png(fig)


def _sweep_plot(sweep) -> str:
    from matplotlib.figure import Figure

    rows = [r for r in sweep["rows"] if "relative_modulus" in r]
    rho = np.array([r["relative_density"] for r in rows])
    rel = np.array([r["relative_modulus"] for r in rows])
    fig = Figure(figsize=(6, 4), dpi=110)
    ax = fig.add_subplot()
    ax.loglog(rho, rel, "o", color="#3b7dd8", label="voxel FE")
    grid = np.geomspace(max(rho.min() * 0.8, 1e-3), min(rho.max() * 1.25, 1.0), 50)
    fit = sweep.get("fit")
    if fit:
        ax.loglog(grid, fit["C"] * grid ** fit["n"], "-", color="#3b7dd8",
                  label=f"fit: {fit['C']:.3g} ρ^{fit['n']:.2f}")
    for (name, pub), style in zip(sorted((sweep.get("published") or {}).items()), (":", "--", "-.")):
        ax.loglog(grid, pub["C"] * grid ** pub["n"], style, color="#888", label=f"{name}: n = {pub['n']:g}")
    ax.set_xlabel("relative density ρ/ρs")
    ax.set_ylabel("relative modulus E/Es")
    ax.legend(fontsize=8)
    fig.subplots_adjust(left=0.17, right=0.97, bottom=0.13, top=0.95)
    return _png(fig)


def _stiffness_html(s) -> str:
    voigt = ["11", "22", "33", "23", "13", "12"]
    e = s["engineering"]
    d = s["directional_modulus"]
    hs = s.get("hashin_shtrikman") or {}
    parts = ["<h3>Stiffness</h3>", _matrix(s["C_MPa"], "homogenised stiffness C (MPa, Voigt order)", voigt)]
    parts.append(_pairs([("E1, E2, E3 (MPa)", f"{_num(e['E1'])}, {_num(e['E2'])}, {_num(e['E3'])}"),
                         ("G23, G13, G12 (MPa)", f"{_num(e['G23'])}, {_num(e['G13'])}, {_num(e['G12'])}"),
                         ("ν12, ν13, ν23", f"{_num(e['nu12'])}, {_num(e['nu13'])}, {_num(e['nu23'])}"),
                         ("bulk modulus (MPa)", _num(e["bulk_modulus"])),
                         ("Zener anisotropy ratio", _num(e["zener_ratio"])),
                         ("E max (MPa), direction", f"{_num(d['E_max'])} along {d['E_max_direction']}"),
                         ("E min (MPa), direction", f"{_num(d['E_min'])} along {d['E_min_direction']}"),
                         ("relative density", _num(s.get("relative_density"))),
                         ("relative modulus E/Es", _num(s.get("relative_modulus"))),
                         ("Hashin–Shtrikman upper bounds (bulk, shear, MPa)",
                          f"{_num(hs.get('bulk_upper'))}, {_num(hs.get('shear_upper'))}: "
                          + ("within" if hs.get("within") else "NOT within"))],
                        "engineering constants"))
    parts.append(f'<img alt="directional Young\'s modulus" src="{_directional_plot(d)}">')
    return "".join(parts)


def _permeability_html(p) -> str:
    axes = ["x", "y", "z"]
    parts = ["<h3>Permeability</h3>"]
    k = p.get("permeability_mm2")
    if k is not None:
        parts.append(_matrix(k, "Darcy permeability tensor (mm²)", axes))
    if p.get("permeability_darcy") is not None:
        parts.append(_matrix(p["permeability_darcy"], "the same in darcy", axes))
    tort = p.get("tortuosity") or {}
    items = [("porosity (voxels)", _num(p.get("porosity"))),
             ("hydraulic tortuosity x, y, z", ", ".join(_num(tort.get(a)) for a in axes))]
    if "kozeny_carman_mm2" in p:
        items.append(("Kozeny–Carman estimate (mm²)", _num(p["kozeny_carman_mm2"])))
    parts.append(_pairs(items, "flow"))
    for key in ("method", "note", "kozeny_carman_note"):
        if p.get(key):
            parts.append(f'<p class="note">{html.escape(str(p[key]))}</p>')
    return "".join(parts)


def _sweep_html(sw) -> str:
    head = "<tr><th>porosity</th><th>relative density</th><th>E/Es</th><th>G12/Es</th><th>Zener ratio</th></tr>"
    body = ""
    for r in sw["rows"]:
        if "error" in r:
            body += f"<tr><td>{_num(r['porosity'])}</td><td colspan=4>{html.escape(str(r['error']))}</td></tr>"
        else:
            body += (f"<tr><td>{_num(r['porosity'])}</td><td>{_num(r['relative_density'])}</td>"
                     f"<td>{_num(r['relative_modulus'])}</td><td>{_num(r.get('G12_rel'))}</td>"
                     f"<td>{_num(r.get('zener_ratio'))}</td></tr>")
    parts = ["<h3>Porosity sweep</h3>", f"<table><caption>relative modulus against porosity</caption>{head}"
             f"{body}</table>"]
    fit = sw.get("fit")
    if fit:
        parts.append(f"<p>Gibson–Ashby fit: E/Es = {_num(fit['C'])} (ρ/ρs)<sup>{fit['n']:.3f}</sup> "
                     f"(R² = {_num(fit.get('r2'))}, {fit.get('points', '')} points).</p>")
    pubs = sw.get("published") or {}
    if pubs:
        parts.append("<p>Published exponents: " + "; ".join(
            f"{html.escape(name)}: n = {v['n']:g}, C = {_num(v['C'], 3)} ({html.escape(v['source'])})"
            for name, v in sorted(pubs.items())) + ".</p>")
    if any("relative_modulus" in r for r in sw["rows"]):
        parts.append(f'<img alt="Gibson–Ashby plot" src="{_sweep_plot(sw)}">')
    return "".join(parts)


def properties_page(report: dict, title: str = "porecad — mechanics and flow") -> str:
    """The report of :func:`~porecad.jobs.design_source.design_properties` as one HTML page.

    Parameters
    ----------
    report : dict
        With any of ``stiffness``, ``permeability`` and ``sweep``; ``source``,
        ``solid_E_MPa``, ``solid_nu`` and ``cell`` describe the job.
    title : str

    Returns
    -------
    str
        A self-contained page (plots as embedded PNG data; no external resource).

    Examples
    --------
    >>> page = properties_page({"source": "cell.toml", "permeability": {
    ...     "permeability_mm2": [[1e-3, 0, 0], [0, 1e-3, 0], [0, 0, 1e-3]], "porosity": 0.6,
    ...     "tortuosity": {"x": 1.3, "y": 1.3, "z": 1.3}}})
    >>> "Mechanics and flow" in page and "0.001" in page and "http" not in page
    True
    """
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{_STYLE}</style></head><body><h2>Mechanics and flow</h2>"]
    items = [("design", str(report.get("source", "")))]
    if "solid_E_MPa" in report:
        items.append(("solid E (MPa), ν", f"{_num(report['solid_E_MPa'])}, {_num(report.get('solid_nu'))}"))
    cell = report.get("cell")
    if cell:
        items += [("voxel grid", " × ".join(str(n) for n in cell.get("grid", []))),
                  ("voxel (mm)", _num(cell.get("voxel_mm"))), ("porosity (voxels)", _num(cell.get("porosity_voxel")))]
    parts.append(_pairs(items, "job"))
    if "stiffness" in report:
        parts.append(_stiffness_html(report["stiffness"]))
    if "permeability" in report:
        parts.append(_permeability_html(report["permeability"]))
    if "sweep" in report:
        parts.append(_sweep_html(report["sweep"]))
    parts.append("</body></html>")
    return "".join(parts)


def write_properties_report(path, report: dict, force: bool = False):
    """Write ``report`` atomically: the HTML page for a ``.html``/``.htm`` path, else JSON."""
    p = Path(os.fspath(path))
    if p.suffix.lower() in (".html", ".htm"):
        data = properties_page(report).encode()
    else:
        data = json.dumps(report, default=json_default, indent=1).encode()
    with atomic_write(p, force=force) as fh:
        fh.write(data)
    return p
