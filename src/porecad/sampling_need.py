"""How finely a lattice must be sampled: the samples per cell edge its design needs.

A lattice sampled too coarsely is not the lattice asked for: walls thinner
than two samples tear, struts break into loose pieces that the promise check
then drops, and the porosity drifts. How coarse is too coarse depends on the
design (type, structure, threshold), not on the body's size: a gyroid pore at
0.6 porosity holds together at 4 samples per cell, a gyroid sheet at 0.83
needs about 40 (its walls are 5 % of the cell).

:func:`samples_per_cell` measures it instead of tabulating it. Two cells per
axis of the lattice are meshed (:func:`porecad.mesh.polygonise.polygonise`,
as every job meshes) at ``n`` samples per cell, for ``n`` up the ladder
:data:`LADDER`, at two offsets of the grid against the lattice (a body's grid
is not aligned with its cells). ``n`` is enough when, at every offset, the
block falls into as many pieces of material (of at least
:data:`PIECE_FRACTION` of it) as at :data:`REFERENCE` samples per cell (finer
than the valid-range table's 32, :mod:`porecad.calibration`), and its
porosity by mesh volume lands within :data:`POROSITY_TOLERANCE` of the exact
whole-cell porosity once the mean miss over the offsets is taken out — as the
jobs take it out (:func:`porecad.bodies.body_porosity.mesh_bias`); a mean miss
over :data:`BIAS_MAX` is too much to take out.
"""

from __future__ import annotations

import functools

import numpy as np

#: samples per cell edge tried, coarse to fine (the last is used when none is enough)
LADDER = (4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48)
#: the fine sampling whose pieces are the lattice's own
REFERENCE = 48
#: after the mean miss is taken out, the porosity by mesh at any offset may miss by this much (half the
#: promise's 0.01: the body's own sampling adds its share)
POROSITY_TOLERANCE = 0.005
#: the largest mean miss (the mesh's bias) taken out
BIAS_MAX = 0.05
#: pieces of material smaller than this fraction of the block's material are cut-off corners, not counted
PIECE_FRACTION = 1e-3
#: offsets of the grid against the lattice (x, y, z), as fractions of a cell
OFFSETS = ((0.0, 0.0, 0.0), (0.37, 0.13, 0.71), (0.71, 0.53, 0.29))


def samples_per_cell(tpms_type: str, structure: str, threshold: float) -> tuple[int, dict]:
    """The fewest samples per cell edge that keep the lattice's pieces and porosity (module docstring).

    Returns ``(n, info)``: ``info`` has ``enough`` (False when even the
    finest of :data:`LADDER` is not, then ``n`` is that finest), the whole-cell
    ``porosity`` and, at ``n``, the mean porosity miss (``bias``), the largest miss left
    once it is taken out, and the pieces.
    The result depends only on the design (cells scale), so it is cached.
    """
    return _need(tpms_type, str(structure), round(float(threshold), 4))


@functools.lru_cache(maxsize=64)
def _need(tpms_type, structure, threshold):
    from .calibration import porosity_of_threshold
    exact = float(porosity_of_threshold(tpms_type, structure, threshold))
    ref = [_block(tpms_type, structure, threshold, REFERENCE, off)[1] for off in OFFSETS]
    info = {"porosity": exact}
    for n in LADDER:
        got = [_block(tpms_type, structure, threshold, n, off) for off in OFFSETS]
        p = np.array([q for q, _ in got]) - exact
        bias, miss = float(p.mean()), float(np.abs(p - p.mean()).max())
        pieces = [k for _, k in got]
        info.update(samples_per_cell=n, bias=round(bias, 4), porosity_miss=round(miss, 4), pieces=pieces,
                    reference_pieces=ref)
        if miss <= POROSITY_TOLERANCE and abs(bias) <= BIAS_MAX and pieces == ref:
            return n, {**info, "enough": True}
    return LADDER[-1], {**info, "enough": False}


def _block(tpms_type, structure, threshold, n, offset):
    """Porosity by mesh volume and the pieces of material of two cells per axis at ``n`` samples per cell."""
    from .fields.tpms import TPMSField
    from .mesh.grid import Grid
    from .mesh.polygonise import polygonise
    from .mesh.shells import shell_labels
    from .solids import StructureField
    lo = np.asarray(offset, float)
    grid = Grid.from_box(lo, lo + 2.0, samples_per_axis=(2 * n + 1,) * 3)
    material = StructureField(TPMSField(tpms_type, 1.0), structure, float(threshold))
    res = polygonise(material.sample_grid, grid, caps=True, threads=1)
    if not len(res.faces):
        return 1.0, 0
    _, vol = shell_labels(res.vertices, res.faces)
    total = float(vol.sum())
    pieces = int(np.count_nonzero(vol > PIECE_FRACTION * max(total, 1e-300)))
    return 1.0 - total / 8.0, pieces


def area_per_volume(tpms_type: str, structure: str, threshold: float) -> float:
    """The lattice's surface area per unit volume in cells of size 1 (divide by the cell size in mm): two cells
    per axis meshed at :data:`AREA_SAMPLES` per cell, for the size estimate of a job (:mod:`porecad.resources`)."""
    return _area(tpms_type, str(structure), round(float(threshold), 4))


#: samples per cell of the two cells whose area :func:`area_per_volume` measures
AREA_SAMPLES = 24


@functools.lru_cache(maxsize=64)
def _area(tpms_type, structure, threshold):
    from .fields.tpms import TPMSField
    from .mesh.grid import Grid
    from .mesh.polygonise import polygonise
    from .solids import StructureField
    grid = Grid.from_box(np.zeros(3), np.full(3, 2.0), samples_per_axis=(2 * AREA_SAMPLES + 1,) * 3)
    res = polygonise(StructureField(TPMSField(tpms_type, 1.0), structure, float(threshold)).sample_grid, grid,
                     caps=False, threads=1)
    if not len(res.faces):
        return 0.0
    tri = np.asarray(res.vertices, np.float64)[np.asarray(res.faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    return float(area) / 8.0

