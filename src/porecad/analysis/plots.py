"""The report's plots (PNG): size and curvature histograms, mid sections, the preview, the calibration curve.

Each figure is a bare :class:`matplotlib.figure.Figure` drawn by the Agg
canvas: pyplot (its figure manager and backend selection) is never imported,
which saves its import and per-figure bookkeeping. Every plot has its axes
named with units; the preview's renders are pictures of the part, with the
scale given in their titles.
"""

from __future__ import annotations

import numpy as np


def new_figure(figsize, dpi=110, nrows=1, ncols=1):
    """``(figure, axes)``: a figure for the Agg canvas (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols)


def histogram(path, values, weights, title, xlabel, color, ylabel=None):
    """A histogram of ``values`` (NaN and inf left out); with ``weights``, fractions of their total on the
    central 98 % of it."""
    fig, ax = new_figure((5.5, 3.6))
    ok = np.isfinite(values)
    values = np.asarray(values, float)[ok]
    if weights is not None:  # fractions of the total weight (the surface area), on its central 98 %
        w = np.asarray(weights, float)[ok]
        w = w / max(float(w.sum()), 1e-300)
        order = np.argsort(values)
        cum = np.cumsum(w[order])
        lo, hi = values[order][np.searchsorted(cum, [0.01, 0.99]).clip(0, len(values) - 1)]
        inside = (values >= lo) & (values <= hi)
        ax.hist(values[inside], bins=40, range=(lo, hi) if hi > lo else None, weights=w[inside], color=color,
                edgecolor="white", linewidth=0.4)
        title = f"{title}; central 98 % of the area"
    else:
        ax.hist(values, bins=40, color=color, edgecolor="white", linewidth=0.4)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel or ("fraction of the surface area" if weights is not None else "count"))
    fig.subplots_adjust(left=0.14, right=0.97, bottom=0.14, top=0.91)
    fig.savefig(path)


def sections(path, solid, pore, strut, inside=None, origin=(0.0, 0.0, 0.0), h=1.0):
    """Three mid sections coloured by strut thickness (+) and pore size (−); outside the domain blank.

    ``origin`` (mm, x y z) and ``h`` (mm) place voxel ``[k, j, i]`` at ``origin + (i, j, k) h``: the axes
    are in mm.
    """
    if inside is None:
        inside = np.ones_like(solid)
    o = np.asarray(origin, dtype=np.float64)
    nz, ny, nx = solid.shape

    def ext(a, n):      # voxel edges along axis a (mm)
        return (o[a] - 0.5 * h, o[a] + (n - 0.5) * h)

    cuts = [(f"xy at z = {o[2] + h * (nz // 2):.3g} mm", np.s_[nz // 2, :, :], ext(0, nx) + ext(1, ny), "x", "y"),
            (f"xz at y = {o[1] + h * (ny // 2):.3g} mm", np.s_[:, ny // 2, :], ext(0, nx) + ext(2, nz), "x", "z"),
            (f"yz at x = {o[0] + h * (nx // 2):.3g} mm", np.s_[:, :, nx // 2], ext(1, ny) + ext(2, nz), "y", "z")]
    vmax = float(max(pore.max(), strut.max(), 1e-9))
    fig, axes = new_figure((11, 4.2), ncols=3)
    fig.subplots_adjust(left=0.06, right=0.86, bottom=0.12, top=0.9, wspace=0.32)
    for ax, (name, sl, extent, xl, yl) in zip(axes, cuts):
        img = np.where(inside[sl], np.where(solid[sl], strut[sl], -pore[sl]), np.nan)
        im = ax.imshow(img, origin="lower", cmap="RdBu_r", vmin=-vmax, vmax=vmax, interpolation="nearest",
                       extent=extent)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel(f"{xl} (mm)")
        ax.set_ylabel(f"{yl} (mm)")
        ax.tick_params(labelsize=8)
    fig.colorbar(im, ax=axes, shrink=0.85, label="strut thickness (+) / pore size (−), mm")
    fig.savefig(path)


def preview(path, images, extent_mm=None):
    """The two renders of :func:`porecad.analysis.report.preview_images` side by side (pictures, no axes:
    the part's size is in the titles)."""
    whole, cut, y = images
    size = "" if extent_mm is None else " ({} mm)".format(" × ".join(f"{e:.3g}" for e in extent_mm))
    fig, axes = new_figure((11, 4.6), ncols=2)
    for ax, img, title in ((axes[0], whole, f"the part{size}"),
                           (axes[1], cut, f"cut away at y = {y:.3g} mm (section in red)")):
        ax.imshow(img, interpolation="lanczos")
        ax.set_title(title)
        ax.set_axis_off()
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.92, wspace=0.03)
    fig.savefig(path)
