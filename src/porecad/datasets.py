"""Bodies for tests and benchmarks, in the style of :mod:`skimage.data` (issue 20).

Every function returns plain arrays, deterministic for a given ``seed``:
``(vertices (V, 3) float64 mm, faces (F, 3) int64)`` for surface bodies —
closed, 2-manifold, outward-oriented, free of self-intersections — and
``(mask (nx, ny, nz) uint8, spacing (3,) float)`` for image bodies.

* :func:`femur` — the sample femur of the project (``../shared/data/femur.stl``).
* :func:`bunny` — the Stanford bunny (low-resolution version of the npm
  package ``bunny``; its holes in the base closed, see :data:`BUNNY_NOTE`).
* :func:`star_blob` — a noisy star-shaped blob like a scanned head (every
  ray from the origin crosses the surface once), at any even triangle count.
* :func:`curved_bone` — a long, bowed shaft with a ball head and two condyles:
  not star-shaped, the case the sliced TBSS fit leaves uncovered.
* :func:`torus_body` — a genus-1 body (a cube map must refuse it).
* :func:`limbed_body` — a torso with limbs thinner than a twelfth of its extent.
* :func:`segmented_volume` / :func:`segmented_body` — a bone-like body
  segmented from an anisotropic image: a 0/1 mask with staircase noise on its
  boundary, and the (unsmoothed) staircase mesh of that mask.
* :func:`ct_volume` — a CT-like image (Hounsfield units, anisotropic voxels)
  holding a bone-like body with a cortical shell and a branching
  contrast-filled vessel beside it (the timing case of issue 20, item 6).

The implicit bodies (bone, torus, limbs, segmentation) are polygonised by
porecad's marching cubes (closed and manifold by construction); the grid
spacing is chosen so that the triangle count is near the one asked for.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = ["BODIES", "BUNNY_NOTE", "body", "bunny", "curved_bone", "femur", "femur_path", "limbed_body",
           "segmented_body", "segmented_volume", "star_blob", "torus_body", "ct_volume", "bone_field",
           "CT_SHAPE", "CT_SPACING"]

#: where the bundled data lie
DATA = Path(__file__).resolve().parent / "data"

BUNNY_NOTE = (
    "Stanford bunny: Stanford University Computer Graphics Laboratory, Stanford 3D Scanning Repository "
    "(Turk & Levoy, 1994). Low-resolution version from the npm package 'bunny' 1.0.1 by Mikola Lysenko "
    "(licence: Public Domain). porecad closed its holes in the base and scaled it from metres to mm.")

#: the largest triangle count a generator makes (bounds memory and time before any work)
MAX_TRIANGLES = 2_000_000


def femur_path() -> Path:
    """Path of the project's sample femur: ``$PORECAD_FEMUR``, or ``shared/data/femur.stl`` beside the checkout.

    Raises
    ------
    InputError
        When no femur file is found (it is project data, not shipped in the package).
    """
    cands = []
    env = os.environ.get("PORECAD_FEMUR")
    if env:
        cands.append(Path(env))
    here = Path(__file__).resolve()
    for up in here.parents[2:5]:  # src/porecad/datasets.py → repository → its parent
        cands.append(up / "shared" / "data" / "femur.stl")
    cands.append(Path.cwd().parent / "shared" / "data" / "femur.stl")
    for c in cands:
        if c.is_file():
            return c
    raise InputError("the sample femur is not here: put it at ../shared/data/femur.stl beside the checkout "
                     "or set PORECAD_FEMUR to its path")


def femur():
    """The project's sample femur (about 470 k mm³, 470 mm long): ``(vertices, faces)``."""
    from .io import read_mesh
    v, f = read_mesh(femur_path())
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


def bunny():
    """The Stanford bunny, closed (holes in the base filled), in mm (about 155 × 150 × 120).

    3,674 triangles of the npm package ``bunny`` plus the fill triangles.
    Attribution and licence: :data:`BUNNY_NOTE`.
    """
    with np.load(DATA / "bunny.npz") as z:
        lo, scale = z["lo"], z["scale"]
        v = lo + z["vertices"].astype(np.float64) * scale
        f = z["faces"].astype(np.int64)
    return v, f


# ----------------------------------------------------------------------------------------- generators


def _check_triangles(n, lo=200):
    if isinstance(n, bool) or int(n) != n or not lo <= int(n) <= MAX_TRIANGLES:
        raise InputError(f"triangles must be a whole number in {lo}..{MAX_TRIANGLES}, got {n!r}")
    return int(n)


def _fibonacci_sphere(n):
    """``n`` nearly uniform unit vectors (golden-angle spiral)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def star_blob(triangles: int = 4000, seed: int = 0, size: float = 100.0, noise: float = 0.006):
    """A noisy star-shaped blob, like a scanned head: every ray from the origin crosses it once.

    The triangulation is the convex hull of a golden-spiral point set on the
    unit sphere (exactly ``2 N − 4`` triangles for ``N`` points); each point
    is moved along its ray to ``r(d) = 1 + Σ_i b_i exp((d · c_i − 1) / w_i) + noise``
    (12 random bumps, ``b_i`` in [−0.12, 0.22], and independent scan noise of
    relative amplitude ``noise``), then the blob is scaled to about
    ``0.8 × 0.9 × 1.15`` ``size`` mm. A radial graph over a triangulated
    sphere is star-shaped about the origin (each triangle keeps its cone of
    rays), and a linear scaling keeps that.

    Parameters
    ----------
    triangles : int
        Even number of triangles (rounded down to even), 200..2,000,000.
    seed : int
    size : float
        Approximate height (mm).
    noise : float
        Relative amplitude of the per-vertex noise.
    """
    from scipy.spatial import ConvexHull
    n = _check_triangles(triangles)
    rng = np.random.default_rng(seed)
    d = _fibonacci_sphere(n // 2 + 2)
    f = np.asarray(ConvexHull(d).simplices, np.int64)
    p = d[f]  # hull simplices come unoriented: make each face's normal point away from the origin
    flip = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])) < 0
    f[flip] = f[flip][:, ::-1]
    c = rng.normal(size=(12, 3))
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    b = rng.uniform(-0.12, 0.22, 12)
    w = rng.uniform(0.08, 0.35, 12)
    r = 1.0 + np.exp((d @ c.T - 1.0) / w) @ b + noise * rng.standard_normal(len(d))
    r = np.maximum(r, 0.3)
    v = d * r[:, None] * (0.5 * size * np.array([0.8, 0.9, 1.15]))
    return _outward(v, f)


def _outward(v, f):
    p = v[f]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()
    return v.astype(np.float64), (f if vol > 0 else f[:, ::-1]).astype(np.int64).copy()


def _smin(a, b, k):
    """Polynomial smooth minimum (Quilez): a blend of width ``k``."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def _segment_distance(p, a, b):
    ab = b - a
    t = np.clip(((p - a) @ ab) / float(ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _ellipsoid(p, c, radii):
    """Approximate signed distance to an ellipsoid (scaled by the smallest radius)."""
    q = (p - c) / radii
    return (np.linalg.norm(q, axis=-1) - 1.0) * float(np.min(radii))


def _polygonise_field(func, lo, hi, triangles, seed_spacing=None):
    """Closed mesh of ``{func < 0}`` in the box, with about ``triangles`` triangles (two passes)."""
    from .mesh.polygonise import Grid, polygonise

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)

    def run(h):
        grid = Grid.from_box(lo, hi, spacing=h)

        def sample(xs, ys, zs):
            Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")
            return func(np.stack([X, Y, Z], axis=-1)).astype(np.float32)

        res = polygonise(sample, grid, caps=True, threads=1)
        return res.vertices, res.faces.astype(np.int64)

    h0 = seed_spacing if seed_spacing is not None else float(np.prod(hi - lo) ** (1 / 3)) / 40.0
    v, f = run(h0)
    h = h0 * np.sqrt(len(f) / triangles)
    v, f = run(h)
    return _largest_piece(v, f)


def _largest_piece(v, f):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n = len(v)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    _, lab = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
    keep_f = lab[f[:, 0]] == np.argmax(np.bincount(lab[f[:, 0]]))
    f = f[keep_f]
    used = np.unique(f)
    remap = np.full(n, -1, np.int64)
    remap[used] = np.arange(len(used))
    return _outward(v[used], remap[f])


def bone_field(p, length, seed):
    """A bowed shaft (radius 0.055 L) with a ball head on a neck and two condyles; negative inside."""
    rng = np.random.default_rng(seed)
    L = float(length)
    bow = L * (0.06 + 0.02 * rng.uniform())
    # centreline: a circular arc in the x-z plane from z = 0.1 L to 0.9 L, sagitta ``bow``
    z0, z1 = 0.1 * L, 0.9 * L
    half = 0.5 * (z1 - z0)
    R = (half * half + bow * bow) / (2.0 * bow)
    cz, cx = 0.5 * (z0 + z1), bow - R
    rel = np.stack([p[..., 0] - cx, p[..., 2] - cz], axis=-1)
    ang = np.arctan2(rel[..., 1], rel[..., 0])
    amax = np.arcsin(half / R)
    angc = np.clip(ang, -amax, amax)
    qx, qz = cx + R * np.cos(angc), cz + R * np.sin(angc)
    s = (angc + amax) / (2.0 * amax)  # 0 at the bottom, 1 at the top
    radius = L * (0.05 + 0.012 * np.cos(2.0 * np.pi * s))
    shaft = np.sqrt((p[..., 0] - qx) ** 2 + p[..., 1] ** 2 + (p[..., 2] - qz) ** 2) - radius
    top = np.array([cx + R * np.cos(amax), 0.0, cz + R * np.sin(amax)])
    bottom = np.array([cx + R * np.cos(-amax), 0.0, cz + R * np.sin(-amax)])
    head_c = top + L * np.array([-0.09, 0.02, 0.06])
    neck = _segment_distance(p, top, head_c) - 0.045 * L
    head = np.linalg.norm(p - head_c, axis=-1) - 0.085 * L
    troch = _ellipsoid(p, top + L * np.array([0.05, 0.0, 0.0]), L * np.array([0.06, 0.055, 0.08]))
    cond_a = _ellipsoid(p, bottom + L * np.array([0.0, 0.055, -0.04]), L * np.array([0.075, 0.06, 0.07]))
    cond_b = _ellipsoid(p, bottom + L * np.array([0.0, -0.055, -0.04]), L * np.array([0.075, 0.06, 0.07]))
    k = 0.03 * L
    out = _smin(shaft, neck, k)
    for g in (head, troch, cond_a, cond_b):
        out = _smin(out, g, k)
    return out


def curved_bone(triangles: int = 6000, seed: int = 0, length: float = 240.0):
    """A long, bowed bone with bulbous ends (ball head on a neck, trochanter, two condyles); not star-shaped.

    The smooth union (polynomial smooth minimum, blend ``0.03 L``) of a shaft
    around a circular arc (sagitta 6–8 % of ``L``, radius 4–6 % of ``L``),
    a neck and a ball head at the top, a trochanter, and two ellipsoidal
    condyles at the bottom; polygonised by marching cubes.
    """
    n = _check_triangles(triangles)
    L = float(length)
    lo = np.array([-0.35, -0.2, -0.08]) * L
    hi = np.array([0.3, 0.2, 1.1]) * L
    return _polygonise_field(lambda p: bone_field(p, L, seed), lo, hi, n)


def torus_body(triangles: int = 4000, seed: int = 0, major: float = 40.0, minor: float = 14.0):
    """A genus-1 body: a torus (radii ``major``, ``minor`` mm) with a smooth random bulge pattern."""
    n = _check_triangles(triangles)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, 3)

    def field(p):
        a = np.arctan2(p[..., 1], p[..., 0])
        q = np.hypot(p[..., 0], p[..., 1]) - major
        r = minor * (1.0 + 0.12 * np.sin(3 * a + ph[0]) + 0.06 * np.sin(5 * a + ph[1]))
        return np.hypot(q, p[..., 2]) - r

    m = major + 1.3 * minor
    return _polygonise_field(field, [-m, -m, -1.3 * minor], [m, m, 1.3 * minor], n)


def limbed_body(triangles: int = 6000, seed: int = 0, size: float = 120.0):
    """A figurine: ellipsoid torso and head with four limbs of radius ``size / 45`` (thinner than ``size / 12``)."""
    n = _check_triangles(triangles)
    rng = np.random.default_rng(seed)
    S = float(size)
    r = S / 45.0
    torso_c = np.array([0.0, 0.0, 0.5]) * S
    shoulder = [np.array([s * 0.12, 0.0, 0.68]) * S for s in (-1, 1)]
    hip = [np.array([s * 0.07, 0.0, 0.33]) * S for s in (-1, 1)]
    jit = rng.uniform(-0.04, 0.04, (4, 3)) * S
    hands = [np.array([s * 0.42, 0.05, 0.55]) * S + jit[i] for i, s in enumerate((-1, 1))]
    feet = [np.array([s * 0.14, 0.0, 0.0]) * S + jit[2 + i] * np.array([1, 1, 0]) for i, s in enumerate((-1, 1))]

    def field(p):
        out = _ellipsoid(p, torso_c, np.array([0.14, 0.08, 0.22]) * S)
        out = _smin(out, np.linalg.norm(p - np.array([0, 0, 0.86]) * S, axis=-1) - 0.08 * S, 0.02 * S)
        for a, b in zip(shoulder + hip, hands + feet):
            out = _smin(out, _segment_distance(p, a, b) - r, 0.015 * S)
        return out

    return _polygonise_field(field, np.array([-0.5, -0.2, -0.06]) * S, np.array([0.5, 0.2, 0.98]) * S, n)


def segmented_volume(seed: int = 0, shape=(96, 60, 110), spacing=(0.88, 0.88, 1.5), noise: float = 0.8):
    """A bone-like body segmented from an anisotropic image: ``(mask, spacing)``.

    The curved bone of :func:`curved_bone` fitted into the image box, sampled
    at the voxel centres (``x = (i + ½) s``), with uniform noise of
    ``± noise`` voxels added to its signed distance before the 0/1 decision
    (staircase and boundary noise of a segmentation), its largest connected
    piece kept and its cavities filled.

    Returns
    -------
    mask : (nx, ny, nz) uint8
        1 inside the body; index ``(i, j, k)`` at ``((i + ½) s_x, (j + ½) s_y, (k + ½) s_z)`` mm.
    spacing : (3,) float
    """
    from scipy import ndimage
    sh = tuple(int(x) for x in shape)
    if len(sh) != 3 or min(sh) < 8 or int(np.prod(sh)) > 64_000_000:
        raise InputError(f"shape must be three sizes >= 8 with at most 64 M voxels, got {shape!r}")
    sp = np.asarray(spacing, float)
    if sp.shape != (3,) or np.any(~np.isfinite(sp)) or np.any(sp <= 0):
        raise InputError(f"spacing must be three positive numbers, got {spacing!r}")
    ext = np.array(sh) * sp
    # the bone's box is about 0.65 x 0.4 x 1.18 L: take the longest axis of the image as its length
    order = np.argsort(ext)
    L = float(min(ext[order[2]] / 1.25, ext[order[1]] / 0.7, ext[order[0]] / 0.45))
    axes = [(np.arange(n) + 0.5) * s for n, s in zip(sh, sp)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    # body frame: its z along the image's longest axis, centred
    Q = np.empty_like(P)
    Q[..., 2] = P[..., order[2]] - 0.5 * ext[order[2]] + 0.5 * L
    Q[..., 0] = P[..., order[1]] - 0.5 * ext[order[1]] - 0.02 * L
    Q[..., 1] = P[..., order[0]] - 0.5 * ext[order[0]]
    d = bone_field(Q, L, seed)
    rng = np.random.default_rng(seed + 1)
    d = d + noise * float(sp.min()) * rng.uniform(-1.0, 1.0, d.shape)
    mask = d < 0
    lab, nlab = ndimage.label(mask)
    if nlab > 1:
        mask = lab == (1 + int(np.argmax(np.bincount(lab.ravel())[1:])))
    mask = ndimage.binary_fill_holes(mask)
    mask[[0, -1], :, :] = mask[:, [0, -1], :] = mask[:, :, [0, -1]] = False
    return mask.astype(np.uint8), sp


def segmented_body(seed: int = 0, shape=(96, 60, 110), spacing=(0.88, 0.88, 1.5)):
    """The staircase mesh of :func:`segmented_volume`'s mask (marching cubes at ½, not smoothed)."""
    from .mesh.polygonise import Grid, polygonise
    mask, sp = segmented_volume(seed, shape, spacing)
    m = np.pad(mask, 1).astype(np.float32)
    n = np.array(m.shape)
    grid = Grid(origin=tuple((-0.5 * sp).tolist()), spacing=tuple(sp.tolist()), shape=tuple(int(x) for x in n))

    def sample(xs, ys, zs):
        i = np.rint((np.asarray(xs) - grid.origin[0]) / sp[0]).astype(np.int64)
        j = np.rint((np.asarray(ys) - grid.origin[1]) / sp[1]).astype(np.int64)
        k = np.rint((np.asarray(zs) - grid.origin[2]) / sp[2]).astype(np.int64)
        return np.ascontiguousarray((0.5 - m[np.ix_(i, j, k)]).transpose(2, 1, 0))

    res = polygonise(sample, grid, caps=True, threads=1)
    return _largest_piece(res.vertices, res.faces.astype(np.int64))


#: the CT-like volume of issue 20 (item 6): voxels and their size (mm)
CT_SHAPE = (157, 393, 34)
CT_SPACING = (0.88, 0.88, 1.5)

#: Hounsfield units of the CT phantom's tissues (typical values: air, fat, muscle, iodine-filled lumen, cancellous
#: and cortical bone)
CT_HU = {"air": -1000.0, "fat": -90.0, "muscle": 45.0, "marrow": -40.0, "cancellous": 420.0,
         "cortex": 1250.0, "contrast": 330.0}


def _tube_tree_distance(p, branches):
    """Signed distance (approximate, negative inside) to a union of tapered tubes along polylines."""
    out = np.full(p.shape[:-1], np.inf)
    for pts, radii in branches:
        for a, b, ra, rb in zip(pts[:-1], pts[1:], radii[:-1], radii[1:]):
            ab = b - a
            t = np.clip(((p - a) @ ab) / float(ab @ ab), 0.0, 1.0)
            d = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1) - (ra + t * (rb - ra))
            np.minimum(out, d, out=out)
    return out


def _ct_vessel_branches(ext, rng):
    """An aorta-like trunk along y with a bifurcation and three side branches, in the image's +x part."""
    x0 = 0.72 * ext[0] + rng.uniform(-2.0, 2.0)
    zc = 0.5 * ext[2]
    y_top, y_fork, y_end = 0.06 * ext[1], 0.68 * ext[1], 0.95 * ext[1]
    r0 = min(0.13 * ext[2], 0.05 * ext[0])
    trunk = (np.array([[x0, y_top, zc], [x0 + 1.5, 0.35 * ext[1], zc + 1.0], [x0, y_fork, zc]]),
             np.array([r0, 0.95 * r0, 0.9 * r0]))
    spread = 0.16 * ext[0]
    legs = [(np.array([[x0, y_fork, zc], [x0 + s * 0.5 * spread, 0.5 * (y_fork + y_end), zc + s * 0.08 * ext[2]],
                       [x0 + s * spread, y_end, zc + s * 0.12 * ext[2]]]),
             np.array([0.7 * r0, 0.62 * r0, 0.55 * r0])) for s in (-1.0, 1.0)]
    sides = []
    for yy, dz, length in ((0.22, 0.3, 0.16), (0.3, -0.3, 0.14), (0.45, 0.0, 0.12)):
        a = np.array([x0, yy * ext[1], zc])
        b = a + np.array([length * ext[0], 0.04 * ext[1], dz * 0.5 * ext[2]])
        b[0] = min(b[0], ext[0] - 0.35 * r0 - 2.0)
        sides.append((np.stack([a, 0.5 * (a + b), b]), np.array([0.38, 0.34, 0.3]) * r0))
    return [trunk] + legs + sides


def ct_volume(shape=CT_SHAPE, spacing=CT_SPACING, seed: int = 0, bone: bool = True, vessel: bool = True,
              noise: float = 12.0):
    """A CT-like volume (Hounsfield units) with a bone-like body and a branching contrast-filled vessel.

    The field of view ``shape × spacing`` (default 157 × 393 × 34 voxels of
    0.88 × 0.88 × 1.5 mm, a slab of an abdominal CT angiogram) holds, inside a
    soft-tissue outline (muscle under a fat layer, air outside):

    * a bone: :func:`bone_field` of length ``0.69 × extent_y`` lying along
      ``y``, flattened to fit the slab (×0.9 across, ×0.8 through the
      slices), in the ``x < 0.5 extent_x`` part; a cortical shell
      (1250 HU) 2 mm thick around cancellous bone (420 HU) at the ends and
      a fatty medullary canal (−40 HU) along the middle of the shaft;
    * a vessel: an aorta-like trunk along ``y`` (radius 13 % of the slab),
      its bifurcation and three side branches, filled with contrast
      (330 HU), in the ``x > 0.5 extent_x`` part, clear of the bone;

    with partial volume at every boundary (a logistic edge of 0.35 voxel)
    and Gaussian noise of ``noise`` HU. Voxel ``(i, j, k)`` lies at
    ``((i + ½) s_x, (j + ½) s_y, (k + ½) s_z)`` mm. A small ``shape`` with a
    proportionally larger ``spacing`` gives the same anatomy at coarse voxels.

    Returns
    -------
    dict
        ``ct`` (nx, ny, nz) int16 HU; ``geometry`` (spacing, origin, direction, for
        :func:`porecad.imaging.io.write_volume`); ``bone`` and ``vessel`` (bool masks of the
        noise-free bodies, partial voxels counted at half occupancy); ``branches``
        (the vessel's polylines as ``(points (n, 3) mm, radii (n,) mm)``).
    """
    sh, sp = _ct_checked(shape, spacing, noise)
    rng = np.random.default_rng(seed)
    ext = np.array(sh) * sp
    branches = _ct_vessel_branches(ext, rng)
    hu, bone_mask, vessel_mask = _ct_slices(sh, sp, ext, branches, seed, bone, vessel)
    if noise > 0:
        hu += rng.normal(0.0, float(noise), sh).astype(np.float32)
    ct = np.clip(np.rint(hu), -1024, 3071).astype(np.int16)
    geometry = {"spacing": sp.tolist(), "origin": (0.5 * sp).tolist(), "direction": np.eye(3).tolist()}
    return {"ct": ct, "geometry": geometry, "bone": bone_mask, "vessel": vessel_mask,
            "branches": [(p.copy(), r.copy()) for p, r in branches]}


def _ct_checked(shape, spacing, noise):
    """Takes :func:`ct_volume`'s ``shape``, ``spacing`` and ``noise``; returns ``(shape, spacing)`` checked.

    The shape as a tuple of 3 ints, the spacing as a (3,) float array; InputError when out of range.
    """
    sh = tuple(int(x) for x in shape)
    if len(sh) != 3 or min(sh) < 8 or int(np.prod(sh)) > 64_000_000:
        raise InputError(f"shape must be three sizes >= 8 with at most 64 M voxels, got {shape!r}")
    sp = np.asarray(spacing, float)
    if sp.shape != (3,) or np.any(~np.isfinite(sp)) or np.any(sp <= 0):
        raise InputError(f"spacing must be three positive numbers, got {spacing!r}")
    if not np.isfinite(noise) or not 0 <= noise <= 500:
        raise InputError(f"noise must be 0..500 HU, got {noise!r}")
    return sh, sp


def _occupancy(d, w: float):
    """Takes signed distances ``d`` (mm) and the edge width ``w``; returns the occupancy of ``{d < 0}``.

    A logistic partial-volume edge: 1 deep inside, 0 far outside, ½ on the boundary.
    """
    return 1.0 / (1.0 + np.exp(np.clip(d / w, -40.0, 40.0)))


def _ct_slices(sh, sp, ext, branches, seed: int, bone: bool, vessel: bool):
    """Takes the checked shape and spacing, the extent, the vessel branches and the body switches.

    Returns ``(hu, bone_mask, vessel_mask)``: the noise-free HU volume
    (float32) and the two bodies' masks, built slice by slice (memory stays a
    few slices): soft tissue (:func:`_ct_tissue`), then the bone
    (:func:`_ct_bone`) and the contrast-filled vessel over it.
    """
    w = 0.35 * float(sp.min())
    hu = np.empty(sh, np.float32)
    bone_mask = np.zeros(sh, bool)
    vessel_mask = np.zeros(sh, bool)
    L = 0.69 * ext[1] / 1.18
    xs, ys = ((np.arange(n) + 0.5) * s for n, s in zip(sh[:2], sp[:2]))
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    for k in range(sh[2]):  # slice by slice: memory stays a few slices
        z = (k + 0.5) * sp[2]
        P = np.stack([X, Y, np.full_like(X, z)], axis=-1)
        v = _ct_tissue(X, z, ext, w)
        if bone:
            v, bone_mask[:, :, k] = _ct_bone(v, X, Y, z, ext, L, seed, w)
        if vessel:
            lumen = _occupancy(_tube_tree_distance(P, branches), w)
            v = v * (1 - lumen) + lumen * CT_HU["contrast"]
            vessel_mask[:, :, k] = lumen >= 0.5
        hu[:, :, k] = v
    return hu, bone_mask, vessel_mask


def _ct_tissue(X, z: float, ext, w: float):
    """Takes a slice's x grid, its z, the extent and the edge width; returns its HU of air, fat and muscle.

    The soft-tissue outline is an elliptic cylinder along y filling most of
    the slab's width: muscle under a fat layer, air outside.
    """
    d_body = np.hypot((X - 0.5 * ext[0]) / (0.49 * ext[0]), (z - 0.5 * ext[2]) / (0.9 * ext[2])) - 1.0
    body = _occupancy(d_body * 0.45 * ext[0], w)
    muscle = _occupancy((d_body + 0.08) * 0.45 * ext[0], w)
    return CT_HU["air"] + body * (CT_HU["fat"] - CT_HU["air"]) + muscle * (CT_HU["muscle"] - CT_HU["fat"])


def _ct_bone(v, X, Y, z: float, ext, L: float, seed: int, w: float):
    """Takes a slice's HU ``v``, its grids and z, the extent, the bone length ``L``, the seed and edge width.

    Returns ``(v, mask)``: the slice with the bone over it (cortex, cancellous
    ends, a fatty canal along the shaft) and the bone's mask in the slice.
    """
    sx, sz = 0.9, 0.8
    Q = np.stack([(X - 0.3 * ext[0]) / sx, np.full_like(X, (z - 0.5 * ext[2]) / sz),
                  Y - 0.5 * ext[1] + 0.5 * L], axis=-1)
    d = bone_field(Q, L, seed) * min(sx, sz)
    outer = _occupancy(d, w)
    inner = _occupancy(d + 2.0, w)
    s = (Q[..., 2] - 0.1 * L) / (0.8 * L)
    canal = inner * _occupancy(-np.minimum(s - 0.25, 0.75 - s) * L, w)
    v = v * (1 - outer) + outer * CT_HU["cortex"]
    v += inner * (CT_HU["cancellous"] - CT_HU["cortex"]) + canal * (CT_HU["marrow"] - CT_HU["cancellous"])
    return v, outer >= 0.5


#: name → (function, keyword arguments) of the corpus bodies used by ``bench/bodies.py``
BODIES = {
    "femur": (femur, {}),
    "bunny": (bunny, {}),
    "blob-4k": (star_blob, {"triangles": 4000}),
    "blob-28k": (star_blob, {"triangles": 28000, "seed": 1}),
    "bone": (curved_bone, {"triangles": 8000}),
    "torus": (torus_body, {"triangles": 4000}),
    "limbs": (limbed_body, {"triangles": 8000}),
    "segmented": (segmented_body, {}),
    # issue 37: what users bring (porecad.corpus)
    "y-tube": (lambda: _corpus().branching_tube(), {}),
    "y-tube-thin": (lambda: _corpus().branching_tube(radius=1.0), {}),
    "plate-1cell": (lambda: _corpus().thin_plate(thickness=3.0), {}),
    "plate-2cell": (lambda: _corpus().thin_plate(thickness=6.0), {}),
    "bracket-2": (lambda: _corpus().holed_part(2), {}),
    "bracket-3": (lambda: _corpus().holed_part(3), {}),
    "bracket-6": (lambda: _corpus().holed_part(6), {}),
    "blob-inward": (lambda: _corpus().inward(star_blob(4000)), {}),
    "bracket-inward": (lambda: _corpus().inward(_corpus().holed_part(6)), {}),
    "blob-metres": (lambda: _corpus().scaled(star_blob(4000), 0.001), {}),
    "blob-micrometres": (lambda: _corpus().scaled(star_blob(4000, size=2.0), 1000.0), {}),
    "blob-open": (lambda: _corpus().open_surface(star_blob(4000)), {}),
}


def _corpus():
    from . import corpus
    return corpus


def body(name: str):
    """A corpus body by its name in :data:`BODIES`: ``(vertices, faces)``."""
    if name not in BODIES:
        raise InputError(f"unknown body {name!r}; use one of {', '.join(BODIES)}")
    fn, kw = BODIES[name]
    return fn(**kw)
