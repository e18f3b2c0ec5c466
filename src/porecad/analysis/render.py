"""Software rendering of a triangle mesh for the report's preview (numpy, no GPU or display).

A z-buffer rasteriser (Catmull 1974): each triangle's pixels are found by
edge functions over its bounding box (Pineda 1988), its depth and vertex
normal interpolated barycentrically, the nearest fragment per pixel kept
(:func:`porecad.analysis._render_kernel.rasterise`).
Lambert shading with a key light from the upper left, a depth cue so that
the near lattice stands out from the far, 2× supersampling.

A cut-away removes the half of the part in front of a plane per pixel
(the fragment's interpolated distance to the plane), so the inside shows;
where the eye then looks into the solid it sees the back of a face, which
is painted in a flat section colour — the cut material, as on a drawing.
"""

from __future__ import annotations

import numpy as np

from ..mesh.arrays import scatter_sum

PART = np.array([0.70, 0.77, 0.90])
SECTION = np.array([0.86, 0.38, 0.30])


def camera(direction=(0.55, -1.0, 0.8)):
    """``(view, right, up)``: the view direction (from the eye into the scene) and the screen axes (z up)."""
    d = -np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    right = np.cross(d, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    return d, right, np.cross(right, d)


def vertex_normals(v, f):
    """Area-weighted vertex normals (unit; zero where no face meets)."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = sum(scatter_sum(f[:, k], fn, len(v)) for k in range(3))
    return n / np.maximum(np.linalg.norm(n, axis=1), 1e-30)[:, None]


def render(vertices, faces, width: int = 640, height: int = 480, direction=(0.55, -1.0, 0.8), cut=None,
           supersample: int = 2):
    """An RGB image ``(height, width, 3)`` in [0, 1] of the mesh seen along ``direction`` (orthographic).

    Parameters
    ----------
    vertices, faces : arrays
        The surface (outward triangles; a decimated copy is plenty).
    width, height : int
        Image size in pixels (the part is fitted with a margin).
    direction : 3 floats
        From the part towards the eye.
    cut : (point, normal), optional
        Removes the part on the ``normal`` side of the plane through ``point``.
    supersample : int
        Rendered at this multiple of the size and averaged down (anti-aliasing).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d, right, up = camera(direction)
    W, H = int(width) * supersample, int(height) * supersample
    sx, sy, z = v @ right, v @ up, v @ d
    side = np.zeros(len(v)) if cut is None else (v - np.asarray(cut[0], float)) @ np.asarray(cut[1], float)
    kept = side <= 0 if np.any(side <= 0) else np.ones(len(v), bool)  # framed on what stays
    fx, fy = sx[kept], sy[kept]
    margin = 0.04 * max(W, H)
    scale = min((W - 2 * margin) / max(np.ptp(fx), 1e-12), (H - 2 * margin) / max(np.ptp(fy), 1e-12))
    px = (sx - 0.5 * (fx.min() + fx.max())) * scale + 0.5 * W
    py = (0.5 * (fy.min() + fy.max()) - sy) * scale + 0.5 * H
    if cut is not None:  # faces wholly in the removed half never show
        f = f[~np.all(side[f] > 0, axis=1)]
    nrm = vertex_normals(v, f)
    face_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    back = face_n @ d > 0
    zbuf = np.full(W * H, np.inf)
    shade = np.zeros(W * H)
    section = np.zeros(W * H, bool)
    light = -d + 0.6 * up - 0.4 * right
    light /= np.linalg.norm(light)
    z_lo, z_span = z.min(), max(np.ptp(z), 1e-12)

    from ._render_kernel import rasterise
    rasterise(np.ascontiguousarray(px), np.ascontiguousarray(py), np.ascontiguousarray(z),
              np.ascontiguousarray(side, dtype=np.float64), np.ascontiguousarray(f), np.ascontiguousarray(nrm),
              np.ascontiguousarray(back), np.ascontiguousarray(light), W, H, cut is not None, float(z_lo),
              float(z_span), zbuf, shade, section)
    img = np.ones((W * H, 3))
    hit = np.isfinite(zbuf)
    part = hit & ~section
    img[part] = np.clip(shade[part, None] * PART[None, :] * 1.15, 0, 1)
    sec = hit & section
    img[sec] = SECTION * (0.75 + 0.25 * (1.0 - 0.45 * (zbuf[sec, None] - z_lo) / z_span))
    img = img.reshape(H, W, 3)
    if supersample > 1:
        img = img.reshape(H // supersample, supersample, W // supersample, supersample, 3).mean(axis=(1, 3))
    return img
