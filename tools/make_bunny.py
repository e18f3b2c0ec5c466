"""Convert the npm package ``bunny`` (1.0.1, public domain) into ``src/porecad/data/bunny.npz``.

Usage (once; the converted copy is committed)::

    npm pack bunny && tar xzf bunny-1.0.1.tgz
    python tools/make_bunny.py package/index.js

``index.js`` holds two JSON arrays (``exports.positions=[...]``,
``exports.cells=[...]``); they are parsed as JSON (never evaluated). The mesh
is checked closed, manifold, outward and free of self-intersections; open
boundary loops, if any, would be closed by a fan around their centroid (the
1.0.1 low-resolution bunny has none: its base was closed by its author).
Vertices are scaled by 15 so that the bunny is about 150 mm long, the size of
the Stanford original (the package's units are arbitrary).
"""

import json
import re
import sys

import numpy as np

from porecad.errors import InputError
from porecad.mesh.validate import check_solid

SCALE = 15.0


def parse(path):
    text = open(path, encoding="utf-8").read()
    out = {}
    for name in ("positions", "cells"):
        m = re.search(r"exports\." + name + r"\s*=\s*(\[.*?\]\])", text, re.S)
        if m is None:
            raise InputError(f"{path}: no exports.{name}")
        out[name] = json.loads(m.group(1))
    return np.asarray(out["positions"], np.float64), np.asarray(out["cells"], np.int64)


def close_holes(v, f):
    """Close each boundary loop by a fan around its centroid (a new vertex)."""
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = {tuple(x) for x in e.tolist()}
    nxt = {a: b for a, b in e.tolist() if (b, a) not in key}  # boundary half-edges, reversed to close
    v, new = list(v), []
    while nxt:
        a0 = next(iter(nxt))
        loop = [a0]
        while nxt[loop[-1]] != a0:
            loop.append(nxt[loop[-1]])
        for a in loop:
            del nxt[a]
        c = len(v)
        v.append(np.mean([v[a] for a in loop], axis=0))
        new += [(b, a, c) for a, b in zip(loop, loop[1:] + loop[:1])]
    return np.asarray(v), (np.concatenate([f, np.asarray(new, np.int64)]) if new else f), len(new)


def main(src, dst="src/porecad/data/bunny.npz"):
    v, f = parse(src)
    v, f, added = close_holes(v, f)
    v = v * SCALE
    chk = check_solid(v, f, check_self_intersections=True)
    if not (chk["closed"] and chk["manifold"] and chk["self_intersections"] == 0):
        raise SystemExit(f"the bunny is not a clean solid: {chk}")
    if not chk["outward"]:
        f = f[:, ::-1].copy()
    lo = v.min(axis=0)
    scale = (v.max(axis=0) - lo) / 65535.0
    q = np.rint((v - lo) / scale).astype(np.uint16)
    np.savez_compressed(dst, vertices=q, faces=f.astype(np.int32), lo=lo, scale=scale)
    print(f"{len(v)} vertices, {len(f)} faces ({added} fill triangles), volume {chk['volume']:.1f} mm3 -> {dst}")


if __name__ == "__main__":
    main(*sys.argv[1:])
