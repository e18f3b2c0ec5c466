"""Robust Boolean operations on closed meshes through manifold3d (Lalish et al.).

Used to cut scaffolds to their body: 002 §4 (the TIS network intersected with
the femur) and 004 §4 (the hex-mapped pore model and the solid model).
"""

from __future__ import annotations

from .decimate import from_manifold, to_manifold

__all__ = ["intersect"]


def intersect(va, fa, vb, fb):
    """``A ∩ B`` of two closed, manifold, outward-oriented meshes; returns ``(vertices, faces)``."""
    return from_manifold(to_manifold(va, fa) ^ to_manifold(vb, fb))
