"""The hex job's grid in a body: its nodes, and the volume they map.

:func:`hex_nodes` makes the node grid of ``cells`` hexahedra (hex8: corners;
hex20: with half-step nodes) in a frustum or a cylinder
(:mod:`porecad.maps.hexmesh`) or in a closed surface mesh, parameterised as a
deformed cube (:func:`porecad.param.hexcube.hex_parameterisation`);
:func:`mapped_volume` is the volume of the mapped parameter box.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import InputError
from .hexmesh import cylinder_nodes, frustum_nodes, map_params


@dataclasses.dataclass(frozen=True)
class HexBody:
    """A checked ``[body]``: a frustum or cylinder (a size not given: :func:`~porecad.maps.hexmesh.frustum_nodes`'
    or :func:`~porecad.maps.hexmesh.cylinder_nodes`' own), a closed surface (``mesh``) or a hex-mesh file."""

    kind: str
    path: str | None = None              # mesh, hexfile
    corners: list | None = None          # mesh: the 8 body vertex ids that become the corners
    untangle_limit: float | None = None  # mesh: seconds (0: none; None: the parameterisation's default)
    bottom: list | None = None           # frustum: bottom and top size (mm)
    top: list | None = None
    height: float | None = None          # frustum, cylinder
    radius: float | None = None          # cylinder

    def sizes(self, *names) -> dict:
        """The sizes among ``names`` that are given (keywords of the node generator)."""
        return {k: getattr(self, k) for k in names if getattr(self, k) is not None}


def hex_nodes(body: HexBody, cells, element, progress=None):
    """The node grid of the hex mesh (hex8: corners; hex20: half-step nodes), the body mesh or None, facts."""
    kind = body.kind
    t = time.perf_counter()
    if kind == "frustum":
        nodes = frustum_nodes(cells, element=element, **body.sizes("bottom", "top", "height"))
        return nodes, None, {"kind": kind, "time_s": time.perf_counter() - t}
    if kind == "cylinder":
        nodes = cylinder_nodes(cells, element=element, **body.sizes("radius", "height"))
        return nodes, None, {"kind": kind, "time_s": time.perf_counter() - t}
    if kind == "mesh":
        from ..bodies import load_body
        from ..param.hexcube import UNTANGLE_LIMIT, hex_parameterisation
        v, f, rep = load_body(body.path)
        limit = UNTANGLE_LIMIT if body.untangle_limit is None else body.untangle_limit
        try:
            nodes, info = hex_parameterisation(v, f, grid=cells, corners=body.corners, progress=progress,
                                               untangle_limit=limit or None, element=element)
        except InputError as err:  # the parameters it names are the recipe's [body] keys
            raise InputError(str(err).replace("`untangle_limit`", "`body.untangle_limit`")
                             .replace("`corners`", "`body.corners`")) from None
        facts = {"kind": "mesh", "path": str(body.path), "body_volume": float(rep["volume"]),
                 "parameterisation": info.report(),
                 "corners": [int(c) for c in info.corners], "time_s": time.perf_counter() - t}
        return nodes, (v, f), facts
    raise InputError(f"unknown hex body {kind!r}; use frustum, cylinder or a closed surface mesh")


def grid_volume(corners):
    """Volume of a structured hex mesh: its boundary quads split into triangles (divergence theorem)."""
    g = np.asarray(corners, dtype=np.float64)
    total = 0.0
    for a in range(3):
        for end, sign in ((0, -1.0), (-1, 1.0)):
            face = np.take(g, end, axis=a)  # (n1, n2, 3) in the order of the remaining axes
            p00, p10 = face[:-1, :-1], face[1:, :-1]
            p11, p01 = face[1:, 1:], face[:-1, 1:]
            # outward orientation: remaining axes (b, c) in cyclic order after a give +a normals
            s = sign if a != 1 else -sign
            tri = np.einsum("...i,...i->...", p00, np.cross(p10, p11)) + \
                np.einsum("...i,...i->...", p00, np.cross(p11, p01))
            total += s * tri.sum() / 6.0
    return total


def mapped_volume(nodes, element, cells, samples_per_cell: int = 8) -> float:
    """Volume of the mapped parameter box (curved for hex20), from its boundary at 8 samples per cell edge."""
    axes = [np.linspace(0.0, c, c * samples_per_cell + 1) for c in cells]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    X = map_params(nodes, P.reshape(-1, 3), element).reshape(P.shape)
    return float(grid_volume(X))
