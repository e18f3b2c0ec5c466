"""Layer bands on dask workers (``scheduler``): each band is one task that returns its layers' bytes.

A band task samples its layers and the one below it (for the pieces resting on nothing), so bands
are independent; the caller writes their results in order, keeping at most ``2 x workers + 1``
bands in flight (memory: that many bands' encoded layers).
"""

from __future__ import annotations

import numpy as np


def band_task(field, boxed: bool, grid, k0: int, k1: int, fmt: str, manifest: dict, polygons: bool) -> list:
    """``[(k, area, payload, islands)]`` of layers ``k0 .. k1-1`` of a field part."""
    from ._kernels import layer_grey, new_islands
    from .formats import encode
    from .raster import field_polygons, sample_layers
    lo = max(0, k0 - 1)
    vals = sample_layers(field, grid, lo, k1)
    weights = grid.box_weights() if boxed else np.ones((1, 1), dtype=np.float32)
    out, below = [], None
    for i, k in enumerate(range(lo, k1)):
        grey = np.empty((grid.ny, grid.nx), dtype=np.uint8)
        solid = np.empty((grid.ny, grid.nx), dtype=np.bool_)
        area = layer_grey(vals[i], grid.px, grid.py, weights, boxed, grey, solid)
        if k >= k0:
            geom = field_polygons(vals[i], grid, boxed) if polygons else None
            found = new_islands(solid, below) if below is not None else None
            out.append((k, area, encode(fmt, manifest, k, grey, geom), found))
        below = solid
    return out


def scheduled_layers(part, grid, fmt: str, manifest: dict, polygons: bool, scheduler):
    """Yield ``(k, area, payload, islands)`` in layer order from band tasks on ``scheduler``."""
    from collections import deque
    sched = scheduler.__enter__()
    try:
        band = grid.band_size()
        starts = list(range(0, grid.n_layers, band))
        window = 2 * max(1, getattr(sched, "workers", 1)) + 1
        pending = deque()
        for k0 in starts:
            pending.append(sched.submit(band_task, part.field, part.boxed, grid, k0, min(grid.n_layers, k0 + band),
                                        fmt, manifest, polygons))
            if len(pending) >= window:
                yield from pending.popleft().result()
        while pending:
            yield from pending.popleft().result()
    finally:
        scheduler.__exit__(None, None, None)
