"""Layers of a part as anti-aliased pixel images, from its field or from its mesh.

A :class:`LayerGrid` fixes the raster: pixel ``px`` (mm) in x and ``py`` in y
(a display's pixels need not be square), layer height ``h`` (mm) in z, pixel
centres at ``lo + (i + 1/2) p`` and layer ``k`` sampled at its middle,
``z_k = lo_z + (k + 1/2) h`` (the section a DLP/SLA printer cures for that layer).

From a field (negative inside) each layer is sampled at the pixel centres,
a band of layers at a time (memory: one band, whatever the part's size),
and a pixel's grey is the fraction of it inside the solid, from the
distance to the contour in the layer's plane ``d = f / |grad_xy f|``:
``clip(1/2 - d / p, 0, 1)`` (exact for a straight edge along a pixel
axis and unbiased for any other straight edge: the summed coverage of
the pixels along an edge equals the area under it). For a px x py pixel
the same holds in pixel units (the gradient per pixel step, ``f / |g|``):
a pixel's covered fraction does not change when x and y are scaled. Pixels that only
partly lie in the design box (a ``tpms`` box job, whose lattice is
unbounded) are scaled by the part of them inside.

From a mesh each layer is its exact polygon section (trimesh), filled at
4 x 4 sub-pixels (Pillow) and averaged.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..errors import InputError, ResourceError

#: the most pixels of one layer and layers of one part (a 1 m square at 25 µm is 1.6 G pixels)
MAX_LAYER_PIXELS = 400_000_000
MAX_LAYERS = 1_000_000
#: values of one band of layers (float32): the memory bound of the field route
BAND_BYTES = 24 << 20
SUPERSAMPLE = 4


def nm(mm) -> int:
    """A length in mm as whole nanometres (the unit every pixel, layer and z is exact in)."""
    return int(round(float(mm) * 1e6))


def mm_text(n: int, places: int = 6) -> str:
    """Whole nanometres ``n`` as exact decimal text in mm (``places`` 6) or µm (``places`` 3)."""
    sign, n = ("-" if n < 0 else ""), abs(int(n))
    whole, frac = divmod(n, 10 ** places)
    return f"{sign}{whole}.{frac:0{places}d}".rstrip("0").rstrip(".")


def check_size(name: str, value) -> float:
    """A pixel or layer size in mm: finite, positive, at least 0.1 µm and at most 10 mm, a whole number of nm."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number (mm), got {value!r}") from None
    if not (math.isfinite(v) and 1e-4 <= v <= 10.0):
        raise InputError(f"{name} must be between 0.0001 and 10 mm, got {value!r}")
    return nm(v) / 1e6


@dataclasses.dataclass(frozen=True)
class LayerGrid:
    """The raster of a part: ``lo`` (3,), pixel (x; ``pixel_y`` in y, 0: the same) and layer (mm), image
    ``(ny, nx)`` and layer count."""

    lo: tuple
    pixel: float
    layer: float
    nx: int
    ny: int
    n_layers: int
    box_hi: tuple  # the design box; pixels beyond it (last column/row) are partly outside
    pixel_y: float = 0.0

    @classmethod
    def around(cls, lo, hi, pixel: float, layer: float, pixel_y: float | None = None) -> "LayerGrid":
        lo = np.asarray(lo, dtype=float)
        hi = np.asarray(hi, dtype=float)
        ext = hi - lo
        if not (np.all(np.isfinite(ext)) and np.all(ext > 0)):
            raise InputError(f"the part has no extent to slice (bounds {lo.tolist()} .. {hi.tolist()})")
        py = pixel if pixel_y is None else pixel_y
        nx, ny = (max(1, math.ceil(e / p - 1e-9)) for e, p in zip(ext[:2], (pixel, py)))
        nz = max(1, round(ext[2] / layer))
        if nx * ny > MAX_LAYER_PIXELS or nz > MAX_LAYERS:
            raise ResourceError(f"the slices would be too large: {nx} x {ny} pixels x {nz} layers; use a larger "
                                "pixel or layer")
        return cls(tuple(lo), pixel, layer, int(nx), int(ny), int(nz), tuple(hi), 0.0 if py == pixel else py)

    @property
    def px(self) -> float:
        return self.pixel

    @property
    def py(self) -> float:
        return self.pixel_y or self.pixel

    @property
    def pixel_area(self) -> float:
        return self.px * self.py

    @property
    def xs(self) -> np.ndarray:
        return self.lo[0] + (np.arange(self.nx) + 0.5) * self.px

    @property
    def ys(self) -> np.ndarray:
        return self.lo[1] + (np.arange(self.ny) + 0.5) * self.py

    def z(self, k) -> np.ndarray:
        return self.lo[2] + (np.asarray(k) + 0.5) * self.layer

    @property
    def height(self) -> float:
        return self.n_layers * self.layer

    def band_size(self) -> int:
        """Layers per band: :data:`BAND_BYTES` of float32 values, at least one."""
        return int(max(1, min(self.n_layers, BAND_BYTES // (4 * self.nx * self.ny))))

    def box_weights(self) -> np.ndarray:
        """``(ny, nx)`` fraction of each pixel inside the design box in x and y."""
        wx = np.clip((self.box_hi[0] - (self.lo[0] + np.arange(self.nx) * self.px)) / self.px, 0, 1)
        wy = np.clip((self.box_hi[1] - (self.lo[1] + np.arange(self.ny) * self.py)) / self.py, 0, 1)
        return np.outer(wy, wx).astype(np.float32)

    def manifest(self) -> dict:
        return {"units": "mm", "pixel_size": self.px, "layer_height": self.layer, "pixel_size_nm": nm(self.px),
                "pixel_x": self.px, "pixel_y": self.py, "pixel_x_nm": nm(self.px), "pixel_y_nm": nm(self.py),
                "layer_height_nm": nm(self.layer), "image_width": self.nx,
                "image_height": self.ny, "layer_count": self.n_layers, "origin": [float(v) for v in self.lo],
                "first_layer_z": float(self.z(0)), "height": self.height,
                "image_rows": "row 0 is the largest y (images are viewed from above)"}


def coverage(values: np.ndarray) -> np.ndarray:
    """Fraction of each pixel inside (``values`` < 0) of a band ``(nb, ny, nx)`` of field samples, float32
    (the gradient per pixel step: any pixel, square or not)."""
    v = np.asarray(values, dtype=np.float32)
    gy, gx = np.gradient(v, axis=(1, 2)) if min(v.shape[1:]) > 1 else (np.zeros_like(v),) * 2
    g = np.sqrt(gx * gx + gy * gy)
    del gx, gy
    with np.errstate(divide="ignore", invalid="ignore"):
        cov = 0.5 - v / g
    flat = ~(g > 1e-12)
    cov[flat] = (v[flat] < 0).astype(np.float32)
    np.clip(cov, 0.0, 1.0, out=cov)
    return cov


def field_bands(field, grid: LayerGrid, boxed: bool = False, band: int | None = None):
    """Yield ``(k0, values, cover)`` per band of layers: field samples ``(nb, ny, nx)`` float32 and coverage."""
    band = band or grid.band_size()
    xs, ys = grid.xs, grid.ys
    weights = grid.box_weights() if boxed else None
    for k0 in range(0, grid.n_layers, band):
        k1 = min(grid.n_layers, k0 + band)
        vals = np.asarray(field.sample_grid(xs, ys, grid.z(np.arange(k0, k1))), dtype=np.float32)
        if not np.all(np.isfinite(vals)):
            vals = np.nan_to_num(vals, nan=1.0, posinf=1.0, neginf=-1.0)
        cov = coverage(vals)
        if weights is not None:
            cov *= weights
        yield k0, vals, cov


def to_grey(cover: np.ndarray) -> np.ndarray:
    """Coverage (0..1) to 8-bit grey, rows flipped so that row 0 is the largest y (the image seen from above)."""
    return np.rint(cover[..., ::-1, :] * 255.0).astype(np.uint8)


def mesh_sections(mesh, grid: LayerGrid, k0: int, k1: int):
    """Exact polygon sections of a trimesh at the layer middles ``k0 .. k1-1``: a list of shapely geometries."""
    from shapely.geometry import Polygon
    from shapely.ops import unary_union
    out = []
    zs = grid.z(np.arange(k0, k1))
    for z in zs:
        sec = mesh.section(plane_origin=[0.0, 0.0, float(z)], plane_normal=[0.0, 0.0, 1.0])
        if sec is None:
            out.append(Polygon())
            continue
        rings = [d[:, :2] for d in sec.discrete if len(d) >= 4]
        out.append(even_odd([Polygon(r) for r in rings]) if rings else unary_union([]))
    return out


def even_odd(polys):
    """The region inside an odd number of the given simple rings (nested rings: holes and islands)."""
    from shapely.geometry import MultiPolygon, Polygon
    from shapely.strtree import STRtree
    polys = [p if p.is_valid else p.buffer(0) for p in polys if p.area > 0]
    polys = [p for p in polys if isinstance(p, Polygon) and p.area > 0]
    if not polys:
        return Polygon()
    tree = STRtree(polys)
    depth = np.zeros(len(polys), dtype=int)
    for i, p in enumerate(polys):
        pt = p.representative_point()
        for j in tree.query(pt, predicate="within"):
            if j != i and polys[j].area > p.area:
                depth[i] += 1
    shells = [i for i in range(len(polys)) if depth[i] % 2 == 0]
    pieces = []
    for i in shells:
        holes = [polys[j].exterior.coords for j in tree.query(polys[i], predicate="contains")
                 if depth[j] == depth[i] + 1]
        pieces.append(Polygon(polys[i].exterior.coords, holes))
    return MultiPolygon(pieces) if len(pieces) > 1 else pieces[0]


def rasterise(geom, grid: LayerGrid, ss: int = SUPERSAMPLE) -> np.ndarray:
    """Coverage ``(ny, nx)`` float32 of a shapely (multi)polygon, filled at ``ss x ss`` sub-pixels."""
    from PIL import Image, ImageDraw
    img = Image.new("L", (grid.nx * ss, grid.ny * ss), 0)
    draw = ImageDraw.Draw(img)
    scale = np.array([ss / grid.px, ss / grid.py])

    def ring(coords):
        c = (np.asarray(coords)[:, :2] - np.asarray(grid.lo[:2])) * scale - 0.5
        return [tuple(p) for p in c]
    polys = sorted(getattr(geom, "geoms", [geom]), key=lambda g: -g.area)  # islands in holes after their holes
    for p in polys:
        if p.is_empty:
            continue
        draw.polygon(ring(p.exterior.coords), fill=255)
        for hole in p.interiors:
            draw.polygon(ring(hole.coords), fill=0)
    a = np.asarray(img, dtype=np.float32).reshape(grid.ny, ss, grid.nx, ss)
    return a.mean(axis=(1, 3)) / 255.0


def field_polygons(values: np.ndarray, grid: LayerGrid, boxed: bool):
    """The layer's solid as shapely polygons: the field's zero contour (sub-pixel), cut to the part's box."""
    from shapely.geometry import Polygon, box
    from skimage.measure import find_contours

    from .raster import even_odd
    v = np.pad(np.asarray(values, dtype=np.float64), 1, constant_values=1e-6)
    rings = []
    for c in find_contours(v, 0.0):
        if len(c) >= 4:
            xy = np.column_stack([grid.lo[0] + (c[:, 1] - 0.5) * grid.px, grid.lo[1] + (c[:, 0] - 0.5) * grid.py])
            rings.append(Polygon(xy))
    geom = even_odd(rings)
    if not geom.is_empty:  # the part lies in its box: a solid reaching the raster's edge ends there, not beyond
        geom = geom.intersection(box(grid.lo[0], grid.lo[1], grid.box_hi[0], grid.box_hi[1]))
    return geom


def sample_layers(field, grid: LayerGrid, k0: int, k1: int) -> np.ndarray:
    """The field on layers ``k0 .. k1 - 1`` of ``grid`` (float32, non-finite values clamped to ±1)."""
    vals = np.asarray(field.sample_grid(grid.xs, grid.ys, grid.z(np.arange(k0, k1))), dtype=np.float32)
    if not np.all(np.isfinite(vals)):
        vals = np.nan_to_num(vals, nan=1.0, posinf=1.0, neginf=-1.0)
    return vals
