"""Up-front estimates of a job's memory and output size; refusal of jobs that will not fit.

The mesh of a level set sampled with spacing ``h`` has about
``TRIS_PER_AREA * S / h^2`` triangles, with ``S`` the surface area
(measured: 3.2 triangles per ``h^2`` of area for marching cubes on the P
surface, 002 Table 5 at N = 500; 2.7-3.2 on lattices of 30 samples per cell).
``S`` is the domain volume times the lattice's own area per volume where the
job measures it (two cells meshed, :func:`porecad.sampling_need.area_per_volume`),
else an upper bound (4 per cell size; the catalogue's largest, D, has 3.83
at C = 0 per 002 Table 4; doubled for sheets), plus the area of the domain's
boundary where the solid meets it. Peak memory counts the mesh
(vertices float64, faces int32), the stitched copy, and the slabs in flight.

Time (``seconds``, a guide shown before the mesh is made): sampling and
marching cubes cost :data:`SECONDS_PER_SAMPLE` per grid sample and thread,
validating and writing :data:`SECONDS_PER_TRIANGLE` per triangle (measured
on the 2-core development machine: a gyroid cut to a 7,000-triangle body,
3.4 M samples in 0.9 CPU s whether the mesh had 0.17 or 0.96 M triangles;
the CT bone of ``bench/images.py``, 6.8 M triangles validated and written in
about 7 s).

Every job sizes its work the same way before it starts: an estimate dict
(``samples``, ``triangles``, ``peak_bytes``, ``stl_bytes``, ``seconds``) from
:func:`estimate` (a sampled grid), :func:`mapped_estimate` (cells mapped
from a parameter box: ``hex``, ``tbss``, ``tis``, ``arbf``) or
:func:`work_estimate` (any count of samples and triangles), refused by
:func:`require_fits` in one line (the estimate, the memory available or the
``memory_limit``, what to change) when it exceeds the memory or
:data:`MAX_SAMPLES`.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError, ResourceError
from .io.bounded import memory_budget

TRIS_PER_AREA = 3.2
BYTES_PER_TRIANGLE = 2 * (12 + 12) + 16  # faces + half a float64 vertex, twice while stitching
#: peak bytes per estimated triangle of a lattice job meshed in memory: the mesh, its check, the promise check's
#: pieces and the rounded copy the files store; measured on 150 mm bodies in 1.5 mm gyroid cells (peak less
#: 0.3 GB per triangle made: a bunny 263 (18.8 GB, 71.5 M), a femur 270 (2.3 GB, 7.4 M), limbs 269 (5.4 GB,
#: 19.0 M)); the estimate of the triangles is within 0.8-1.3x of those made (bench/bone-size.md)
BYTES_PER_LATTICE_TRIANGLE = 290
#: bytes per triangle of a slab in flight when a mesh is streamed (its arrays, the weld, the check's edge keys and
#: pieces; nine slabs' worth with 2 threads): a streamed peak is the footprint below and about 1,000 bytes per slab
#: triangle (150 mm bodies: a bunny 2.4 GB for 1.9 M per slab, a blob 3.3 GB for 4.0 M; an ellipsoid of 58 mm
#: in 0.12 mm voxels 1.9 GB for 1.5 M; one of 15 mm in 4 MiB slabs 0.56 GB for 0.11 M)
STREAMED_BYTES_PER_TRIANGLE = 110
#: a streamed body job's footprint besides its slabs: the process, the body, its calibration samples (an
#: ellipsoid's job in 1 MiB slabs peaked at 415 MB)
STREAMED_BASE_BYTES = 450e6
MAX_SAMPLES = 2e11
SECONDS_PER_SAMPLE = 0.3e-6
SECONDS_PER_TRIANGLE = 1.0e-6


#: the most parametric samples of a mapped scaffold (TBSS periods or hex cells, times resolution³)
MAX_PARAM_SAMPLES = 400_000_000


def require_param_samples(counts, resolution: int, per: str = "cell") -> None:
    """Refuse, before the work, more than :data:`MAX_PARAM_SAMPLES` samples of ``counts`` cells (or periods:
    ``per="period"``) at ``resolution`` samples per edge."""
    samples = float(np.prod(np.asarray(counts, dtype=np.float64))) * float(resolution) ** 3
    if samples > MAX_PARAM_SAMPLES:
        raise ResourceError(f"{' x '.join(str(int(c)) for c in counts)} {per}s at {resolution} samples per {per} "
                            f"edge are {samples:,.0f} samples (at most {MAX_PARAM_SAMPLES:,}); lower the resolution "
                            f"or use fewer {per}s")


def estimate(grid, cell_size, structure: str, domain_volume: float, domain_area: float,
             chunk_bytes: int, threads: int, area_per_volume: float | None = None) -> dict:
    """Estimated triangles, peak memory (bytes) and binary-STL size of a job.

    ``area_per_volume``: the lattice's own (mm⁻¹, :func:`porecad.sampling_need.area_per_volume`); without it the
    upper bound of the module docstring."""
    h = float(np.mean(grid.spacing))
    L = float(np.min(np.broadcast_to(cell_size, (3,))))
    if area_per_volume is None:
        area_per_volume = 4.0 / L * (2.0 if structure == "sheet" else 1.0)
    area = area_per_volume * domain_volume + domain_area
    tris = TRIS_PER_AREA * area / (h * h)
    peak = tris * BYTES_PER_LATTICE_TRIANGLE + 3 * threads * chunk_bytes + 200e6
    seconds = SECONDS_PER_SAMPLE * grid.n_samples / max(int(threads), 1) + SECONDS_PER_TRIANGLE * tris
    return {"samples": grid.n_samples, "triangles": int(tris), "peak_bytes": int(peak),
            "stl_bytes": int(84 + 50 * tris), "seconds": float(seconds)}


def require_fits(est: dict, memory_limit: int | None = None,
                 change: str = "lower the `resolution` or the number of cells", what: str = "the job") -> None:
    """Raise :class:`ResourceError` (one line: the estimate, the memory there is, ``change``) if the job will not fit.

    Without ``memory_limit`` the job may use 80 % of the available memory;
    with one, all of it.
    """
    eta = describe_seconds(est.get("seconds") or 0.0)
    if est["samples"] > MAX_SAMPLES:
        unit = est.get("unit", "samples")
        raise ResourceError(f"{what} is too large: {est['samples']:.3g} {unit} (limit {MAX_SAMPLES:.0e}, "
                            f"{eta}); {change}")
    limit = memory_budget(memory_limit)
    usable = usable_bytes(memory_limit)
    if not est["peak_bytes"] <= usable:
        have = (f"{usable / 2**30:.3g} GiB available" if memory_limit is None
                else f"over the memory limit of {limit / 2**30:.3g} GiB (`memory_limit`)")
        tris = f"about {est['triangles']:.3g} triangles " if est.get("triangles") else ""
        raise ResourceError(f"{what} is too large for this machine: {tris}needing about "
                            f"{est['peak_bytes'] / 2**30:.3g} GiB of memory and {eta}, {have}; {change}")


def usable_bytes(memory_limit: int | None = None) -> float:
    """The memory a job may use: 80 % of the available memory, or all of ``memory_limit``."""
    limit = memory_budget(memory_limit)
    return 0.8 * limit if memory_limit is None else float(limit)


def describe_seconds(seconds: float) -> str:
    """An estimated time in words: ``about 40 s``, ``about 12 min``, ``about 3.5 h``."""
    s = float(seconds)
    if s >= 5400:
        return f"about {s / 3600:.2g} h"
    return f"about {s / 60:.0f} min" if s >= 90 else f"about {s:.0f} s"


#: base footprint of a job's process (Python, numpy, numba and porecad loaded)
BASE_BYTES = 300e6
#: peak bytes per estimated triangle of a mapped scaffold (the mesh, its parameters, the crossing search and
#: validation), above :data:`WORK_BASE_BYTES`: measured (bench/estimates.md) 220 (hex IWP cylinder refined to 1,040
#: cells, 2.3 M triangles), 255 (tbss P cylinder, 1.3 M), 330 (tbss D rod), 300-370 (hex P, IWP of 64-96 cells)
#: per triangle of :func:`mapped_estimate` (was 400 over the area bound's, which counted 4/3 as many); 350 is the
#: top of that range
BYTES_PER_MAPPED_TRIANGLE = 350
#: seconds per estimated triangle of a mapped scaffold (same runs, 2 cores: P 1.6 us, D 8.5 us)
SECONDS_PER_MAPPED_TRIANGLE = 4e-6
#: surface area of one mapped cell, in cell edges squared (twice for sheets): the triangles of a mapped scaffold
#: are ``TRIS_PER_AREA`` times this per sample spacing squared. The area bound 4 (:func:`estimate`) made
#: 1.34-1.57 times the triangles measured (bench/estimates.md: tbss P pore, G sheet; hex P hex20, IWP, refined P;
#: arbf hex and hex-rod); 3 gives 0.83 (tbss D rod, the densest) to 1.18 of them
MAPPED_AREA_PER_CELL = 3.0
#: the footprint of a job's process in :func:`work_estimate` (porecad, numpy, numba loaded and a small job done):
#: the max RSS of the smallest jobs of bench/estimates.md was 193-216 MB (tis and arbf of one element)
WORK_BASE_BYTES = 210e6


def work_estimate(samples: float, triangles: float, sample_bytes: float = 8.0,
                  triangle_bytes: float = BYTES_PER_TRIANGLE, sample_seconds: float = SECONDS_PER_SAMPLE,
                  triangle_seconds: float = SECONDS_PER_TRIANGLE, extra_bytes: float = 0.0) -> dict:
    """The estimate (:func:`require_fits`) of work on ``samples`` samples that makes about ``triangles`` triangles."""
    samples, triangles = float(samples), float(triangles)
    peak = WORK_BASE_BYTES + samples * sample_bytes + triangles * triangle_bytes + float(extra_bytes)
    return {"samples": samples, "triangles": int(triangles), "peak_bytes": peak, "stl_bytes": int(84 + 50 * triangles),
            "seconds": samples * sample_seconds + triangles * triangle_seconds}


def mapped_estimate(counts, resolution: int, structure: str = "pore", sample_bytes: float = 8.0) -> dict:
    """The estimate of one TPMS period (or element) per cell of ``counts``, ``resolution`` samples per edge.

    Triangles: :data:`MAPPED_AREA_PER_CELL` per cell edge squared (twice for sheets) at
    :data:`TRIS_PER_AREA` per sample spacing squared; each costs :data:`BYTES_PER_MAPPED_TRIANGLE`.
    """
    cells = float(np.prod(np.asarray(counts, dtype=np.float64)))
    r = float(resolution)
    tris = TRIS_PER_AREA * MAPPED_AREA_PER_CELL * (2.0 if structure == "sheet" else 1.0) * cells * r * r
    return work_estimate(cells * r ** 3, tris, sample_bytes=sample_bytes, triangle_bytes=BYTES_PER_MAPPED_TRIANGLE,
                         triangle_seconds=SECONDS_PER_MAPPED_TRIANGLE)


def require_disk(est: dict, path) -> None:
    """Refuse up front (ResourceError) a mesh whose estimated file would not fit on the disk it goes to."""
    import os
    import shutil
    if not path:
        return
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    need = float(est.get("stl_bytes") or 0)
    if need > free:
        raise ResourceError(f"the mesh would be about {need / 2**30:.3g} GiB ({est['triangles']:.3g} triangles); "
                            f"{free / 2**30:.3g} GiB is free where it goes: lower the resolution or the cell count")


def estimate_streamed(est: dict, grid, chunk_bytes: int, workers: int, window: int,
                      processes: bool = False) -> dict:
    """The estimate of a streamed job: memory bounded by the chunks in flight, not by the mesh.

    Each chunk in flight holds its float32 samples (computed on a worker) or
    its mesh (waiting to be welded); the mesh of a chunk is bounded by its
    share of the estimated triangles. Workers of a remote cluster are
    counted too (a bound for the whole job); worker processes
    (``processes``) each add the base footprint of a Python process.
    """
    nx, ny, nz = grid.shape
    planes = max(2, min(nz, chunk_bytes // max(nx * ny * 4, 1)))
    slabs = max(1, -(-(nz - 1) // max(1, planes - 1)))
    slab_mesh = est["triangles"] / slabs * STREAMED_BYTES_PER_TRIANGLE
    slab_samples = planes * nx * ny * 4
    # worker: samples + kernel scratch + its mesh; driver: the window of meshes, two slabs welded and checked
    base = STREAMED_BASE_BYTES + BASE_BYTES * (workers if processes else 0)
    peak = workers * (2 * slab_samples + slab_mesh) + (window + 2) * slab_mesh + base
    out = dict(est)
    out.update({"peak_bytes": int(peak), "streamed": True})
    return out


#: an output larger than this (bytes of binary STL, or triangles) is announced before the work starts
LARGE_OUTPUT_BYTES = 1e9
LARGE_OUTPUT_TRIANGLES = 10e6
_UNITS = {"": 1, "b": 1, "kb": 1e3, "mb": 1e6, "gb": 1e9, "tb": 1e12, "kib": 2**10, "mib": 2**20,
          "gib": 2**30, "tib": 2**40}


def parse_size(text) -> int:
    """Bytes of a size such as ``500MB``, ``2 GB``, ``1.5GiB`` or a plain number of bytes."""
    import re
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:e[0-9]+)?)\s*([a-zA-Z]*)\s*", str(text))
    if not m or m.group(2).lower() not in _UNITS:
        raise InputError(f"not a size: {text!r} (e.g. 500MB, 2GB)")
    n = float(m.group(1)) * _UNITS[m.group(2).lower()]
    if not 0 < n < 1e18:
        raise InputError(f"size out of range: {text!r}")
    return int(n)


#: work estimated longer than this (seconds) is announced before it starts
LONG_WORK_SECONDS = 60.0


def announce_time(est: dict, what: str, write=None) -> str | None:
    """Before the work: say on stderr (or through ``write``) how long ``what`` will take when that is over
    :data:`LONG_WORK_SECONDS`. Returns the line said, if any."""
    if not float(est.get("seconds") or 0.0) > LONG_WORK_SECONDS:
        return None
    return _say(f"porecad: note: {what} will take {describe_seconds(est['seconds'])} (estimated before it starts)",
                write)


def announce_size(est: dict, max_output: int | None = None, write=None) -> str | None:
    """Before the work: refuse an output over ``max_output`` bytes (ResourceError); say on stderr (or through
    ``write``) what a large one will be: estimated triangles, size and time. Returns the line said, if any."""
    size, tris, secs = float(est.get("stl_bytes") or 0), float(est.get("triangles") or 0), float(est["seconds"])
    what = f"about {tris / 1e6:.3g} M triangles, a {size / 1e9:.3g} GB binary STL"
    eta = describe_seconds(secs)
    if max_output is not None and size > max_output:
        raise ResourceError(f"the mesh would be {what} ({eta}), over the {max_output / 1e9:.3g} GB allowed "
                            "(max_output); lower the resolution or the number of cells")
    if size <= LARGE_OUTPUT_BYTES and tris <= LARGE_OUTPUT_TRIANGLES:
        return None
    return _say(f"porecad: note: this job will write {what} in {eta} (estimated before it starts)", write)


def _say(line: str, write=None) -> str:
    """``line`` on stderr (or through ``write``); returns it."""
    if write is None:
        import sys
        print(line, file=sys.stderr, flush=True)
    else:
        write(line)
    return line
