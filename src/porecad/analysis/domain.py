"""The design domain of an analysis: where porosity, pore sizes and connectivity are measured.

A scaffold fills a domain — a box, a body, a TBSS solid, a vessel wall —
and its pores are the domain minus the solid, never the air of a bounding
box around it (issue 22). The analysis takes the domain as

* ``None``: the mesh's bounding box (:class:`BoxDomain`);
* a body mesh: ``(vertices, faces)`` or a :class:`~porecad.bodies.mesh.MeshBody`
  (:class:`MeshDomain`: inside by winding number, exact distances to its
  triangles);
* any :class:`~porecad.fields.base.Field`, negative inside
  (:class:`FieldDomain`: inside where the field is negative; the distance to
  its boundary is the first-order estimate ``|f| / |∇f|``, exact for signed
  distance fields).

The boundary of a body or field domain is a wall of the pore space: a pore
cut open by the body surface is measured up to that surface (its largest
ball stays inside the body), so the air outside never counts as pore and no
pore reads larger than the lattice's. The faces of the default bounding box
are not walls (:class:`BoxDomain`).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


class BoxDomain:
    """Axis-aligned box ``[lo, hi]``: a window on a larger material, its faces are no walls.

    A pore that the box cuts is measured as if it went on (its balls may
    reach past the faces, where there is no solid): a channel open at a face
    keeps its diameter up to the face, as with PoreSpy on the cropped image.
    The solid is bounded by its own surface, caps included (the part as
    built). A box smaller than the mesh is a window: balls centred around it,
    in the mesh's bounding box, count too, so the structure is measured as
    it is, not as cut by the window.
    """

    kind = "bounding box"
    walls = False

    def __init__(self, lo, hi):
        self.lo = np.asarray(lo, dtype=np.float64)
        self.hi = np.asarray(hi, dtype=np.float64)
        if not np.all(self.hi > self.lo):
            raise InputError("the analysis domain box is empty (a flat mesh has no volume to analyse)")

    @property
    def bounds(self):
        return self.lo.copy(), self.hi.copy()

    @property
    def volume(self) -> float:
        return float(np.prod(self.hi - self.lo))

    def inside_grid(self, xs, ys, zs):
        fx = (xs >= self.lo[0]) & (xs <= self.hi[0])
        fy = (ys >= self.lo[1]) & (ys <= self.hi[1])
        fz = (zs >= self.lo[2]) & (zs <= self.hi[2])
        return fz[:, None, None] & fy[None, :, None] & fx[None, None, :]

    def wall(self, points, upper):
        """Distance to the box's boundary and the nearest boundary point (capped at ``upper``)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        inside = np.all((p >= self.lo) & (p <= self.hi), axis=1)
        gaps = np.concatenate([p - self.lo, self.hi - p], axis=1)      # (n, 6), >= 0 inside
        face = np.argmin(gaps, axis=1)
        d_in = gaps[np.arange(len(p)), face]
        c = p.copy()
        ax = face % 3
        c[np.arange(len(p)), ax] = np.where(face < 3, self.lo[ax], self.hi[ax])
        clamped = np.clip(p, self.lo, self.hi)
        d_out = np.linalg.norm(p - clamped, axis=1)
        d = np.where(inside, d_in, d_out)
        c = np.where(inside[:, None], c, clamped)
        far = d > np.asarray(upper)
        d = np.where(far, upper, d)
        c[far] = np.nan
        return d, c


class MeshDomain:
    """A closed body mesh: inside by winding number, exact distances to its surface."""

    kind = "body mesh"
    walls = True

    def __init__(self, vertices, faces):
        from ..bodies.mesh import MeshBody
        from ..mesh.validate import signed_volume
        from .surface_index import SurfaceIndex

        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        if len(f) == 0:
            raise InputError("the analysis domain mesh has no triangles")
        self.lo, self.hi = v.min(axis=0), v.max(axis=0)
        ext = self.hi - self.lo
        self._volume = float(signed_volume(v, f))
        if not self._volume > 0:
            raise InputError("the analysis domain mesh must be closed and outward (its volume is not positive)")
        # coarse distance bins: the body is only asked for winding numbers here
        self.body = MeshBody(v, f, band=max(float(ext.max()) / 48.0, 1e-6))
        e = v[f[:, [1, 2, 0]]] - v[f]
        edge = float(np.sqrt((e ** 2).sum(axis=2)).mean())
        self.index = SurfaceIndex(v, f, cell=max(edge, float(ext.max()) / 300.0))

    @property
    def bounds(self):
        return self.lo.copy(), self.hi.copy()

    @property
    def volume(self) -> float:
        return self._volume

    def inside_grid(self, xs, ys, zs):
        return self.body.inside_grid(xs, ys, zs)

    def wall(self, points, upper):
        return self.index.nearest(points, upper)


class FieldDomain:
    """A field, negative inside, over given bounds; boundary distances estimated as ``|f| / |∇f|``."""

    kind = "field"
    walls = True

    def __init__(self, field, lo, hi):
        self.field = field
        self.lo = np.asarray(lo, dtype=np.float64)
        self.hi = np.asarray(hi, dtype=np.float64)
        self.volume = None

    @property
    def bounds(self):
        return self.lo.copy(), self.hi.copy()

    def inside_grid(self, xs, ys, zs):
        return self.field.sample_grid(xs, ys, zs) < 0

    def wall(self, points, upper):
        # the gradient by forward differences (4 field evaluations, not 7 for central ones) over a step
        # of 1e-5 of the extent: its error, about step / (2 R) relative where the level set through the
        # point bends with radius R, moves the distance by about 2e-5 of it (tests/analysis/test_analysis_cost.py)
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        step = 1e-5 * float(np.max(self.hi - self.lo))
        f = np.asarray(self.field(p), dtype=np.float64)
        g = np.empty_like(p)
        for a in range(3):
            e = np.zeros(3)
            e[a] = step
            g[:, a] = (np.asarray(self.field(p + e), dtype=np.float64) - f) / step
        g2 = np.maximum((g ** 2).sum(axis=1), 1e-300)
        d = np.abs(f) / np.sqrt(g2)
        c = p - (f / g2)[:, None] * g
        far = ~(d < np.asarray(upper))
        d = np.where(far, upper, d)
        c[far] = np.nan
        return d, c


def make_domain(domain, vertices):
    """The analysis domain of ``domain`` (see the module doc) for a scaffold with these vertices."""
    from ..bodies.mesh import MeshBody
    from ..fields.base import Field

    v = np.asarray(vertices, dtype=np.float64)
    if domain is None:
        return BoxDomain(v.min(axis=0), v.max(axis=0))
    if isinstance(domain, (BoxDomain, MeshDomain, FieldDomain)):
        return domain
    if isinstance(domain, MeshBody):
        return MeshDomain(domain.vertices, domain.faces)
    if isinstance(domain, Field):
        lo, hi = v.min(axis=0), v.max(axis=0)
        bounds = getattr(domain, "bounds", None)
        if isinstance(bounds, tuple) and len(bounds) == 2:
            lo, hi = np.minimum(lo, bounds[0]), np.maximum(hi, bounds[1])
        return FieldDomain(domain, lo, hi)
    if isinstance(domain, (tuple, list)) and len(domain) == 2:
        return MeshDomain(*domain)
    raise InputError("the analysis domain must be None, a body mesh (vertices, faces) or a field")
