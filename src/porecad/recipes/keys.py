"""Every job's recipe keys, declared once (:class:`~porecad.recipes.schema.Key`; see :mod:`porecad.recipes.schema`).

:data:`JOBS` maps a job's name to its top-level keys; a table's keys are
its :class:`Key`'s ``keys``. The job specs read their tables through these
declarations (:meth:`porecad.recipes.table.Table.get`); ``porecad schema``,
the generated reference in ``docs/recipes.md`` and the studio's form are
made from them. A key added here is in all of them.
"""

from __future__ import annotations

import dataclasses

from ..io.mesh_formats import mesh_suffixes
from .key import REQUIRED, Key

# ------------------------------------------------------------------------------------------ shorthand makers


def num(default=None, help="", **kw) -> Key:  # noqa: A002
    """A number key."""
    return Key("number", default, help, **kw)


def whole(default, lo, hi, help="", **kw) -> Key:  # noqa: A002
    """An integer key (always bounded)."""
    return Key("int", default, help, lo=lo, hi=hi, **kw)


def flag(default, help="", **kw) -> Key:  # noqa: A002
    """A true/false key."""
    return Key("bool", default, help, **kw)


def pick(choices, default, help="", **kw) -> Key:  # noqa: A002
    """A key taking one of ``choices``."""
    return Key("choice", default, help, choices=tuple(choices), **kw)


def table(keys: dict, help="", **kw) -> Key:  # noqa: A002
    """A sub-table."""
    return Key("table", kw.pop("default", None), help, keys=keys, **kw)


FAR = {"lo": -1e7, "hi": 1e7}  # a coordinate or a field value: finite, of sane size
AXIS = ("x", "y", "z")

# -------------------------------------------------------------------------------------------- every job

ROOT = {
    "format": whole(1, 1, 10**6, "Recipe format (2; format-1 recipes of job tpms still run)."),
    "porecad_version": Key("string", None, "The porecad that wrote the recipe.", max_len=64),
    "job": Key("string", None, "The job's name."),
    "islands": pick(("drop", "keep"), None, "Pieces not attached to the largest one: dropped (the default) or "
                                            "kept with a warning."),
    "strict": flag(False, "Any warning is a refusal (exit status 6, nothing written)."),
}

OUTPUTS = {
    "mesh": Key("output", None, f"The solid ({mesh_suffixes('write', ', ')})."),
    "report": Key("output", None, "A .json report, or a folder: the HTML report with the full analysis."),
    "report_dir": Key("output", None, "The HTML report folder beside a JSON report."),
    "recipe": Key("output", None, "This recipe, rewritten with paths relative to it."),
    "tdf": Key("output", None, "The TDF (threshold distribution function) file."),
    "tets": Key("output", None, "The tet mesh the surface was built over."),
    "centreline": Key("output", None, "The model's centreline (.vtp, MaximumInscribedSphereRadius, its frame)."),
    "labelmap": Key("output", None, "The model as a labelmap on the input image's grid (.nrrd, .seg.nrrd)."),
    "dir": Key("output", None, "Required: the folder of every disc's scaffolds and the job report."),
}


def job(tables: dict, outputs: tuple) -> dict:
    """A job's top-level keys: the common ones, its own, and ``[output]`` with ``outputs``."""
    out = {k: OUTPUTS[k] for k in outputs}
    return {**ROOT, **tables, "output": table(out, "The files the job writes (relative to the recipe).")}


# ---------------------------------------------------------------------------------------------- tpms, infill

#: the smallest TPMS cell (mm): 1 µm, below any printer and well within the float32 coordinates of a mesh file
CELL_MIN = 1e-3

RAMP = {
    "kind": pick(("linear",), "linear", "A linear ramp of the cell size."),
    "axis": pick(AXIS, "z", "The axis it runs along.", fold_case=True),
    "from": num(REQUIRED, "Cell size at the start.", units="mm", lo=CELL_MIN, hi=1e5),
    "to": num(REQUIRED, "Cell size at the end.", units="mm", lo=CELL_MIN, hi=1e5),
    "start": num(None, "Where the ramp starts along its axis (default: the body's start).", units="mm", **FAR),
    "end": num(None, "Where the ramp ends along its axis (default: the body's end).", units="mm", **FAR),
    "centre": Key("numbers", None, "Centre of the ramp.", units="mm", length=3, **FAR),
}

LATTICE_TPMS = {
    "type": Key("any", REQUIRED, "TPMS type (G, P, D, IWP, ...; porecad.fields.tpms).", json="string"),
    "structure": Key("any", "sheet", "pore, rod, sheet or surface (a bare surface).", json="string"),
    "threshold": num(None, "Threshold C of the TPMS field.", excludes=("porosity",), one_of=True),
    "porosity": num(None, "Target porosity (void fraction) instead of a threshold.", excludes=("threshold",)),
    "allow_closed_pores": flag(False, "Build outside the valid range (the report says so)."),
    "cell_size": Key("numbers", 1.0, "Cell size, one or per axis (or a table: a linear ramp, bodies only).",
                     units="mm", length=(1, 3), lo=CELL_MIN, hi=1e5, keys=RAMP),
    "origin": Key("numbers", [0.0, 0.0, 0.0], "Origin of the lattice.", units="mm", length=3, **FAR),
}

_DISC = "Analytic lumbar disc (kind = disc): "
LATTICE_DOMAIN = {
    "kind": pick(("box", "disc", "mesh"), "box", "box (of cells), disc (analytic lumbar disc) or mesh (a body "
                                                 "file; infill's default)."),
    "cells": Key("integers", [1, 1, 1], "Cells NX NY NZ of a box.", length=3, lo=1, hi=100_000,
                 what="cell counts"),
    "origin": Key("numbers", [0.0, 0.0, 0.0], "Origin of a box.", units="mm", length=3, **FAR),
    **{k: num(None, _DISC + k.replace("_", " ") + ".", units="mm", nonneg=True, hi=1e5)
       for k in ("a", "b", "height", "notch", "notch_depth", "rim")},
    "path": Key("path", REQUIRED, "The body (mesh or image) of kind = mesh.", when="kind = mesh"),
    "boundary": pick(("cut", "skin", "whole"), "cut", "cut to the body, a solid skin, or whole cells only."),
    "skin": num(1.0, "Shell thickness (boundary = skin).", units="mm", positive=True, hi=1e5),
    "label": num(None, "Image body: the voxel value of the body in a label map.", excludes=("threshold",)),
    "threshold": num(None, "Image body: voxels at or above this.", excludes=("label",)),
    "keep_all": flag(False, "Keep every component of an image body (default: the largest)."),
    "units": pick(("mm", "m", "um", "in"), "mm", "Units of the body file."),
}

GRADING = {
    "kind": pick(("constant", "linear", "radial", "expression", "distance", "points", "image"), "constant",
                 "The grading field (porecad.grading)."),
    "of": pick(("threshold", "porosity"), "threshold", "What the field grades."),
    "value": num(None, "kind = constant: the value.", **FAR),
    "axis": pick(AXIS, "z", "kind = linear: the axis.", fold_case=True),
    "start": num(None, "kind = linear: where the ramp starts.", units="mm", **FAR),
    "end": num(None, "kind = linear: where it ends (not start).", units="mm", **FAR),
    "from": num(None, "The value at the start (linear), the centre (radial) or the surface (distance).", **FAR),
    "to": num(None, "The value at the end (linear), r1 (radial) or d1 (distance).", **FAR),
    "axes": Key("string", "xyz", "kind = radial: the axes the radius is measured in (some of x, y, z).",
                max_len=3),
    "centre": Key("numbers", [0.0, 0.0, 0.0], "kind = radial: the centre.", units="mm", length=3, **FAR),
    "r0": num(0.0, "kind = radial: radius where the ramp starts.", units="mm", nonneg=True, hi=1e7),
    "r1": num(REQUIRED, "kind = radial: radius where it ends (larger than r0).", units="mm", positive=True,
              hi=1e7, when="kind = radial"),
    "expr": Key("any", REQUIRED, "kind = expression: a formula in x, y, z (mm) and dn (depth).", json="string",
                when="kind = expression"),
    "d0": num(0.0, "kind = distance: depth where the ramp starts.", units="mm", nonneg=True, hi=1e7),
    "d1": num(None, "kind = distance: depth where it ends (default: the deepest point).", units="mm",
              positive=True, hi=1e7),
    "exponent": num(1.0, "kind = distance: exponent of the ramp.", positive=True, hi=100.0),
    "file": Key("path", REQUIRED, "kind = points: a CSV of x, y, z, value.", excludes=("points",),
                when="kind = points, no points"),
    "points": Key("any", None, "kind = points: 4 to 100,000 rows of [x, y, z, value].", json="array",
                  excludes=("file",)),
    "smoothing": num(0.0, "kind = points: smoothing of the interpolant.", nonneg=True, hi=1e6),
    "path": Key("path", REQUIRED, "kind = image: the image whose values (x scale + offset) are the field.",
                when="kind = image"),
    "scale": num(1.0, "kind = image: scale of the image values.", **FAR),
    "offset": num(0.0, "kind = image: offset of the image values.", **FAR),
}

SCALE = {
    "scheduler": Key("any", None, "threads or local:N, N at most the cores (a recipe file); tcp://HOST:PORT "
                                  "only from the command line or Python (porecad.scale).", json="string",
                     local_only=True),
    "stream": flag(None, "Stream chunks to the mesh file instead of holding the mesh."),
    "zarr": Key("output", None, "Store the sampled field in a Zarr folder."),
    "retries": whole(2, 0, 100, "Attempts after a chunk fails."),
    "chunk_mb": num(None, "Samples per chunk (default 16).", units="MiB", positive=True, hi=1 << 16,
                    what="chunk_mb"),
    "max_output": Key("any", None, "Largest output, e.g. 500MB.", json="string"),
}

LATTICE = {
    "tpms": table(LATTICE_TPMS, "The lattice.", default=REQUIRED),
    "domain": table(LATTICE_DOMAIN, "Where the lattice is: a box of cells or a body."),
    "grading": table(GRADING, "Optional threshold or porosity field, instead of one threshold/porosity."),
    "sampling": table({
        "resolution": whole(40, 2, 100_000, "Samples per cell edge (both ends included).", excludes=("voxel",)),
        "voxel": num(REQUIRED, "Sample spacing (instead of resolution).", units="mm", positive=True, hi=1e4, when="given",
                     excludes=("resolution",)),
    }, "How finely the field is sampled."),
    "post": table({
        "smooth": pick(("none", "laplacian", "taubin"), "none", "Smoothing of the mesh.", fold_case=True),
        "smooth_iterations": whole(10, 0, 10_000, "Smoothing iterations."),
        "decimate": num(0.0, "Decimation tolerance (keeps it closed).", units="mm", nonneg=True, hi=1e6),
    }, "Post-processing of the mesh."),
    "analysis": table({
        "regions": whole(None, 0, 100, "Per-region porosity of graded body jobs: the number of slabs."),
        "region_axis": pick(AXIS, None, "Slab axis (default: longest).", fold_case=True),
    }, "Extra analysis."),
    "scale": table(SCALE, "Scale-out (docs/scale-out.md)."),
}

#: a body's defaults: pores in 5 mm cells (a bone, a disc), the body a mesh file
INFILL = {**LATTICE,
          "tpms": dataclasses.replace(LATTICE["tpms"], keys={
              **LATTICE_TPMS, "structure": dataclasses.replace(LATTICE_TPMS["structure"], default="pore"),
              "cell_size": dataclasses.replace(LATTICE_TPMS["cell_size"], default=5.0)}),
          "domain": dataclasses.replace(LATTICE["domain"], keys={
              **LATTICE_DOMAIN, "kind": dataclasses.replace(LATTICE_DOMAIN["kind"], default="mesh")})}

# ------------------------------------------------------------------------------------------------------ tbss

_SIZE = {"units": "mm", "positive": True, "hi": 1e6}
PRIMITIVE = {
    "width": num(None, "disc: width.", **_SIZE),
    "depth": num(None, "disc: depth.", **_SIZE),
    "height": num(None, "disc, cylinder, tube: height.", **_SIZE),
    "wedge_deg": num(None, "disc: wedge angle.", units="°", lo=-90.0, hi=90.0),
    "dome": num(None, "disc: dome height.", units="mm", nonneg=True, hi=1e6),
    "center": Key("numbers", None, "disc, cylinder, tube: centre.", units="mm", length=3, lo=-1e6, hi=1e6),
    "size": Key("numbers", None, "box: size.", units="mm", length=3, lo=-1e6, hi=1e6, positive=True),
    "origin": Key("numbers", None, "box: origin.", units="mm", length=3, lo=-1e6, hi=1e6),
    "radius": num(None, "cylinder: radius.", **_SIZE),
    "r_inner": num(None, "tube: inner radius.", **_SIZE),
    "r_outer": num(None, "tube: outer radius.", **_SIZE),
}

TBSS = {
    "body": table({
        "kind": pick(("disc", "box", "cylinder", "tube", "mesh"), "disc", "A primitive body or a mesh to fit."),
        "path": Key("path", REQUIRED, "kind = mesh: the body, fitted.", when="kind = mesh"),
        "fit": pick(("auto", "radial", "sliced", "hex"), "auto", "kind = mesh: how the TBSS is fitted."),
        "control": Key("integers", 8, "kind = mesh: TBSS control grid of a fitted body (one or three).",
                       length=3, lo=4, hi=64, scalar=True),
        "clip": flag(True, "kind = mesh: fit a margin larger, cut the scaffold to the body."),
        "margin": num(None, "kind = mesh: the margin (default: radial fit a tenth of the body's mean thickness "
                            "3V/A, hex 0; sliced: none).", units="mm", nonneg=True, hi=1e6),
        "skin": num(None, "kind = mesh: a clipped scaffold wrapped in a solid shell that thick (default 0).",
                    units="mm", nonneg=True, hi=1e6),
        "params": table(PRIMITIVE, "A primitive body's sizes and position."),
    }, "The body: a primitive or a mesh to fit and cut to."),
    "tpms": table({
        "type": Key("any", "G", "TPMS type (G, P, D, ...).", json="string"),
        "structure": Key("any", "sheet", "pore, rod or sheet.", json="string"),
        "periods": Key("any", (4, 4, 4), "Periods along u, v, w (one or three whole numbers).", json="array",
                       excludes=("cell_size",)),
        "cell_size": num(None, "Instead of periods: mm per cell along the solid's u, v, w lines.", units="mm",
                         positive=True, hi=1e9, excludes=("periods",)),
        "allow_closed_pores": flag(False, "Accept a TDF outside the valid threshold range."),
    }, "The lattice."),
    "tdf": table({
        "method": pick(("layer", "fill", "function"), "layer", "How the threshold distribution is made."),
        "by": pick(("u", "v", "w", "sides", "boundary"), "w", "method = layer: layers along."),
        "layers": whole(None, 1, 1000, "method = layer: number of layers (default: one per period along by)."),
        "layer_values": Key("numbers", None, "method = layer: the value of each layer.", max_len=1000),
        "quantity": pick(("mean", "gaussian"), "mean", "method = fill: mean or gaussian curvature."),
        "expr": Key("any", REQUIRED, "method = function: a formula in u, v, w.", json="string",
                    when="method = function"),
        "threshold_range": Key("numbers", None, "Map the TDF onto [lo, hi] (default: valid range, inset 10 %).",
                               length=2, excludes=("porosity_range",)),
        "porosity_range": Key("numbers", None, "Map the TDF onto porosities [lo, hi] instead.", length=2,
                              lo=0.0, hi=1.0, excludes=("threshold_range",)),
        "grid": Key("integers", 100, "Parametric grid N (N^3 vertices; one or three).", length=3, lo=4, hi=400,
                    scalar=True),
        "control": Key("integers", 20, "TDF control grid M (M^3; one or three).", length=3, lo=2, hi=128,
                       scalar=True),
        "degree": whole(3, 1, 5, "Degree of the TDF B-spline."),
        "tol": num(1e-4, "Tolerance of the LSPIA fit.", positive=True, hi=1.0),
        "max_iter": whole(200, 1, 100_000, "Iterations of the LSPIA fit."),
        "file": Key("path", REQUIRED, "Regenerate the scaffold stored in a TDF file (no [body] then).",
                    when="given"),
        "edits": Key("tables", None, "Local modifications (001 §3.2).", max_len=64, keys={
            "where": Key("any", REQUIRED, "A condition in u, v, w.", json="string"),
            "threshold": num(REQUIRED, "The threshold where it holds.", lo=-10, hi=10)}),
        "edit_grid": whole(100, 4, 400, "Grid of the edits."),
    }, "The threshold distribution function."),
    "mesh": table({"resolution": whole(16, 2, 512, "Samples per period edge.")}, "Meshing."),
    "analysis": table({"layers": flag(True, "Achieved porosity per layer.")}, "Extra analysis."),
}

# ------------------------------------------------------------------------------------------------------- hex

HEX = {
    "body": table({
        "kind": pick(("frustum", "cylinder", "mesh", "hexfile"), REQUIRED, "The body of the hex mesh."),
        "path": Key("path", REQUIRED, "kind = mesh or hexfile: the file.", when="kind = mesh or hexfile"),
        "corners": Key("integers", None, "kind = mesh: the 8 body vertex ids that become the corners.",
                       length=8, lo=0, hi=10**9),
        "untangle_limit": num(None, "kind = mesh: seconds for untangling the parameterisation (0: none; "
                                    "default 60).", units="s", nonneg=True, hi=86400.0),
        "bottom": Key("numbers", None, "kind = frustum: bottom size.", units="mm", length=2, positive=True, hi=1e6),
        "top": Key("numbers", None, "kind = frustum: top size.", units="mm", length=2, positive=True, hi=1e6),
        "height": num(None, "kind = frustum or cylinder: height.", units="mm", positive=True, hi=1e6),
        "radius": num(None, "kind = cylinder: radius.", units="mm", positive=True, hi=1e6),
    }, "The body.", default=REQUIRED),
    "tpms": table({
        "type": Key("any", "P", "TPMS type.", json="string"),
        "structure": Key("any", "pore", "pore, rod or sheet.", json="string"),
        "threshold": num(None, "TPMS threshold C.", excludes=("porosity",), one_of=True),
        "porosity": num(None, "Target porosity (of the parameter cells) instead of C.", lo=0.0, hi=1.0,
                        open_lo=True, open_hi=True, excludes=("threshold",)),
        "allow_closed_pores": flag(False, "Build outside the valid range."),
    }, "The lattice."),
    "element": pick(("hex8", "hex20"), "hex8", "8-node or 20-node hexahedra."),
    "grid": Key("integers", None, "Cells NU NV NW of the structured hex mesh (not for hex-mesh files).",
                length=3, lo=1, hi=100_000),
    "mesh": table({"resolution": whole(16, 2, 512, "Samples per cell edge."),
                   "smooth": whole(0, 0, 1000, "Laplacian smoothing iterations of the hex mesh.")}, "Meshing."),
    "intersect": flag(True, "Cut the scaffold to the body (false: cut = none)."),
    "cut": pick(("field", "boolean", "none"), "field", "How it is cut to the body (default none when "
                                                       "intersect = false)."),
    "refine": Key("any", [], "Grid vertices [i, j, k] around which cells are refined (at most 10,000).",
                  json="array"),
    "refine_box": Key("integers", None, "A box of grid vertices [i0, j0, k0, i1, j1, k1] to refine.", length=6,
                      lo=0, hi=100_000),
    "analysis": table({"pore_sizes": flag(True, "Pore sizes of refined cells vs unrefined.")}, "Extra analysis."),
}

# ------------------------------------------------------------------------------------------------------- tis

TIS = {
    "domain": table({
        "kind": pick(("regular-tet", "two-tets", "icosahedron", "tet-mesh", "body"), "regular-tet",
                     "A built-in tet domain, a tet-mesh file or a closed body."),
        "path": Key("path", None, "kind = tet-mesh or body: the file."),
        "size": num(10.0, "Size of a built-in shape.", units="mm", positive=True, hi=1e6),
        "tets": whole(1000, 1, 2_000_000, "kind = body: target tetrahedron count."),
    }, "The tet domain."),
    "tis": table({
        "type": Key("any", "P", "TIS type: P, D or G.", json="string"),
        "lambda": Key("any", 1.0, "Periods per tet: one value or four (per tet coordinate), each ≤ 1000.",
                      json="number"),
        "structure": pick(("pore", "rod"), "pore", "pore or rod."),
        "relative": num(None, "Relative threshold R in [0, 1].", lo=0.0, hi=1.0, excludes=("threshold",),
                        one_of=True),
        "threshold": num(None, "The absolute level C instead.", excludes=("relative",)),
    }, "The implicit surface."),
    "mesh": table({
        "resolution": whole(17, 3, 4096, "Samples per tet edge (default 200 for a regular-tet domain)."),
        "method": pick(("lattice", "grid"), "lattice", "Barycentric lattice per tet, or a Cartesian grid."),
        "smooth": whole(0, 0, 1000, "Smoothing iterations."),
    }, "Meshing."),
}

# ------------------------------------------------------------------------------------------------------ arbf

ARBF = {
    "domain": table({
        "kind": pick(("tet", "two-tets", "icosahedron", "hex", "hex2x2x2", "hex-rod", "mesh-file", "body",
                      "points"), "tet", "A built-in tet or hex mesh, a volume-mesh file, a closed body or points."),
        "path": Key("path", None, "kind = mesh-file, body or points: the file."),
        "size": num(10.0, "Size of a built-in mesh.", units="mm", positive=True, hi=1e6),
        "tets": whole(1000, 1, 2_000_000, "kind = body: target tet count."),
    }, "The domain."),
    "arbf": table({
        "basis": Key("any", "imq", "Radial basis: gaussian, mq, imq or tps.", json="string"),
        "shape": Key("any", 0.1, "Shape parameter c of the basis.", json="number"),
        "iso": num(0.0, "Iso-value of the material {Φ ≥ iso}."),
        "local": flag(False, "Per-cell local solves instead of one global solve."),
        "ring": pick(("vertex", "face"), "vertex", "Neighbourhood of a local solve."),
        "jitter": num(0.0, "Random displacement of the centres.", units="mm", nonneg=True, hi=1e6),
        "seed": whole(0, 0, 2**32 - 1, "Random seed of the jitter (needs a jitter)."),
        "table": flag(True, "Report the table of centres and values."),
        "islands": pick(("drop", "keep"), "drop", "Loose pieces of material besides the largest."),
    }, "The anisotropic RBF."),
    "mesh": table({"resolution": whole(24, 3, 1000, "Grid samples per mean element edge.")}, "Meshing."),
}

# ---------------------------------------------------------------------------------------------------- vessel

VESSEL = {
    "input": table({
        "kind": pick(("centreline", "image"), "centreline", "A centreline graph or a segmented image."),
        "path": Key("path", REQUIRED, "The centreline (.vtp .swc .json) or the image."),
        "points": Key("path", None, "kind = centreline: boundary points to fit."),
        "radius_array": Key("string", None, "kind = centreline: the radius array of a .vtp.", max_len=256),
        "image": Key("path", None, "kind = centreline: segment this image along it."),
        "frame": pick(("auto", "lps", "ras"), "auto", "kind = centreline: its frame (auto: the file's, or found "
                      "in the image)."),
        "threshold": num(None, "kind = image: foreground threshold (default: halfway)."),
        "smooth": num(1.0, "kind = image: smoothing of the image.", nonneg=True, hi=100.0),
        "seeds": Key("any", None, "kind = image: the vessel between the seeds [[x, y, z], ...].", units="mm",
                     json="array"),
        "seeds_file": Key("path", None, "kind = image: the seeds from a 3D Slicer markups file (.mrk.json)."),
    }, "The vessel's centreline or image.", default=REQUIRED),
    "frame_out": pick(("lps", "ras"), None, "Frame of the outputs (default: the input's)."),
    "voxel": num(REQUIRED, "Grid spacing.", units="mm", positive=True, hi=1e4),
    "blend": Key("any", "2,0.2", "Li's union parameters n,delta (003 eq. 2.12), or a table.", json="string",
                 keys={"kind": pick(("li", "sharp", "softmax", "rfunc"), "li", "The blend."),
                       "n": num(None, "li: n."), "delta": num(None, "li: delta."),
                       "k": num(None, "softmax: k."), "alpha": num(None, "rfunc: alpha.")}),
    "wall": Key("numbers", None, "Wall layer thicknesses from the lumen out (none: a solid lumen).", units="mm",
                positive=True, hi=1e4, max_len=16),
    "porous": table({
        "layer": whole(REQUIRED, 1, 16, "Layer number (1 = innermost; at most the wall's layers) made porous."),
        "type": Key("string", "G", "TPMS type (G, P, D, ...) or a 003 periodic field.", max_len=64),
        "cell_size": num(REQUIRED, "Period of the porous field.", units="mm", positive=True, hi=1e4),
    }, "A porous wall layer."),
    "trim_ends": flag(None, "Trim open ends by planes (default: with a wall)."),
    "fit": pick(("rbf", "ellipsoid", "tube"), None, "Fit of the boundary points."),
    "segment_length": num(None, "Skeleton marching length L (default: 4 × radius).", units="mm", positive=True,
                          hi=1e6),
    "segment_angle": num(45.0, "Skeleton marching angle.", units="°", lo=0.0, hi=180.0, open_lo=True),
    "workers": whole(1, 1, 256, "Parallel per-segment evaluation (a recipe file: at most the cores).",
                     local_only=True),
    "executor": pick(("thread", "process"), "thread", "Workers are threads or processes.", local_only=True),
    "evaluation": pick(("local", "global"), "local", "Per-segment (local) or whole-grid evaluation."),
}

# ------------------------------------------------------------------------------------------------------- ivd


def _method_keys(defaults: dict, limits: dict) -> dict:
    """The ``[params.METHOD]`` keys: overrides of the method's design parameters, typed like their defaults."""
    out = {}
    for k, d in defaults.items():
        help_ = f"Override of {k} (default {d!r})."
        if isinstance(d, str):
            out[k] = Key("string", d, help_, max_len=64)
        elif isinstance(d, int) and not isinstance(d, bool):
            out[k] = whole(d, 1, limits.get(k, 1_000_000), help_)
        elif isinstance(d, float):
            out[k] = num(d, help_, lo=-1e6, hi=1e6)
        else:
            out[k] = Key("any", d, help_, json="array")
    return out


METHODS = ("tpms", "tbss", "tis", "arbf")

#: per-method design parameters for a disc-sized body (mm)
METHOD_DEFAULTS = {
    # 000 ch.2 TPMS infill: P pores, cut to the disc
    "tpms": {"type": "P", "structure": "pore", "porosity": 0.6, "cell_size": 5.0, "voxel": 0.3},
    # 001/000 ch.3 parameterised TPMS in a fitted trivariate B-spline solid
    "tbss": {"type": "P", "structure": "pore", "periods": [4, 4, 2], "resolution": 10,
             "fits": [["sliced", 6], ["sliced", 5], ["sliced", 4], ["sliced", 7], ["sliced", 8], ["radial", 6]]},
    # 002/000 ch.4 TIS-P over a BCC tet mesh of the disc (relative threshold of 002's femur)
    "tis": {"type": "P", "lambda": 1.0, "relative": 0.176, "tets": 300, "resolution": 9},
    # 000 ch.5 ARBF, IMQ basis with c = 0.1, local face-ring solves
    "arbf": {"basis": "imq", "shape": 0.1, "iso": -0.45, "tets": 150, "ring": "face", "resolution": 6},
}

#: largest counts one disc's scaffold may ask for (a disc is a few centimetres across; the job builds one per disc)
DISC_LIMITS = {"tets": 20_000, "resolution": 64}


def _ivd() -> dict:
    return {
        "input": table({
            "path": Key("path", REQUIRED, "Subject folder, image or DICOM series."),
            "segmenter": pick(("classical", "unet"), "classical", "How the discs are segmented."),
            "checkpoint": Key("path", None, "The U-Net checkpoint (segmenter = unet)."),
            "channels": Key("any", None, "1 to 16 channel names to read (default: all found).", json="array"),
        }, "The image."),
        "methods": Key("any", ["tpms"], "Scaffold methods: some of tpms, tbss, tis, arbf, or all.", json="array"),
        "discs": Key("integers", None, "Disc numbers to build (1 = most superior; default: every disc found).",
                     lo=1, hi=1000, max_len=1000),
        "smooth_iterations": whole(10, 0, 10_000, "Taubin smoothing of each disc surface."),
        "reports": flag(False, "A report directory per scaffold (analysis in the disc's domain)."),
        "params": table({m: table(_method_keys(d, DISC_LIMITS), f"Overrides of the {m} method's parameters.")
                         for m, d in METHOD_DEFAULTS.items()}, "Per-method parameter overrides."),
    }


#: job name → its top-level keys
JOBS = {
    "tpms": job(LATTICE, ("mesh", "report", "report_dir", "recipe")),
    "infill": job(INFILL, ("mesh", "report", "report_dir", "recipe")),
    "tbss": job(TBSS, ("mesh", "report", "recipe", "tdf")),
    "hex": job(HEX, ("mesh", "report", "recipe")),
    "tis": job(TIS, ("mesh", "report", "recipe", "tets")),
    "arbf": job(ARBF, ("mesh", "report", "recipe")),
    "vessel": job(VESSEL, ("mesh", "report", "recipe", "centreline", "labelmap")),
    "ivd": job(_ivd(), ("dir", "recipe")),
}
