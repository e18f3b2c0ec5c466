"""Primitive bodies as (approximate) signed distance fields, negative inside.

Includes the bundled analytic lumbar-disc body used by ``porecad demo``: a
kidney-shaped elliptic slab (the transverse outline of a lumbar
intervertebral disc: about 45 mm wide, 32 mm deep, with a posterior
concavity towards the spinal canal) of about 10 mm height (000 ch.1: the
lumbar disc is the thickest, about 9 mm) with rounded rims.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .base import Field


def _positive(name, value):
    v = np.asarray(value, dtype=float)
    if np.any(~np.isfinite(v)) or np.any(v <= 0):
        raise InputError(f"{name} must be positive, got {value}")
    return v


class Box(Field):
    """Axis-aligned box ``[lo, hi]`` (exact signed distance)."""

    def __init__(self, lo, hi):
        self.lo = np.asarray(lo, dtype=float)
        self.hi = np.asarray(hi, dtype=float)
        _positive("box size", self.hi - self.lo)

    @property
    def bounds(self):
        return self.lo.copy(), self.hi.copy()

    def evaluate(self, p):
        c = 0.5 * (self.lo + self.hi)
        h = 0.5 * (self.hi - self.lo)
        q = np.abs(p - c) - h
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        return outside + inside


class Sphere(Field):
    """Ball of radius ``r`` about ``centre`` (exact)."""

    def __init__(self, centre=(0, 0, 0), radius=1.0):
        self.c = np.asarray(centre, dtype=float)
        self.r = float(_positive("radius", radius))

    @property
    def bounds(self):
        return self.c - self.r, self.c + self.r

    def evaluate(self, p):
        return np.linalg.norm(p - self.c, axis=1) - self.r


class LumbarDisc(Field):
    """Analytic lumbar intervertebral disc (kidney-shaped slab), centred at the origin.

    The outline is an ellipse (semi-axes ``a`` along x, ``b`` along y) minus
    a posterior circular notch of radius ``notch`` whose centre lies
    ``notch + b - notch_depth`` behind the centre; the slab is ``height`` mm
    thick with rims rounded by ``rim`` mm. The field is an approximate
    distance (exact near the flat faces, first-order elsewhere).
    """

    def __init__(self, a=22.5, b=16.0, height=10.0, notch=9.0, notch_depth=5.0, rim=2.0):
        self.a, self.b = float(_positive("a", a)), float(_positive("b", b))
        self.h = float(_positive("height", height))
        self.notch = float(_positive("notch", notch))
        self.notch_depth = float(notch_depth)
        self.rim = float(min(rim, 0.49 * self.h))

    @property
    def bounds(self):
        return (np.array([-self.a, -self.b, -0.5 * self.h]), np.array([self.a, self.b, 0.5 * self.h]))

    def evaluate(self, p):
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        # first-order distance to the ellipse: (|q| - 1) / |grad|q||
        qx, qy = x / self.a, y / self.b
        rq = np.sqrt(qx * qx + qy * qy)
        grad = np.sqrt((qx / self.a) ** 2 + (qy / self.b) ** 2) / np.maximum(rq, 1e-12)
        d_ell = (rq - 1.0) / np.maximum(grad, 1e-12)
        cy = -(self.b - self.notch_depth + self.notch)
        d_notch = self.notch - np.hypot(x, y - cy)
        d2 = np.maximum(d_ell, d_notch)
        # round the rims: 2-D rounded-box distance in (d2, z)
        r = self.rim
        dx = d2 + r
        dz = np.abs(z) - 0.5 * self.h + r
        return (np.minimum(np.maximum(dx, dz), 0.0)
                + np.hypot(np.maximum(dx, 0.0), np.maximum(dz, 0.0)) - r)
