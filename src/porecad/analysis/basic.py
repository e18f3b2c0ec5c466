"""Basic scaffold metrics: volume, area, porosity, specific surface, topology flags.

* volume: divergence theorem over the closed mesh, ``V = 1/6 sum (a x b) . c``;
* porosity: void fraction of the domain, ``1 - V_material / V_domain``;
* specific surface: ``S / V_material`` (1/mm); area per volume ``S / V_domain``
  (the quantity of 002 Table 4 for a surface in a unit cell).
"""

from __future__ import annotations

from ..mesh.topology import edge_topology
from ..mesh.validate import bounds, signed_volume, surface_area


def volume_metrics(area: float, volume, domain_volume=None) -> dict:
    """Volume-derived report entries: volume, outward, specific surface (S/V), porosity, area per domain volume.

    ``volume`` is None for an open mesh or a bare surface (then only the
    domain entries are given). Porosity ``1 − V / V_domain``; specific
    surface ``S / V``; area per volume ``S / V_domain`` (001 Table 3's A/V).
    """
    out = {"volume": None}
    if volume is not None:
        vol = float(volume)
        out.update({"volume": vol, "outward": vol > 0, "specific_surface": area / vol if vol > 0 else None})
        if domain_volume:
            out["porosity"] = 1.0 - vol / float(domain_volume)
    if domain_volume:
        out["domain_volume"] = float(domain_volume)
        out["area_per_volume"] = area / float(domain_volume)
    return out


def mesh_report(vertices, faces, domain_volume: float | None = None, solid: bool = True,
                check: dict | None = None) -> dict:
    """Metrics of a mesh as a plain dict (JSON-ready).

    ``check`` is the dict of :func:`porecad.mesh.validate.check_solid` for this
    mesh, when the caller has one: its topology, volume and area are reused.
    """
    topo = edge_topology(faces) if check is None else check
    area = float(surface_area(vertices, faces) if check is None else check["area"])
    out = {
        "triangles": int(len(faces)),
        "vertices": int(len(vertices)),
        "surface_area": area,
        "closed": bool(topo["closed"]),
        "manifold": bool(topo["manifold"]),
        "oriented": bool(topo["oriented"]),
    }
    vol = None
    if solid and topo["closed"]:
        vol = float(signed_volume(vertices, faces) if check is None else check["volume"])
    out.update(volume_metrics(area, vol, domain_volume))
    if len(vertices):
        if check is not None and check.get("bounds") is not None:
            out["bounds"] = check["bounds"]
        else:
            out["bounds"] = [b.tolist() for b in bounds(vertices)]
    return out
