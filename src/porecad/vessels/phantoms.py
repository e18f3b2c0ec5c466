"""Synthetic vessel phantoms with analytic centrelines and radii (acceptance tests, benchmarks).

A :class:`Phantom` is a set of branches, each an analytic curve ``c(t)``,
``t ∈ [0, 1]``, with a radius ``r(t)``; its *analytic surface* is the
boundary of the union of the balls ``B(c(t), r(t))`` (the swept tube), whose
signed distance :meth:`Phantom.distance` is computed on a dense sampling of
the curves (sampling error below 1e-5 mm at the sizes used). The phantoms:
``straight``, ``curved`` (a quarter circle of centreline radius 6 mm),
``y`` (a Y-bifurcation) and ``tree`` (three generations, five branches).
:func:`phantom_image` voxelises one with optional Gaussian noise (for the
image route).
"""

from __future__ import annotations

from dataclasses import dataclass, field as dc_field

import numpy as np

from .graph import CentrelineGraph, from_polylines


@dataclass
class Branch:
    curve: object          # t -> (len(t), 3)
    radius: object         # t -> (len(t),)
    length: float


@dataclass
class Phantom:
    name: str
    branches: list
    junctions: list = dc_field(default_factory=list)   # junction points (3,)
    _dense: tuple | None = None

    def graph(self, spacing: float = 0.25) -> CentrelineGraph:
        """The centreline graph: each branch sampled about every ``spacing`` mm of arc."""
        lines, rads = [], []
        for b in self.branches:
            n = max(2, int(np.ceil(b.length / spacing)) + 1)
            t = np.linspace(0.0, 1.0, n)
            lines.append(b.curve(t))
            rads.append(b.radius(t))
        return from_polylines(lines, rads, source=f"phantom:{self.name}")

    def dense(self, n_per_mm: int = 400):
        if self._dense is None:
            P, R, B = [], [], []
            for k, b in enumerate(self.branches):
                n = max(2, int(b.length * n_per_mm))
                t = np.linspace(0.0, 1.0, n)
                P.append(b.curve(t))
                R.append(b.radius(t))
                B.append(np.full(n, k))
            self._dense = (np.concatenate(P), np.concatenate(R), np.concatenate(B))
        return self._dense

    def distance(self, x, k: int = 64):
        """Signed distance to the analytic swept tube, and the radius of the nearest ball ``(d, r)``."""
        from scipy.spatial import cKDTree
        P, R, _ = self.dense()
        tree = getattr(self, "_tree", None)
        if tree is None:
            tree = self._tree = cKDTree(P)
        x = np.asarray(x, float).reshape(-1, 3)
        dist, idx = tree.query(x, k=min(k, len(P)))
        val = dist - R[idx]
        j = np.argmin(val, axis=1)
        rows = np.arange(len(x))
        return val[rows, j], R[idx[rows, j]]

    def bounds(self):
        P, R, _ = self.dense()
        return (P - R[:, None]).min(0), (P + R[:, None]).max(0)


def _line(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return (lambda t: a + np.asarray(t)[:, None] * (b - a)), float(np.linalg.norm(b - a))


def _const(r):
    return lambda t: np.full(len(np.atleast_1d(t)), float(r))


def straight(radius=1.0, length=8.0) -> Phantom:
    c, L = _line((0, 0, 0), (0, 0, length))
    return Phantom("straight", [Branch(c, _const(radius), L)])


def curved(radius=1.0, bend=6.0, angle=np.pi / 2) -> Phantom:
    def c(t):
        th = np.asarray(t) * angle
        return np.stack([bend * (1 - np.cos(th)), np.zeros_like(th), bend * np.sin(th)], axis=1)
    return Phantom("curved", [Branch(c, _const(radius), bend * angle)])


def _children(p, direction, length, r, spread_deg, plane_axis):
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    ax = np.asarray(plane_axis, float)
    ax = ax - d * (ax @ d)
    ax /= np.linalg.norm(ax)
    out = []
    for s in (+1, -1):
        a = np.deg2rad(spread_deg) * s
        dd = np.cos(a) * d + np.sin(a) * ax
        out.append(_line(p, p + length * dd) + (dd,))
    return out


def y_bifurcation(r0=1.0, r1=0.75, length=5.0, spread=35.0) -> Phantom:
    c0, L0 = _line((0, 0, 0), (0, 0, length))
    p = np.array([0, 0, length], float)
    br = [Branch(c0, _const(r0), L0)]
    for c, L, _ in _children(p, (0, 0, 1), length, r1, spread, (1, 0, 0)):
        br.append(Branch(c, _const(r1), L))
    return Phantom("y", br, junctions=[p])


def tree(r0=1.0, length=5.0) -> Phantom:
    c0, L0 = _line((0, 0, 0), (0, 0, length))
    p = np.array([0, 0, length], float)
    br = [Branch(c0, _const(r0), L0)]
    junctions = [p]
    kids = _children(p, (0, 0, 1), 0.8 * length, 0.75 * r0, 35.0, (1, 0, 0))
    for k, (c, L, d) in enumerate(kids):
        br.append(Branch(c, _const(0.75 * r0), L))
        if k == 0:
            q = c(np.array([1.0]))[0]
            junctions.append(q)
            for c2, L2, _ in _children(q, d, 0.6 * length, 0.55 * r0, 35.0, (0, 1, 0)):
                br.append(Branch(c2, _const(0.55 * r0), L2))
    return Phantom("tree", br, junctions=junctions)


PHANTOMS = {"straight": straight, "curved": curved, "y": y_bifurcation, "tree": tree}


def phantom_image(ph: Phantom, spacing: float, noise: float = 0.0, seed: int = 0, margin: float = 1.5,
                  blur: float = 0.0):
    """Voxelise a phantom: ``(array[i, j, k], geometry)`` with 1 inside, 0 outside (partial-volume
    anti-aliased over one voxel), plus Gaussian noise of std ``noise``."""
    lo, hi = ph.bounds()
    lo, hi = lo - margin, hi + margin
    n = np.ceil((hi - lo) / spacing).astype(int) + 1
    axes = [lo[a] + spacing * np.arange(n[a]) for a in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    d, _ = ph.distance(np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1))
    img = np.clip(0.5 - d.reshape(X.shape) / spacing, 0.0, 1.0)
    if blur > 0:
        from scipy import ndimage
        img = ndimage.gaussian_filter(img, blur)
    if noise > 0:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    geometry = {"spacing": [spacing] * 3, "origin": lo.tolist(), "direction": np.eye(3).tolist()}
    return img.astype(np.float32), geometry


def surface_error(vertices, faces, ph: Phantom, n: int = 20000, seed: int = 0, near: float = 2.0) -> dict:
    """Distance of the mesh to the analytic surface relative to the local radius.

    ``n`` points sampled uniformly by area on the mesh; ``|d(x)| / r(x)``
    with ``d`` the analytic signed distance and ``r`` the radius of the
    nearest ball. Reported over the whole surface and split into points
    within ``near`` × radius of a junction (where the blend adds material by
    design) and elsewhere.
    """
    import trimesh
    m = trimesh.Trimesh(vertices, faces, process=False)
    pts, _ = trimesh.sample.sample_surface(m, n, seed=seed)
    d, r = ph.distance(pts)
    rel = np.abs(d) / r
    out = {"mean": float(rel.mean()), "max": float(rel.max()), "p95": float(np.percentile(rel, 95))}
    if ph.junctions:
        J = np.asarray(ph.junctions)
        dj = np.min(np.linalg.norm(pts[:, None, :] - J[None], axis=2), axis=1)
        close = dj < near * r
        for key, mask in (("junction", close), ("away", ~close)):
            if np.any(mask):
                out[key] = {"mean": float(rel[mask].mean()), "max": float(rel[mask].max()),
                            "fraction": float(mask.mean())}
    return out


def junction_report(vertices, faces, ph: Phantom, near: float = 2.0) -> dict:
    """Crease/gap indicators near the junctions (curvature report).

    Over the vertices within ``near`` × radius of a junction: the largest and
    99th-percentile ``|H| r`` (mean curvature in units of the local radius;
    a crease of the sharp union grows like ``r / h``) and the largest
    dihedral angle between adjacent faces there (degrees). Also the number
    of connected shells of the whole mesh (a gap would split it).
    """
    import trimesh
    from ..analysis.curvature import vertex_curvatures
    m = trimesh.Trimesh(vertices, faces, process=False)
    H, K, area = vertex_curvatures(vertices, faces)
    d, r = ph.distance(vertices)
    J = np.asarray(ph.junctions) if ph.junctions else np.zeros((0, 3))
    out = {"shells": int(len(trimesh.graph.connected_components(m.face_adjacency, min_len=1)))}
    if len(J) == 0:
        return out
    dj = np.min(np.linalg.norm(vertices[:, None, :] - J[None], axis=2), axis=1)
    close = dj < near * r
    hr = np.abs(H[close]) * r[close]
    hr = hr[np.isfinite(hr)]
    adj = m.face_adjacency
    ang = np.degrees(m.face_adjacency_angles)
    fclose = close[faces[adj[:, 0]]].all(axis=1)
    out.update(max_abs_H_r=float(hr.max()), p99_abs_H_r=float(np.percentile(hr, 99)),
               max_dihedral_deg=float(ang[fclose].max()), vertices=int(close.sum()))
    return out


def junction_field_curvature(field, vertices, ph: Phantom, near: float = 2.0, fd_step: float = 0.02) -> dict:
    """Analytic-field curvature at the surface near the junctions (crease indicator).

    Mesh vertices within ``near`` × radius of a junction are projected onto
    the field's zero set and the level-set mean curvature is taken by central
    differences of step ``fd_step`` mm (:func:`porecad.analysis.curvature.field_curvatures`).
    A crease (sharp union) gives ``|H| r`` of order ``r / fd_step``; a C² blend
    of span δ stays of order ``r / δ``.
    """
    from ..analysis.curvature import implicit_curvatures, project_to_level_set
    from ..fields.derivatives import finite_difference_derivatives
    d, r = ph.distance(vertices)
    J = np.asarray(ph.junctions)
    dj = np.min(np.linalg.norm(vertices[:, None, :] - J[None], axis=2), axis=1)
    close = dj < near * r
    p = project_to_level_set(field, vertices[close])
    _v, g, Hf = finite_difference_derivatives(field, p, h=fd_step)
    H, _K = implicit_curvatures(g, Hf)
    hr = np.abs(H) * r[close]
    hr = hr[np.isfinite(hr)]
    return {"max_abs_H_r": float(hr.max()), "p99_abs_H_r": float(np.percentile(hr, 99)),
            "mean_abs_H_r": float(hr.mean()), "vertices": int(close.sum())}
