"""What gets sliced: a design's field (tpms and infill recipes) or a mesh (any other job, any mesh file).

Field jobs are sliced from the field the job meshes (after the body
calibration of a porosity target, :func:`porecad.lattice.plan.hold_porosity`),
never through a mesh; jobs whose solid is mapped from a parameter domain
(tbss, hex, tis, arbf) and the rest are run in memory and sliced from
their mesh.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..fields.base import Field

FIELD_JOBS = ("tpms", "infill")


@dataclasses.dataclass
class Part:
    lo: np.ndarray
    hi: np.ndarray
    field: Field | None = None
    mesh: object = None  # a trimesh.Trimesh
    boxed: bool = False  # the field is an unbounded lattice cut to [lo, hi]
    recipe: dict | None = None
    route: str = "mesh"
    windows: "LayerWindows | None" = None  # the field's layers, each on the pixels that can be solid

    def rotated(self, R: np.ndarray) -> "Part":
        """The part turned by the rotation ``R`` (print = R @ design)."""
        if np.allclose(R, np.eye(3)):
            return self
        if self.field is not None:
            f = Rotated(self.field, R, self.lo, self.hi, self.boxed)
            return Part(*f.bounds, field=f, recipe=self.recipe, route=self.route)
        m = self.mesh.copy()
        T = np.eye(4)
        T[:3, :3] = R
        m.apply_transform(T)
        return Part(m.bounds[0], m.bounds[1], mesh=m, recipe=self.recipe, route=self.route)


class Rotated(Field):
    """A field turned by ``R`` (cut to its design box first when it is an unbounded lattice)."""

    def __init__(self, field, R, lo, hi, boxed):
        self.field, self.R, self.boxed = field, np.asarray(R, dtype=float), boxed
        self.blo, self.bhi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        c = corners @ self.R.T
        self._bounds = (c.min(axis=0), c.max(axis=0))

    @property
    def bounds(self):
        return self._bounds

    def sample_grid(self, xs, ys, zs):
        """A turn by a signed permutation (the cube's face directions) samples the field's own grid."""
        R = self.R
        if not (np.allclose(np.abs(R).sum(axis=0), 1) and np.allclose(np.abs(R), np.abs(R).round())):
            return super().sample_grid(xs, ys, zs)
        axes = [np.asarray(a, dtype=np.float64) for a in (xs, ys, zs)]
        src = [int(np.argmax(np.abs(R[:, i]))) for i in range(3)]  # design axis i = sign * print axis src[i]
        design = [np.sign(R[src[i], i]) * axes[src[i]] for i in range(3)]
        v = np.asarray(self.field.sample_grid(*design), dtype=np.float32)  # (dz, dy, dx)
        order = [2 - src.index(2 - j) for j in range(3)]  # print axis (z, y, x) -> the design array's axis
        v = np.ascontiguousarray(np.transpose(v, order))
        if self.boxed:
            for i in range(3):
                d = np.maximum(self.blo[i] - design[i], design[i] - self.bhi[i]).astype(np.float32)
                shape = [1, 1, 1]
                shape[2 - src[i]] = -1
                np.maximum(v, d.reshape(shape), out=v)
        return v

    def evaluate(self, points):
        p = points @ self.R  # design coordinates
        v = np.asarray(self.field.evaluate(p), dtype=np.float64)
        if self.boxed:
            box = np.max(np.maximum(self.blo - p, p - self.bhi), axis=1)
            v = np.maximum(v, box)
        return v


def from_source(source, base=None) -> Part:
    """A :class:`Part` of a recipe (a dict or a ``.toml`` file, :func:`from_recipe`) or a mesh file."""
    if isinstance(source, dict):
        return from_recipe(source, base)
    p = Path(source)
    if p.suffix.lower() == ".toml":
        from ..io.recipe import read_recipe
        return from_recipe(read_recipe(p), base if base is not None else p.resolve().parent)
    import trimesh

    from ..io import read_mesh
    v, f = read_mesh(p)
    m = trimesh.Trimesh(v, f, process=False)
    return Part(m.bounds[0], m.bounds[1], mesh=m)


def from_recipe(recipe: dict, base=None) -> Part:
    """Plan a field job (or run any other job in memory) without writing its outputs.

    A body job with a porosity target is calibrated on the body's samples as the job does
    (:func:`porecad.lattice.plan.hold_porosity`), but for the exact field: without the
    corrections the job adds for its mesh's discretisation at its voxel (the mesh bias and the
    mesh passes' shift), so that the slices, not a coarse mesh, carry the asked porosity.
    """
    import trimesh

    from ..jobs.runner import parse, run_job
    job, spec, _, _ = parse(recipe, base)
    if job.name in FIELD_JOBS and spec.domain.boundary != "whole":
        from ..lattice.plan import hold_porosity, plan_lattice, replay_hold
        from ..jobs.tpms_job import regions_wanted
        plan = plan_lattice(spec)
        if plan.body is None:
            g = plan.grid
            return Part(np.asarray(g.box_min, float), np.asarray(g.box_max, float), field=plan.field, boxed=True,
                        recipe=recipe, route="field")
        n, axis = regions_wanted(spec, plan, calibrating=True)
        hold_porosity(plan, n, axis, allow=spec.tpms.allow_closed_pores)
        replay_hold(plan, 0.0, bias=0.0)  # the exact field: no correction for a mesh's discretisation
        lo, hi = plan.body.bounds
        field = layer_field(plan)
        return Part(np.asarray(lo, float), np.asarray(hi, float), field=field, recipe=recipe, route="field",
                    windows=LayerWindows.of(plan, field))
    result = run_job(job, spec)
    m = trimesh.Trimesh(result.vertices, result.faces, process=False)
    return Part(m.bounds[0], m.bounds[1], mesh=m, recipe=recipe)


def layer_field(plan):
    """The plan's solid for the slicer: a mesh body's distance exact only near its outline in each layer
    (:class:`porecad.bodies.slice_distance.SlicedBody`: the same sections, the grey of the pixels at
    least a few pixels inside or outside the outline interpolated); any other body's field as planned."""
    from ..bodies.mesh import MeshBody
    from ..bodies.slice_distance import SlicedBody
    from ..lattice.plan import solid_field
    if not isinstance(plan.body, MeshBody) or plan.boundary not in ("cut", "skin"):
        return plan.field
    skin = float(plan.body_info.get("skin", 0.0)) if plan.boundary == "skin" else 0.0
    return solid_field(plan.material, SlicedBody(plan.body, skin=skin), plan.boundary, plan.body_info)


class LayerWindows:
    """A body job's solid on a print layer's pixels, only where it can be solid (issue 54).

    Outside the rectangle of a layer where its :class:`~porecad.bodies.slice_distance.SlicedBody` is nearer
    than its band (:meth:`SlicedBody.sample_layer`), the body's value is ``+band`` and so is the solid's
    (``max(material, body)`` of a cut is at least ``band``, a skin's ``max(min(m, -d - T), d)`` is
    ``band``): no pixel there is solid, and none is grey while the field changes by less than twice the
    band over a pixel (a lattice's values change by a small fraction of that over a pixel; the grey of
    a pixel ``band`` outside the body would be an error anyway). :meth:`sample` gives the solid's values
    on that rectangle widened by ``margin`` pixels (the gradient's neighbours), the same as
    :meth:`Field.sample_grid` of the whole layer there.
    """

    def __init__(self, material, body, skin: float | None):
        self.material, self.body, self.skin = material, body, skin  # skin None: a cut

    @classmethod
    def of(cls, plan, field):
        """The windows of ``field`` (:func:`layer_field` of ``plan``), or None where it has none."""
        from ..bodies.slice_distance import SlicedBody
        from ..fields.base import Intersection
        if isinstance(field, Intersection) and isinstance(field.b, SlicedBody):
            return cls(field.a, field.b, None)
        if plan.boundary == "skin" and isinstance(getattr(field, "body", None), SlicedBody):
            return cls(field.material, field.body, float(field.skin))
        return None

    @property
    def outside(self) -> float:
        """The value of every pixel beyond a layer's window (float32)."""
        return float(np.float32(self.body.band))

    def sample(self, xs, ys, z: float, margin: int = 1):
        """``(i0, i1, j0, j1, values)``: the solid's values (float32 ``(j1 - j0, i1 - i0)``, non-finite ones
        clamped to ±1) on the pixels ``xs[i0:i1]`` x ``ys[j0:j1]`` of the layer ``z``; every other pixel is
        :attr:`outside` (no pixel at all: ``i1 == i0``)."""
        xs, ys = (np.ascontiguousarray(a, dtype=np.float64) for a in (xs, ys))
        nx, ny = len(xs), len(ys)
        if not self.body.layered(xs, ys):
            got = (0, nx, 0, ny, self.body.sample_grid(xs, ys, [z])[0])
        else:
            got = self.body.sample_layer(xs, ys, float(z))
        if got is None:
            return 0, 0, 0, 0, np.zeros((0, 0), np.float32)
        i0, i1, j0, j1, sub = got
        a0, a1, b0, b1 = max(0, i0 - margin), min(nx, i1 + margin), max(0, j0 - margin), min(ny, j1 + margin)
        d = np.full((b1 - b0, a1 - a0), self.body.band, np.float32)
        d[j0 - b0:j1 - b0, i0 - a0:i1 - a0] = sub
        m = np.asarray(self.material.sample_grid(xs[a0:a1], ys[b0:b1], np.array([z]))[0], dtype=np.float32)
        if self.skin is None:  # as fields.base.Intersection (material, body)
            v = np.maximum(m, d)
        else:  # as lattice.plan.SkinSolid
            np.minimum(m, -d - np.float32(self.skin), out=m)
            v = np.maximum(m, d, out=m)
        if not np.all(np.isfinite(v)):
            v = np.nan_to_num(v, nan=1.0, posinf=1.0, neginf=-1.0)
        return a0, a1, b0, b1, v


def directions() -> np.ndarray:
    """The 26 build directions of the cube's faces, edges and corners (unit vectors, faces first)."""
    d = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)],
                 dtype=float)
    d = d[np.argsort(np.abs(d).sum(axis=1), kind="stable")]
    return d / np.linalg.norm(d, axis=1)[:, None]


def rotation_to_z(d) -> np.ndarray:
    """The rotation that turns the design direction ``d`` into the build direction +z (Rodrigues)."""
    d = np.asarray(d, dtype=float) / np.linalg.norm(d)
    z = np.array([0.0, 0.0, 1.0])
    c = float(d @ z)
    if c > 1 - 1e-12:
        return np.eye(3)
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    k = np.cross(d, z)
    s = np.linalg.norm(k)
    k /= s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K
