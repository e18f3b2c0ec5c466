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
import io
import json
import os
from pathlib import Path

import numpy as np

from porecad.io.atomic import atomic_write
from porecad.io.jsonable import json_default
from porecad.pages import num, render

__all__ = ["properties_page", "write_properties_report"]

def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


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


def _clean(rows):
    """Round-off entries (below 1e-9 of the largest) as 0, as a symmetric tensor's zeros."""
    a = np.asarray(rows, dtype=np.float64)
    return np.where(np.abs(a) < 1e-9 * float(np.abs(a).max() or 1.0), 0.0, a).tolist()


def _stiffness(s) -> dict:
    e, d = s["engineering"], s["directional_modulus"]
    hs = s.get("hashin_shtrikman") or {}
    constants = [("E1, E2, E3 (MPa)", f"{num(e['E1'])}, {num(e['E2'])}, {num(e['E3'])}"),
                 ("G23, G13, G12 (MPa)", f"{num(e['G23'])}, {num(e['G13'])}, {num(e['G12'])}"),
                 ("ν12, ν13, ν23", f"{num(e['nu12'])}, {num(e['nu13'])}, {num(e['nu23'])}"),
                 ("bulk modulus (MPa)", num(e["bulk_modulus"])),
                 ("Zener anisotropy ratio", num(e["zener_ratio"])),
                 ("E max (MPa), direction", f"{num(d['E_max'])} along {d['E_max_direction']}"),
                 ("E min (MPa), direction", f"{num(d['E_min'])} along {d['E_min_direction']}"),
                 ("relative density", num(s.get("relative_density"))),
                 ("relative modulus E/Es", num(s.get("relative_modulus"))),
                 ("Hashin–Shtrikman upper bounds (bulk, shear, MPa)",
                  f"{num(hs.get('bulk_upper'))}, {num(hs.get('shear_upper'))}: "
                  + ("within" if hs.get("within") else "NOT within"))]
    return {"C": _clean(s["C_MPa"]), "constants": constants, "plot": _directional_plot(d)}


def _permeability(p) -> dict:
    tort = p.get("tortuosity") or {}
    flow = [("porosity (voxels)", num(p.get("porosity"))),
            ("hydraulic tortuosity x, y, z", ", ".join(num(tort.get(a)) for a in "xyz"))]
    if "kozeny_carman_mm2" in p:
        flow.append(("Kozeny–Carman estimate (mm²)", num(p["kozeny_carman_mm2"])))
    k, darcy = p.get("permeability_mm2"), p.get("permeability_darcy")
    return {"k_mm2": None if k is None else _clean(k), "k_darcy": None if darcy is None else _clean(darcy),
            "flow": flow, "notes": [str(p[key]) for key in ("method", "note", "kozeny_carman_note") if p.get(key)]}


def _sweep(sw) -> dict:
    return {"rows": sw["rows"], "fit": sw.get("fit"), "published": sorted((sw.get("published") or {}).items()),
            "plot": _sweep_plot(sw) if any("relative_modulus" in r for r in sw["rows"]) else None}


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
        A self-contained page (plots as embedded PNG data; no external resource), from the
        template ``porecad/pages/templates/properties.html``.

    Examples
    --------
    >>> page = properties_page({"source": "cell.toml", "permeability": {
    ...     "permeability_mm2": [[1e-3, 0, 0], [0, 1e-3, 0], [0, 0, 1e-3]], "porosity": 0.6,
    ...     "tortuosity": {"x": 1.3, "y": 1.3, "z": 1.3}}})
    >>> "Mechanics and flow" in page and "0.001" in page and "http" not in page
    True
    """
    job = [("design", str(report.get("source", "")))]
    if "solid_E_MPa" in report:
        job.append(("solid E (MPa), ν", f"{num(report['solid_E_MPa'])}, {num(report.get('solid_nu'))}"))
    cell = report.get("cell")
    if cell:
        job += [("voxel grid", " × ".join(str(n) for n in cell.get("grid", []))),
                ("voxel (mm)", num(cell.get("voxel_mm"))), ("porosity (voxels)", num(cell.get("porosity_voxel")))]
    return render("properties.html", title=title, job=job,
                  stiffness=_stiffness(report["stiffness"]) if "stiffness" in report else None,
                  permeability=_permeability(report["permeability"]) if "permeability" in report else None,
                  sweep=_sweep(report["sweep"]) if "sweep" in report else None)


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
