"""A contrast-CT-like phantom: a bent vessel with a branch against bone of the same brightness (issue 39).

The failure it reproduces: in a contrast-enhanced abdominal CT the aorta runs
beside the vertebral bodies, whose bone is as bright as the contrast, so a
global threshold joins them. :func:`ct_phantom` builds, in Hounsfield units:

* air (−1000) outside an elliptic body of soft tissue (40 HU);
* a **vessel** of contrast blood (300 HU): a main tube of radius ``r`` whose
  axis bends sideways (a ``tanh`` step of 0.6 r), with a branch of radius
  0.4 r leaving it at 55 % of its length (ends rounded, inside the image);
* a column of **vertebral bodies** (cylinders of radius 1.6 r, 300 HU, as
  bright as the blood) behind the vessel at a gap of ``gap`` mm (0.5 mm:
  closed by the blur), following its bend, separated by discs (90 HU);
* **partial volume**: each voxel averages its slice (three sub-slices across
  the slice thickness, a box profile) of a scene whose edges are blurred in
  plane by a Gaussian of half an in-plane voxel (the normal CDF of the signed
  distance); then Gaussian **noise** (``noise`` HU).

The vessel runs along the image axis of the largest physical extent, the bone
lies along the next; the image is in ITK's LPS physical frame (identity
direction). The truth: :attr:`CTPhantom.distance` (signed distance to the
vessel surface: the union of the two swept tubes, exact outside), the mask of
voxel centres inside, and the centreline graph with its true radii.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from .graph import CentrelineGraph
from .local_fields import tube_distance

AIR, TISSUE, BLOOD, BONE, DISC = -1000.0, 40.0, 300.0, 300.0, 90.0


@dataclass
class CTPhantom:
    array: np.ndarray          # (nx, ny, nz) int16 HU, indexed [i, j, k]
    geometry: dict             # spacing, origin, direction (LPS, identity)
    graph: CentrelineGraph     # the true centreline with its true radii (LPS mm)
    main: tuple                # (points, radii) of the main vessel's axis
    branch: tuple              # (points, radii) of the branch's axis
    bone: dict                 # axis points, radius, vertebra/disc heights
    mask: np.ndarray           # (nx, ny, nz) bool: voxel centres inside the vessel

    def distance(self, points) -> np.ndarray:
        """Signed distance (mm) of ``points (N, 3)`` to the true vessel surface (negative inside)."""
        X = np.asarray(points, float).reshape(-1, 3)
        return np.minimum(tube_distance(X, *self.main), tube_distance(X, *self.branch))


def _axes(shape, spacing):
    """Canonical axes: (along the vessel, toward the bone, lateral) as image axis numbers."""
    ext = np.asarray(shape, float) * np.asarray(spacing, float)
    s = int(np.argmax(ext))
    rest = [a for a in range(3) if a != s]
    t = max(rest, key=lambda a: ext[a])
    u = [a for a in rest if a != t][0]
    return s, t, u, ext


def _scene(shape, spacing, radius, gap):
    """The geometry in physical coordinates: (main P, R), (branch P, R), bone dict, body semi-axes."""
    s, t, u, ext = _axes(shape, spacing)
    E = np.zeros((3, 3))
    E[s, 0] = E[t, 1] = E[u, 2] = 1.0   # canonical (s, t, u) -> physical via columns
    r = float(radius) if radius else float(min(9.0, 0.13 * min(ext[t], ext[u])))
    rb = 1.6 * r
    half = ext / 2.0
    s0, s1 = -half[s] + r + 2.0, half[s] - r - 2.0
    n = max(8, int(np.ceil((s1 - s0) / 1.0)) + 1)
    sv = np.linspace(s0, s1, n)
    bend = 0.6 * r * np.tanh(sv / max((s1 - s0) / 4.0, 1e-6))
    ta = -0.5 * (r + gap + rb) + 0.3 * rb     # vessel and bone straddle the centre, bone partly in view
    main = np.stack([sv, np.full(n, ta), bend], axis=1)
    j = int(round(0.55 * (n - 1)))
    d = np.array([0.3, -0.25, 1.0])
    d /= np.linalg.norm(d)
    reach = half[u] - 0.4 * r - 3.0 - bend[j]
    L = float(min(2.5 * r, reach / d[2]))
    m = max(3, int(np.ceil(L / 1.0)) + 1)
    br = main[j] + np.linspace(0.0, L, m)[:, None] * d
    bone_axis = main + np.array([0.0, r + gap + rb, 0.0])
    centre = np.zeros(3)
    to_phys = lambda P: P @ E.T + centre  # noqa: E731
    return ((to_phys(main), np.full(n, r)), (to_phys(br), np.full(m, 0.4 * r)),
            {"axis": to_phys(bone_axis), "radius": rb, "s_axis": s, "height": 2.0 * r + 4.0, "disc": 5.0},
            {"t": (t, 0.5 * ext[t] - 1.0), "u": (u, 0.5 * ext[u] - 1.0)}, j)


def bone_distances(X, bone):
    """Signed distances to the vertebral bodies and to the discs between them."""
    radial = tube_distance(X, bone["axis"], np.full(len(bone["axis"]), bone["radius"]))
    s = X[:, bone["s_axis"]]
    period = bone["height"] + bone["disc"]
    w = np.abs(np.mod(s + 0.5 * bone["disc"], period) - 0.5 * period)  # 0 mid-vertebra
    in_body = w - 0.5 * bone["height"]
    return np.maximum(radial, in_body), np.maximum(radial, -in_body)


def render_ct(axes, h, scene, noise: float, seed: int):
    """``(image, vessel mask)`` of ``scene(points) -> (HU, signed distance to the vessel)`` on the grid ``axes``:
    each voxel the mean of three sub-slices across its thickness ``h[2]`` (partial volume), Gaussian ``noise``
    (HU, seeded) added, HU rounded to int16; the mask at the voxel centres."""
    shape = tuple(len(a) for a in axes)
    out = np.empty(shape, np.float32)
    mask = np.empty(shape, bool)
    for k in range(shape[2]):
        acc = np.zeros(shape[:2])
        for ds in (np.arange(3) - 1.0) / 3.0:
            X = np.stack(np.meshgrid(axes[0], axes[1], [axes[2][k] + ds * h[2]], indexing="ij"), -1).reshape(-1, 3)
            v, dv = scene(X)
            acc += v.reshape(shape[:2]) / 3.0
            if ds == 0.0:
                mask[:, :, k] = (dv <= 0).reshape(shape[:2])
        out[:, :, k] = acc
    if noise:
        out += np.random.default_rng(seed).normal(0.0, float(noise), shape).astype(np.float32)
    return np.clip(np.rint(out), -1024, 3071).astype(np.int16), mask


def ct_phantom(shape=(72, 72, 48), spacing=(0.8, 0.8, 1.5), radius: float | None = None, gap: float = 0.5,
               noise: float = 20.0, seed: int = 0) -> CTPhantom:
    """The phantom on an image of ``shape`` voxels (module docstring); deterministic for a ``seed``."""
    shape = tuple(int(v) for v in shape)
    h = np.asarray(spacing, float)
    origin = -0.5 * (np.asarray(shape) - 1) * h
    main, branch, bone, body, j = _scene(shape, h, radius, gap)
    sigma = 0.5 * float(min(h[0], h[1], h[2]))
    axes = [origin[a] + h[a] * np.arange(shape[a]) for a in range(3)]
    (ta, at), (ua, au) = body["t"], body["u"]
    f = lambda dist: ndtr(-dist / sigma)  # noqa: E731

    def scene(X):
        dv = np.minimum(tube_distance(X, *main), tube_distance(X, *branch))
        db, dd = bone_distances(X, bone)
        dbody = (np.sqrt((X[:, ta] / at) ** 2 + (X[:, ua] / au) ** 2) - 1.0) * min(at, au)
        return AIR + (TISSUE - AIR) * f(dbody) + (BLOOD - TISSUE) * f(dv) + (BONE - TISSUE) * f(db) \
            + (DISC - TISSUE) * f(dd), dv
    arr, mask = render_ct(axes, h, scene, noise, seed)
    P = np.concatenate([main[0], branch[0][1:]])
    R = np.concatenate([main[1], branch[1][1:]])
    n = len(main[0])
    E = [(i, i + 1) for i in range(n - 1)] + [(j, n)] + [(n + i, n + i + 1) for i in range(len(branch[0]) - 2)]
    g = CentrelineGraph(P, R, np.asarray(E), source="ct-phantom")
    geo = {"spacing": h.tolist(), "origin": origin.tolist(), "direction": np.eye(3).tolist()}
    return CTPhantom(arr, geo, g, main, branch, bone, mask)


def to_ras(points) -> np.ndarray:
    """LPS ↔ RAS: x and y negated (the same map both ways)."""
    P = np.array(points, float, copy=True).reshape(-1, 3)
    P[:, :2] *= -1.0
    return P


def write_ct_phantom(folder, ph: CTPhantom, frame: str = "lps", radii=None) -> dict:
    """Write ``ct.mha``, ``truth.mha`` (uint8 mask) and ``centreline.json`` (in ``frame``: lps or ras).

    ``radii``: a constant to write instead of the true radii (a rough centreline). Returns the paths.
    """
    import json
    from pathlib import Path
    from ..bodies.image import sitk_module
    sitk = sitk_module()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, arr in (("ct", ph.array), ("truth", ph.mask.astype(np.uint8))):
        im = sitk.GetImageFromArray(np.transpose(arr, (2, 1, 0)).copy())
        im.SetSpacing(tuple(ph.geometry["spacing"]))
        im.SetOrigin(tuple(ph.geometry["origin"]))
        paths[name] = folder / f"{name}.mha"
        sitk.WriteImage(im, str(paths[name]))
    P = ph.graph.points if frame == "lps" else to_ras(ph.graph.points)
    R = ph.graph.radii if radii is None else np.full(len(ph.graph.radii), float(radii))
    paths["centreline"] = folder / f"centreline-{frame}.json"
    paths["centreline"].write_text(json.dumps({"format": "porecad-centreline", "units": "mm", "frame": frame,
                                               "points": P.tolist(), "radii": R.tolist(),
                                               "edges": ph.graph.edges.tolist()}))
    return paths
