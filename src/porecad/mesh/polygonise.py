"""Chunked, watertight polygonisation of a scalar field on a regular grid.

Pipeline stage *polygonise* (``../DESIGN.md``): the field is sampled slab by
slab (z-chunks that share one plane with their neighbour), each slab is meshed
by marching cubes on a worker thread (the numba kernel releases the GIL), and
the slabs are welded exactly by the ids of the vertices on their shared plane
(no position tolerance). With ``caps=True`` the solid ``{f < 0}`` is closed
against the faces of the sampling box by marching squares with the same face
rule as the cube table (document 001, section 3.1: the "outside triangles" of
the boundary faces close a volume TPMS structure), so the output is a closed,
2-manifold, outward-oriented mesh.

Memory is bounded by the slab: at most ``2 * threads`` slabs of
``chunk_bytes`` samples are alive at a time; only the mesh accumulates.
The workers mesh into a few pooled buffers and the calling thread welds
each slab straight into the output arrays, sized once from the first slab
(no copy per slab, no joining of parts at the end).
The slab loop (:func:`slab_job`, :func:`mesh_chunk`, :func:`welded_slabs`) is
shared with :mod:`porecad.scale`, which runs it on dask and streams the mesh
to disk instead of accumulating it.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field as dc_field

import numpy as np

from ..errors import ResourceError
from .grid import Grid

from ._mc_kernel import mesh_slab

#: degeneracy guard, relative to the field's scale: samples with |f| < eta become +eta, so no
#: vertex sits on a grid point (the face rule stays consistent between neighbours).
ETA_REL = 1e-5


@dataclass
class PolygoniseResult:
    """Output of :func:`polygonise`: the mesh and what was learnt on the way."""

    vertices: np.ndarray
    faces: np.ndarray
    grid: Grid
    inside_fraction: float  # trapezoid-weighted fraction of samples with f < 0
    stats: dict = dc_field(default_factory=dict)


class GridArraySampler:
    """``sample_grid`` over a precomputed array on a :class:`~porecad.mesh.polygonise.Grid` (for polygonise)."""

    def __init__(self, F: np.ndarray, grid):
        self.F, self.grid = F, grid

    def _idx(self, vals, a):
        return np.rint((np.asarray(vals) - self.grid.origin[a]) / self.grid.spacing[a]).astype(np.int64)

    def __call__(self, xs, ys, zs):
        ix, iy, iz = self._idx(xs, 0), self._idx(ys, 1), self._idx(zs, 2)
        if len(ix) == self.F.shape[2] and len(iy) == self.F.shape[1] and len(iz) and \
                np.all(np.diff(iz) == 1):
            return self.F[iz[0]:iz[-1] + 1]
        return self.F[np.ix_(iz, iy, ix)]


def _trapezoid_weights(n: int) -> np.ndarray:
    w = np.ones(n, dtype=np.float64)
    w[0] = w[-1] = 0.5
    return w


def slab_ranges(nz: int, planes_per_slab: int) -> list[tuple[int, int]]:
    """Plane ranges ``[a, b]`` (inclusive) covering ``0 .. nz-1``; neighbours share a plane."""
    step = max(1, planes_per_slab - 1)
    out = []
    a = 0
    while a < nz - 1:
        b = min(a + step, nz - 1)
        out.append((a, b))
        a = b
    return out


def _weld_table(bottom, prev_top_ids, offset, n_local, dtype=np.int64):
    """The renumbering of a slab's local vertex ids to global ones, welding its first plane.

    The slab's first-plane vertices (``bottom = (keys, ids, nv_head, nf_head)``,
    local ids sorted by grid key, all below ``nv_head``) are the previous
    slab's last-plane vertices (``prev_top_ids``, global ids in the same key
    order, or None for the first slab); all others get ids ``offset, offset + 1,
    ...`` in order. Vertices from ``nv_head`` on are only shifted (by the
    returned ``shift``), and faces from ``nf_head`` on use only them.
    Returns the table (local -> global ids), the mask of the first ``nv_head``
    vertices to keep, ``shift`` and the number of vertices kept. (numpy: a
    kernel cost 0.8 s to compile on a first run.)
    """
    b_ids, nv_head = bottom[1], bottom[2]
    if prev_top_ids is None:
        b_ids = b_ids[:0]
    shift = offset - len(b_ids)
    remap = np.arange(shift, shift + n_local, dtype=dtype)
    keep = np.ones(nv_head, np.bool_)
    keep[b_ids] = False
    remap[:nv_head][keep] = np.arange(offset, offset + nv_head - len(b_ids), dtype=dtype)
    if prev_top_ids is not None:
        remap[b_ids] = prev_top_ids
    return remap, keep, shift, n_local - len(b_ids)


def _weld_slab(faces, bottom, prev_top_ids, offset, n_local):
    """Renumber a slab's faces in place to global vertex ids, welding its first plane (:func:`_weld_table`).

    Only the head ``faces[:nf_head]`` goes through the table; the rest are
    shifted. Returns the table, the mask of the first ``nv_head`` vertices to
    keep and the number of vertices kept.
    """
    nf_head = bottom[3]
    remap, keep, shift, n_new = _weld_table(bottom, prev_top_ids, offset, n_local)
    faces[:nf_head] = remap[faces[:nf_head]]
    if shift:
        faces[nf_head:] += shift
    return remap, keep, n_new


def load_kernels() -> None:
    """Load the marching-cubes kernel now (from numba's cache, or compile it) on a tiny slab of the
    types :func:`mesh_chunk` passes: a fresh process's first :func:`polygonise` otherwise pays that
    (about 20 ms from the cache) inside its own time. Calling it is optional."""
    w = np.array([0.5, 0.5])
    mesh_slab(np.ones((2, 2, 2), np.float32), 0, np.zeros(3), np.ones(3), np.zeros(6, bool), w.copy(), w, w,
              16, ETA_REL)


def default_threads() -> int:
    return max(1, min(os.cpu_count() or 1, 8))


@dataclass(frozen=True)
class SlabJob:
    """Everything a worker needs to sample and mesh any slab of a grid (picklable).

    Built once by :func:`slab_job`; :func:`mesh_chunk` turns ``(job, idx)`` into
    the slab's local mesh. Shipping the job to a process or a remote worker
    needs ``sample_slab`` to pickle (the TPMS fields do).
    """

    sample_slab: object
    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray
    ranges: tuple
    cap6: tuple
    origin: np.ndarray
    spacing: np.ndarray
    wx: np.ndarray
    wy: np.ndarray
    wz: np.ndarray
    eta: float
    planes: int
    zarr_path: str | None = None

    @property
    def n_slabs(self) -> int:
        return len(self.ranges)


def slab_job(sample_slab, grid: Grid, caps=True, chunk_bytes: int = 16 << 20, zarr_path=None) -> SlabJob:
    """Plan the slabs of ``grid`` and fix the degeneracy guard (one probe of the field)."""
    nx, ny, nz = grid.shape
    cap6 = tuple(bool(c) for c in np.broadcast_to(np.asarray(caps, dtype=bool), (6,)))
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    plane_bytes = nx * ny * 4
    planes = int(max(2, min(nz, chunk_bytes // max(plane_bytes, 1))))
    # degeneracy guard, global so that slabs agree on shared planes
    probe = np.asarray(sample_slab(xs[:: max(1, nx // 16)], ys[:: max(1, ny // 16)],
                                   zs[:: max(1, nz // 16)]), dtype=np.float64)
    scale = float(np.max(np.abs(probe))) if probe.size else 1.0
    eta = ETA_REL * (scale if np.isfinite(scale) and scale > 0 else 1.0)
    return SlabJob(sample_slab=sample_slab, xs=xs, ys=ys, zs=zs, ranges=tuple(slab_ranges(nz, planes)),
                   cap6=cap6, origin=np.asarray(grid.origin, dtype=np.float64),
                   spacing=np.asarray(grid.spacing, dtype=np.float64), wx=_trapezoid_weights(nx),
                   wy=_trapezoid_weights(ny), wz=_trapezoid_weights(nz), eta=eta, planes=planes,
                   zarr_path=None if zarr_path is None else str(zarr_path))


def sample_chunk(job: SlabJob, idx: int) -> np.ndarray:
    """The samples of slab ``idx``: ``(b - a + 1, ny, nx)`` float32, C-contiguous."""
    a, b = job.ranges[idx]
    ny, nx = len(job.ys), len(job.xs)
    F = np.ascontiguousarray(job.sample_slab(job.xs, job.ys, job.zs[a:b + 1]), dtype=np.float32)
    if F.shape != (b - a + 1, ny, nx):
        raise ValueError(f"sample_slab returned shape {F.shape}, expected {(b - a + 1, ny, nx)}")
    return F


def mesh_chunk(job: SlabJob, idx: int, est_tris: int | None = None, times: list | None = None, out=None):
    """Sample and mesh slab ``idx`` (runs on a worker thread or process).

    Returns ``(verts, faces, bottom, top, inside_weight)`` as
    :func:`porecad.mesh._mc_kernel.mesh_slab` (local vertex ids; ``bottom``
    and ``top`` are the seam planes' ``(keys, ids)``, ``bottom`` with the
    sizes of the slab's head after them). With
    ``job.zarr_path`` the samples are also stored there (see
    :mod:`porecad.io.zarr_field`). With ``times`` (a list) appends this
    thread's CPU seconds ``(sampling, meshing)``. With ``out`` (a list
    ``[verts, faces]`` of buffers, see :func:`~porecad.mesh._mc_kernel.mesh_slab`)
    the slab is meshed into those and ``verts``, ``faces`` are views of them.
    """
    a, b = job.ranges[idx]
    nz, ny, nx = len(job.zs), len(job.ys), len(job.xs)
    t0 = time.thread_time()
    F = sample_chunk(job, idx)
    if job.zarr_path is not None:
        from ..io.zarr_field import store_slab
        store_slab(job.zarr_path, F, a, b, nz)
    wz = job.wz[a:b + 1].copy()
    if b != nz - 1:
        wz[-1] = 0.0  # counted by the next slab
    c = job.cap6
    cap = np.array([c[0], c[1], c[2], c[3], c[4] and a == 0, c[5] and b == nz - 1])
    if est_tris is None:
        est_tris = int(8 * (nx + ny)) * (b - a)
    t1 = time.thread_time()
    res = mesh_slab(F, a, job.origin, job.spacing, cap, wz, job.wy, job.wx, est_tris, job.eta, out)
    if times is not None:
        times.append((t1 - t0, time.thread_time() - t1))
    return res


@dataclass
class WeldedSlab:
    """One slab after welding: new vertices and faces in global ids.

    ``faces`` index the whole mesh; the slab's own vertices have the ids
    ``offset .. offset + len(vertices) - 1``; faces may also use the previous
    slab's last-plane vertices (never older ones).
    """

    index: int
    vertices: np.ndarray
    faces: np.ndarray
    offset: int
    inside_weight: float
    top_ids: np.ndarray  # global ids of the vertices on the slab's last plane (in grid-key order)


def welded_slabs(job: SlabJob, submit, window: int, progress=None):
    """Run the slabs of ``job`` through ``submit`` and yield them welded, in order.

    Parameters
    ----------
    job : SlabJob
    submit : callable
        ``submit(idx, est_tris) -> future`` with ``future.result()`` giving
        :func:`mesh_chunk`'s tuple (a thread pool, a dask client, ...).
    window : int
        Slabs in flight at most: bounds memory.
    progress : callable, optional
        ``progress(done, total)`` after each slab.

    Yields
    ------
    WeldedSlab
        In slab order. Welding is exact: the vertices on a shared plane are
        matched by their grid edge, never by position.
    """
    n_verts = 0
    prev_top = None
    for idx, (v, f, bottom, top, w) in _in_order(job, submit, window):
        if n_verts + len(v) >= 2**31:
            raise ResourceError("the mesh would have more than 2**31 vertices; use a coarser grid")
        remap, keep, n_new = _weld_slab(f, bottom, prev_top, n_verts, len(v))
        if n_new < len(v):   # drop the first plane's vertices: the kept head moves up to the rest
            nb = len(v) - n_new
            v[nb:len(keep)] = v[:len(keep)][keep]
            v = v[nb:]
        prev_top = remap[top[1]]
        yield WeldedSlab(idx, v, f, n_verts, w, prev_top)
        n_verts += n_new
        if progress is not None:
            progress(idx + 1, job.n_slabs)


def _in_order(job: SlabJob, submit, window: int):
    """``(idx, result)`` of every slab in order, ``window`` slabs in flight (see :func:`welded_slabs`).

    Checks that each slab's first plane has the vertices of the previous one's last plane.
    """
    n = job.n_slabs
    nx, ny = len(job.xs), len(job.ys)
    est_per_plane = int(8 * (nx + ny))
    prev_keys = None
    pending = {}
    nxt = 0
    try:
        for idx in range(n):
            while nxt < n and nxt < idx + max(1, window):
                a, b = job.ranges[nxt]
                pending[nxt] = submit(nxt, est_per_plane * (b - a))
                nxt += 1
            res = pending.pop(idx).result()
            f, bottom, top = res[1], res[2], res[3]
            # later slabs start with room for what this one produced per plane
            a, b = job.ranges[idx]
            est_per_plane = max(est_per_plane, int(1.1 * len(f) / max(1, b - a)) + 64)
            if prev_keys is not None and not np.array_equal(bottom[0], prev_keys):
                raise RuntimeError("slab seam mismatch: field sampling is not deterministic")
            prev_keys = top[0]
            yield idx, res
    finally:
        for fut in pending.values():
            cancel = getattr(fut, "cancel", None)
            if cancel is not None:
                cancel()


class _Buffers:
    """Mesh buffers ``[verts, faces]`` lent to the worker threads: a slab is meshed into one, and it is given
    back once the slab is joined, so a few buffers (warm pages) serve all slabs, with no copy per slab."""

    def __init__(self):
        self._free, self._lock = [], threading.Lock()

    def take(self) -> list:
        with self._lock:
            return self._free.pop() if self._free else [None, None]

    def give(self, bufs: list) -> None:
        with self._lock:
            self._free.append(bufs)


def _pooled_chunk(job, idx, est, times, buffers):
    bufs = buffers.take()
    return mesh_chunk(job, idx, est, times, out=bufs) + (bufs,)


class _Joined:
    """The welded mesh, filled in place slab by slab: one block of ``rows`` sized up front from the first
    slab (the untouched end of a generous size costs address space, not memory) and cut to size at the end;
    a further block only when the estimate falls short (then joined by one copy)."""

    def __init__(self, width: int, dtype):
        self.width, self.dtype = width, dtype
        self.blocks, self.n, self.room = [], 0, 0   # room: rows left in the last block

    def take(self, rows: int, est_rest: int) -> np.ndarray:
        """The next ``rows`` rows to fill (room for ``est_rest`` more later when a block is made)."""
        if rows > self.room or not self.blocks:
            if self.blocks:   # the last block ends where it was filled
                blk, used = self.blocks[-1]
                self.blocks[-1] = (blk, len(blk) - self.room)
            size = rows + int(min(max(0, est_rest), 2**32))
            try:
                blk = np.empty((size, self.width), self.dtype)
            except MemoryError:   # an address space too small for the estimate: room for this slab, twice
                size = 2 * rows
                blk = np.empty((size, self.width), self.dtype)
            self.blocks.append((blk, 0))
            self.room = size
        blk, _ = self.blocks[-1]
        start = len(blk) - self.room
        self.room -= rows
        self.n += rows
        return blk[start:start + rows]

    def result(self) -> np.ndarray:
        if not self.blocks:
            return np.zeros((0, self.width), self.dtype)
        self.blocks[-1] = (self.blocks[-1][0], len(self.blocks[-1][0]) - self.room)
        if len(self.blocks) > 1:
            return np.concatenate([blk[:used] for blk, used in self.blocks])
        blk, used = self.blocks[0]
        self.blocks = []
        try:   # shrink in place (realloc: no copy of a large block)
            blk.resize((used, self.width), refcheck=False)
            return blk
        except ValueError:
            return blk[:used].copy()


#: the first slab's rate of triangles per layer is extrapolated to the whole grid times this (its layers
#: may be the sparsest: 1.8 times too few for the P surface at 500^3)
_EST_MARGIN = 3.0


def _join_slab(V, Fo, v, f, bottom, remap, keep, shift, n_new, est):
    """Write a slab's vertices and welded faces into the joined mesh ``V``, ``Fo`` (numpy, in place)."""
    nv_head, nf_head = bottom[2], bottom[3]
    est_v, est_f = est
    dst = V.take(n_new, est_v)
    k = n_new - (len(v) - nv_head)          # kept head vertices
    if k == nv_head:
        dst[:] = v
    else:
        np.compress(keep, v[:nv_head], axis=0, out=dst[:k])
        dst[k:] = v[nv_head:]
    dst = Fo.take(len(f), est_f)
    np.take(remap, f[:nf_head], out=dst[:nf_head], mode="clip")   # indices in range: clip does not buffer
    if shift:
        np.add(f[nf_head:], shift, out=dst[nf_head:], casting="unsafe")
    else:
        dst[nf_head:] = f[nf_head:]


def total_weight(job: SlabJob) -> float:
    """Sum of the trapezoid weights of all samples (the denominator of the inside fraction)."""
    return float(job.wz.sum() * job.wy.sum() * job.wx.sum())


def polygonise(sample_slab, grid: Grid, caps: bool = True, chunk_bytes: int = 16 << 20,
               threads: int | None = None, progress=None) -> PolygoniseResult:
    """Extract the surface ``f = 0`` of a field sampled on ``grid``.

    Parameters
    ----------
    sample_slab : callable
        ``sample_slab(xs, ys, zs) -> (len(zs), len(ys), len(xs)) float32``:
        field values (negative inside) on the tensor grid of the given axes.
        Usually ``field.sample_grid``.
    grid : Grid
        Sampling grid; marching cubes runs over its cells.
    caps : bool or (6,) bool
        Close the solid ``{f < 0}`` on the six faces of the grid box (or on
        the faces x0, x1, y0, y1, z0, z1 given as True). Without caps the open
        level set is returned (``structure="surface"``).
    chunk_bytes : int
        Target size of one slab of float32 samples; bounds memory.
    threads : int, optional
        Worker threads (default: the number of cores, at most 8).
    progress : callable, optional
        ``progress(done, total)`` called after each slab.

    Returns
    -------
    PolygoniseResult
        Vertices (float64), faces (int32, outward oriented), the weighted
        inside fraction of the samples (trapezoid rule: exact for periodic
        fields sampled over whole periods) and statistics.

    See Also
    --------
    porecad.scale.run_chunks : the same slabs on dask, streamed to a file.
    """
    job = slab_job(sample_slab, grid, caps, chunk_bytes)
    threads = default_threads() if threads is None else max(1, int(threads))
    times, buffers = [], _Buffers()
    V, Fo = _Joined(3, np.float64), _Joined(3, np.int32)
    inside_w = 0.0
    n_verts = 0
    prev_top = None
    layers = len(job.zs) - 1
    main_cpu = time.thread_time()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        def submit(idx, est):
            return pool.submit(_pooled_chunk, job, idx, est, times, buffers)

        for idx, (v, f, bottom, top, w, bufs) in _in_order(job, submit, 2 * threads):
            if n_verts + len(v) >= 2**31:
                raise ResourceError("the mesh would have more than 2**31 vertices; use a coarser grid")
            a, b = job.ranges[idx]
            # room for the rest at this slab's rate per layer, past its first two layers (the z0 cap's)
            # or, with fewer layers, not from a slab with that cap (a later block is sized)
            nh = bottom[3] if b - a > 2 else 0
            rest = (layers - b) * _EST_MARGIN / max(1, b - a - (2 if nh else 0))
            if not nh and a == 0 and job.cap6[4]:
                rest = 0.0
            est = (int(rest * len(v)) + 1024, int(rest * (len(f) - nh)) + 1024)
            remap, keep, shift, n_new = _weld_table(bottom, prev_top, n_verts, len(v), np.int32)
            _join_slab(V, Fo, v, f, bottom, remap, keep, shift, n_new, est)
            prev_top = remap[top[1]]
            buffers.give(bufs)
            inside_w += w
            n_verts += n_new
            if progress is not None:
                progress(idx + 1, job.n_slabs)
    vertices, faces = V.result(), Fo.result()
    # CPU seconds: sampling and marching (worker threads), welding and joining (this thread)
    cpu = {"sample_cpu_s": float(sum(t[0] for t in times)), "mesh_cpu_s": float(sum(t[1] for t in times)),
           "weld_cpu_s": time.thread_time() - main_cpu}
    return PolygoniseResult(vertices=vertices, faces=faces, grid=grid,
                            inside_fraction=float(inside_w / total_weight(job)),
                            stats={"slabs": job.n_slabs, "planes_per_slab": job.planes,
                                   "threads": threads, "samples": grid.n_samples, **cpu})
