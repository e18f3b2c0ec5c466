"""Skeleton marching (003 ch. 3, §3.2): overlapping local segments of a centreline graph.

Every branch (node chain between junctions and ends, see
:meth:`CentrelineGraph.branches`) is walked from its first node and a
*breakpoint* is set whenever the arc length since the previous breakpoint
reaches ``L`` or the accumulated turning angle (sum of the angles between
successive edge directions) reaches ``K``; the branch end is always a
breakpoint. With ``m`` breakpoints ``b_0 .. b_{m-1}`` the segments are the
spans ``[b_k, b_{k+2}]`` for ``k = 0 .. m-3`` (003 §3.2: "m breakpoints give
m − 2 overlapping segments"; a branch with two breakpoints is one segment),
so consecutive segments overlap by one interval. Each segment carries its
axis-aligned bounding box: the box of its balls ``B(p_i, r_i)`` grown by a
margin ``pad`` (the *truncated implicit function* of 003 §3.3 is its field
inside the box and a constant outside).

003 gives no values for ``L`` and ``K`` (notes §0); porecad's defaults are
``L = 4 × median radius`` of the branch and ``K = 45°``. A junction node has
one radius in the graph but belongs to several branches; each branch takes
the radius of its own next node there, so a thin child does not start with
the parent's radius and taper.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .graph import CentrelineGraph


@dataclass
class Segment:
    branch: int
    nodes: np.ndarray      # graph node ids along the segment
    points: np.ndarray     # (m, 3)
    radii: np.ndarray      # (m,)
    box_min: np.ndarray
    box_max: np.ndarray
    arc_length: float
    turning: float         # accumulated turning angle (rad) between its breakpoints


def breakpoints(points: np.ndarray, L: float, K: float) -> list[int]:
    """Breakpoint indices along one polyline (first and last included)."""
    seg = np.diff(points, axis=0)
    ln = np.linalg.norm(seg, axis=1)
    u = seg / ln[:, None]
    turn = np.zeros(len(points))
    if len(u) > 1:
        turn[1:-1] = np.arccos(np.clip(np.einsum("ij,ij->i", u[:-1], u[1:]), -1.0, 1.0))
    out = [0]
    acc_l, acc_k = 0.0, 0.0
    for i in range(1, len(points)):
        acc_l += ln[i - 1]
        if i < len(points) - 1:
            acc_k += turn[i]
        if i == len(points) - 1:
            out.append(i)
        elif acc_l >= L or acc_k >= K:
            out.append(i)
            acc_l, acc_k = 0.0, 0.0
    return out


def march(graph: CentrelineGraph, length: float | None = None, angle_deg: float = 45.0,
          pad: float = 0.0) -> list[Segment]:
    """Split every branch of ``graph`` into overlapping segments (module docstring)."""
    if length is not None and (not np.isfinite(length) or length <= 0):
        raise InputError(f"`segment_length` must be positive, got {length}")
    if not np.isfinite(angle_deg) or angle_deg <= 0:
        raise InputError(f"`segment_angle` must be positive, got {angle_deg}")
    K = np.deg2rad(angle_deg)
    out = []
    for b, chain in enumerate(graph.branches()):
        P = graph.points[chain]
        R = graph.radii[chain].copy()
        deg = graph.degrees()
        if len(chain) > 2:  # at a junction each branch keeps its own radius (its neighbour's)
            if deg[chain[0]] >= 3:
                R[0] = R[1]
            if deg[chain[-1]] >= 3:
                R[-1] = R[-2]
        L = float(length) if length is not None else 4.0 * float(np.median(R))
        bp = breakpoints(P, L, K)
        spans = [(bp[0], bp[-1])] if len(bp) <= 2 else [(bp[k], bp[k + 2]) for k in range(len(bp) - 2)]
        for a, e in spans:
            p, r = P[a:e + 1], R[a:e + 1]
            seg = np.diff(p, axis=0)
            ln = np.linalg.norm(seg, axis=1)
            u = seg / ln[:, None]
            turning = float(np.sum(np.arccos(np.clip(np.einsum("ij,ij->i", u[:-1], u[1:]), -1, 1)))) \
                if len(u) > 1 else 0.0
            out.append(Segment(branch=b, nodes=chain[a:e + 1], points=p, radii=r,
                               box_min=(p - r[:, None]).min(0) - pad, box_max=(p + r[:, None]).max(0) + pad,
                               arc_length=float(ln.sum()), turning=turning))
    return out
