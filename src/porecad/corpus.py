"""Bodies like those users bring that the scanned-looking ones of :mod:`porecad.datasets` miss (issue 37).

Built from primitives by constructive solid geometry (manifold3d), so
closed and 2-manifold by construction, deterministic, in mm unless the name
says otherwise. Returned as ``(vertices (V, 3) float64, faces (F, 3) int64)``:

* :func:`branching_tube` — a thin Y of tubes (radius a twentieth of the length).
* :func:`thin_plate` — a plate ``thickness`` thick (1–2 lattice cells).
* :func:`holed_part` — a CAD block with sharp edges and ``holes`` through-holes (genus = holes).
* :func:`inward` — any body with its normals turned inward (as some exporters write them).
* :func:`scaled` — any body in metres or micrometres (a factor of the mm body).
* :func:`open_surface` — any body with a hole in its surface (a few faces missing).
"""

from __future__ import annotations

import numpy as np


def _mesh(m):
    mesh = m.to_mesh()
    v = np.asarray(mesh.vert_properties, np.float64)[:, :3]
    return v, np.asarray(mesh.tri_verts, np.int64)


def branching_tube(length: float = 40.0, radius: float = 2.0, angle: float = 30.0, segments: int = 24):
    """A Y: a stem and two branches ``angle`` degrees off it, tubes of ``radius`` (solid rods), ``length`` long."""
    import manifold3d as m
    rod = m.Manifold.cylinder(length / 2, radius, radius, segments)
    stem = rod.translate([0.0, 0.0, -length / 2])
    ball = m.Manifold.sphere(radius, segments)
    return _mesh(stem + rod.rotate([0.0, angle, 0.0]) + rod.rotate([0.0, -angle, 0.0]) + ball)


def thin_plate(size: float = 40.0, thickness: float = 3.0):
    """A square plate ``size`` wide and ``thickness`` thick, corners rounded off by a bevel."""
    import manifold3d as m
    plate = m.Manifold.cube([size, size, thickness], True)
    cut = m.Manifold.cube([size, size, 2 * thickness], True).rotate([0.0, 0.0, 45.0]).scale([1.3, 1.3, 1.0])
    return _mesh(plate ^ cut)


def holed_part(holes: int = 6, size: float = 60.0, thickness: float = 10.0, segments: int = 32):
    """A bracket: a block with sharp edges, a step, and ``holes`` round through-holes in two rows."""
    import manifold3d as m
    width = size / 2
    block = m.Manifold.cube([size, width, thickness], True)
    step = m.Manifold.cube([size / 3, width, thickness], True).translate([size / 3, 0.0, thickness / 2])
    part = block + step
    per_row = (holes + 1) // 2
    r = min(size / (4 * per_row), width / 8)
    for k in range(holes):
        row, col = divmod(k, per_row)
        x = (col + 0.5) * size / per_row - size / 2
        y = (row - 0.5) * width / 2 if holes > 1 else 0.0
        part = part - m.Manifold.cylinder(4 * thickness, r, r, segments, True).translate([x, y, 0.0])
    return _mesh(part)


def inward(body):
    """``body`` = ``(vertices, faces)`` with every face reversed (normals inward)."""
    v, f = body
    return v.copy(), f[:, ::-1].copy()


def scaled(body, factor: float):
    """``body`` scaled by ``factor`` (0.001: written in metres; 1000: in micrometres)."""
    v, f = body
    return v * float(factor), f.copy()


def open_surface(body, faces: int = 3):
    """``body`` with ``faces`` adjacent faces removed: a hole in its surface."""
    v, f = body
    c = v[f].mean(axis=1)
    top = int(np.argmax(c[:, 2]))
    near = np.argsort(np.linalg.norm(c - c[top], axis=1))[:faces]
    return v.copy(), np.delete(f, near, axis=0)
