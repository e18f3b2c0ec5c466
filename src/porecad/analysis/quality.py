"""Triangle quality of a surface mesh, in words a user can act on.

Marching cubes puts a vertex on every sample edge the surface crosses; where
the surface passes very close to a sample, three vertices nearly coincide
and the triangle is a *sliver*: an angle near 0°. Slivers do not matter for
printing (the slicer only needs a closed surface), but a volume mesh for FEA
built on them has badly shaped elements (stiffness matrices ill-conditioned,
stresses wrong at those elements): remesh or smooth the surface first
(e.g. ``--smooth taubin``, or a remesher such as pytetwild).

The angle bound for a sliver is 5° here — a common floor for FEA surface
meshes (TetGen refuses to improve below it by default; Shewchuk 2002,
"What is a good linear finite element?", relates the error to small angles).
"""

from __future__ import annotations

import numpy as np

#: a triangle with an angle below this is a sliver (degrees)
SLIVER_DEG = 5.0


def min_angles(vertices, faces, chunk: int = 1_000_000):
    """Smallest interior angle of each triangle (degrees; 0 for a degenerate one)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    out = np.empty(len(f))
    for a in range(0, len(f), chunk):
        p = v[f[a:a + chunk]]
        e = [p[:, (c + 2) % 3] - p[:, (c + 1) % 3] for c in range(3)]   # edge opposite corner c
        l2 = np.stack([(x * x).sum(axis=1) for x in e], axis=1)
        # law of cosines at each corner: cos A = (b² + c² − a²) / (2 b c)
        ang = np.empty_like(l2)
        for c in range(3):
            b2, c2 = l2[:, (c + 1) % 3], l2[:, (c + 2) % 3]
            with np.errstate(invalid="ignore", divide="ignore"):
                cos = (b2 + c2 - l2[:, c]) / (2.0 * np.sqrt(b2 * c2))
            ang[:, c] = np.degrees(np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1.0, 1.0)))
        out[a:a + chunk] = ang.min(axis=1)
    return out


def mesh_quality(vertices, faces, sliver_deg: float = SLIVER_DEG) -> dict:
    """Smallest angle, sliver count and share, and what they mean (``note``)."""
    m = min_angles(vertices, faces)
    n = int((m < sliver_deg).sum())
    share = n / max(len(m), 1)
    out = {"min_angle_deg": float(m.min()) if len(m) else None,
           "angle_p01_deg": float(np.percentile(m, 1)) if len(m) else None,
           "slivers": n, "sliver_fraction": float(share), "sliver_angle_deg": float(sliver_deg)}
    if n == 0:
        out["note"] = f"no triangle has an angle below {sliver_deg:g}°: fine for printing and for volume meshing"
    else:
        out["note"] = (f"{n} triangles ({100 * share:.2g} %) have an angle below {sliver_deg:g}° (slivers, where "
                       "marching cubes passes close to a sample): harmless for printing; for FEA smooth or "
                       "remesh the surface before volume meshing, or those elements will be badly shaped")
    return out
