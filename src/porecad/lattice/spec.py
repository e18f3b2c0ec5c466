"""A checked lattice recipe's tables as records (:class:`porecad.jobs.tpms_spec.TpmsSpec` fills them; their keys,
defaults and bounds: :mod:`porecad.recipes.keys`). ``[grading]`` is :class:`porecad.grading.Grading`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fields.tpms import TPMSType


@dataclass(frozen=True)
class CellRamp:
    """``tpms.cell_size`` as a linear ramp, ``from`` (L0) to ``to`` (L1); None: the body's ends and centre."""

    axis: str
    L0: float
    L1: float
    start: float | None
    end: float | None
    centre: list | None


@dataclass(frozen=True)
class Lattice:
    """``[tpms]``: the type (resolved once, by name or alias), one of threshold or porosity, the cells."""

    type: TPMSType
    structure: str
    threshold: float | None
    porosity: float | None
    allow_closed_pores: bool
    cell_size: np.ndarray | CellRamp  # per axis (mm), or a ramp (bodies only)
    origin: tuple


@dataclass(frozen=True)
class Domain:
    """``[domain]``: a box of cells, the analytic disc or a body (``mesh``); the other kinds' keys are None."""

    kind: str
    cells: list | None = None
    origin: list | None = None
    a: float | None = None  # the disc's: None keeps porecad.fields.sdf.LumbarDisc's own
    b: float | None = None
    height: float | None = None
    notch: float | None = None
    notch_depth: float | None = None
    rim: float | None = None
    path: str | None = None
    boundary: str | None = None
    skin: float | None = None  # boundary = skin only
    label: float | None = None
    threshold: float | None = None
    keep_all: bool | None = None
    units: str | None = None


@dataclass(frozen=True)
class Sampling:
    """``[sampling]``: one of voxel (mm) or resolution; neither: a mesh body's default voxel."""

    voxel: float | None = None
    resolution: int | None = None


@dataclass(frozen=True)
class Post:
    """``[post]``."""

    smooth: str
    smooth_iterations: int
    decimate: float


@dataclass(frozen=True)
class Analysis:
    """``[analysis]``."""

    regions: int | None
    region_axis: str | None


@dataclass(frozen=True)
class Scale:
    """``[scale]``: ``scheduler`` a :class:`porecad.scale.schedulers.SchedulerSpec`, ``max_output`` bytes."""

    scheduler: object
    stream: bool | None
    zarr: str | None
    retries: int
    chunk_mb: float | None
    max_output: int | None
