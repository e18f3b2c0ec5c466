"""``porecad vessel``: implicit vessel models from centrelines or images (document 003 ch. 3–4)."""

from __future__ import annotations

import os

import click

from ..errors import InputError
from .console import run_job
from .options import keyed_in, output_options, outputs

option = keyed_in("vessel")

EXAMPLES = """
\b
Examples:
  porecad vessel tree.json --voxel 0.1 -o tree.stl --json
  porecad vessel centerlines.vtp --blend 2,0.2 --voxel 0.1 -o lumen.stl
  porecad vessel artery.swc --wall 0.1,0.3,0.2 --porous-layer 2 --pore-type G --cell-size 0.3 \\
      --voxel 0.04 -o graft.stl --report graft.json
  porecad vessel --image segmented.nii.gz --voxel 0.2 -o vessel.stl
  porecad vessel centreline.json --image ct.mha --frame auto --voxel 0.5 -o aorta.stl
  porecad vessel --image ct.mha --seed 10 -20 30 --seed 12 -18 90 --voxel 0.5 -o aorta.stl
  porecad vessel rough-centreline.json --points wall-points.xyz --voxel 0.1 -o fitted.stl
  porecad vessel --image ct.nrrd --seeds F.mrk.json --voxel 0.5 -o aorta.stl \\
      --centreline-out "Centerline model.vtp" --labelmap-out Segmentation.seg.nrrd   # 3D Slicer's files
"""


def _floats(text, what):
    try:
        vals = [float(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{what} takes comma-separated numbers, got {text!r}") from None
    return vals


def vessel_recipe(centreline, image, wall, porous_layer, pore_type, cell_size, blend, blend_kind, voxel, out,
                  report, trim_ends, segment_length, segment_angle, workers, executor, evaluation,
                  threshold, points=None, fit=None, recipe_out=None, frame=None, seeds=(), seeds_file=None,
                  frame_out=None, centreline_out=None, labelmap_out=None) -> dict:
    """The recipe of a ``porecad vessel`` command line."""
    if not centreline and not image:
        raise InputError("give a CENTRELINE (.vtp .swc .json), an --image IMG, or both")
    if centreline:
        if not os.path.exists(centreline):
            raise InputError(f"{centreline}: no such file")
        if seeds or seeds_file:
            raise InputError("--seed finds a vessel in an --image without a CENTRELINE; give one or the other")
        inp = {"kind": "centreline", "path": centreline}
        if points:
            inp["points"] = points
        if image:
            if not os.path.exists(image):
                raise InputError(f"{image}: no such file")
            inp["image"] = image
        if frame:
            inp["frame"] = frame
    else:
        if frame:
            raise InputError("--frame is the CENTRELINE's frame; there is no centreline (--frame-out sets the output's)")
        if not os.path.exists(image):
            raise InputError(f"{image}: no such file")
        if points:
            raise InputError("--points fits a CENTRELINE to a boundary cloud; it does not go with --image")
        inp = {"kind": "image", "path": image}
        if threshold is not None:
            inp["threshold"] = threshold
        if seeds and seeds_file:
            raise InputError("give the seeds as --seed X Y Z or as --seeds FILE, not both")
        if seeds:
            inp["seeds"] = [list(s) for s in seeds]
        if seeds_file:
            inp["seeds_file"] = seeds_file
    if blend_kind == "li":
        bl = blend if blend is not None else "2,0.2"
    else:
        bl = {"kind": blend_kind}
        if blend is not None:
            raise InputError("--blend n,delta is for --blend-type li")
    recipe = {"job": "vessel", "input": inp, "voxel": voxel, "blend": bl, "workers": workers,
              "executor": executor, "evaluation": evaluation, "segment_angle": segment_angle,
              "output": outputs(out, report, recipe_out, centreline=centreline_out, labelmap=labelmap_out)}
    if frame_out:
        recipe["frame_out"] = frame_out
    if fit is not None:
        recipe["fit"] = fit
    if segment_length is not None:
        recipe["segment_length"] = segment_length
    if wall:
        recipe["wall"] = _floats(wall, "--wall")
    if porous_layer is not None or pore_type is not None:
        if porous_layer is None:
            raise InputError("--pore-type needs --porous-layer K")
        recipe["porous"] = {"layer": porous_layer, "cell_size": cell_size}
        if pore_type is not None:
            recipe["porous"]["type"] = pore_type
    if trim_ends is not None:
        recipe["trim_ends"] = trim_ends
    return recipe


@click.command(epilog=EXAMPLES)
@click.argument("centreline", required=False)
@click.option("--image", type=click.Path(dir_okay=True),
              help="An image (NIfTI, MHA, ...): segmented, or grey (contrast CT, MRA) with CENTRELINE or --seed.")
@option("input.frame", "--frame", default=None, help="The CENTRELINE's frame, LPS (ITK's) or RAS (VMTK's and 3D Slicer's older files: x, y negated) "
            "[default: auto, the file's own, else with --image the one in which it runs inside the lumen].")
@option("frame_out", "--frame-out", help="Frame of every output [default: the input's: the centreline's, or the seeds' (--seed: the image's "
            "LPS)]; the report states it.")
@option("input.seeds_file", "--seeds", "seeds_file", type=click.Path(dir_okay=False), metavar="FILE",
       help="With --image alone: the seeds from a 3D Slicer markups file (.mrk.json), in its own frame.")
@option("output.centreline", "--centreline-out", "centreline_out", type=click.Path(dir_okay=False),
       help="Also write the model's centreline (.vtp, MaximumInscribedSphereRadius, SPACE) for 3D Slicer / VMTK.")
@option("output.labelmap", "--labelmap-out", "labelmap_out", type=click.Path(dir_okay=False),
       help="Also write the model as a labelmap on the --image's grid (.nrrd, .seg.nrrd).")
@option("input.seeds", "--seed", "seeds", type=float, nargs=3, multiple=True, metavar="X Y Z",
       help="With --image alone: a point in the vessel (mm, the image's physical frame); repeat it, one per "
            "vessel end (two at least).")
@option("input.threshold", "--threshold", type=float, help="Image foreground threshold [default: halfway between the "
                                             "background and foreground plateaus].")
@option("input.points", "--points", "points", type=click.Path(dir_okay=False),
              help="Boundary point cloud of the lumen wall (x y z text, .npy, or a mesh's vertices): the "
                   "CENTRELINE's positions and radii are fitted to it.")
@option("wall", "--wall", help="Wall layer thicknesses in mm from the lumen out, e.g. 0.1,0.3,0.2 "
                             "(intima, media, adventitia). Without it the lumen is built as a solid.")
@option("porous.layer", "--porous-layer", type=int, help="Layer number (1 = innermost) made porous.")
@option("porous.type", "--pore-type", default=None, help="TPMS type (G, P, D, ...) or a 003 periodic field "
                                  "(ellipsoids, irregular, boxes) [default: G].")
@option("porous.cell_size", "--cell-size", type=float, help="Period of the porous field in mm.")
@option("blend", "--blend", default=None, help="Li's shape-preserving union parameters n,delta [default: 2,0.2] (003 eq. 2.12).")
@option("blend.kind", "--blend-type", "blend_kind", help="Blend between branches (003 §2.4.5).")
@option("voxel", "--voxel", type=float, help="Grid spacing in mm.")
@option("trim_ends", "--trim-ends/--no-trim-ends", default=None,
              help="Cut open ends flat by planes [default: on with --wall].")
@option("segment_length", "--segment-length", type=float,
       help="Skeleton marching length L in mm [default: 4 × radius].")
@option("segment_angle", "--segment-angle", type=float, help="Skeleton marching turning angle K in degrees.")
@option("workers", "--workers", type=int, help="Parallel per-segment evaluation.")
@option("executor", "--executor")
@option("fit", "--fit", help="Local implicit per segment: a thin-plate RBF fit to the boundary points (of --image or "
                   "--points), 003's direct RBF fit with an ellipsoid constraint, or a swept-radius tube "
                   "[default: rbf where boundary points are known, else tube].")
@option("evaluation", "--evaluation", help="Segments on their bounding boxes (local) or on the whole grid (global).")
@output_options()
def vessel(centreline, image, frame, frame_out, seeds_file, centreline_out, labelmap_out, seeds, threshold, points, wall, porous_layer, pore_type, cell_size, blend, blend_kind, voxel,
           trim_ends, segment_length, segment_angle, workers, executor, fit, evaluation, out, report, recipe_out,
           force, as_json):
    """Build a vessel model (lumen solid, or a layered porous wall) from a CENTRELINE graph with radii
    (.vtp VMTK centreline, .swc, .json) or a segmented --image (document 003)."""
    recipe = vessel_recipe(centreline, image, wall, porous_layer, pore_type, cell_size, blend, blend_kind, voxel,
                           out, report, trim_ends, segment_length, segment_angle, workers, executor, evaluation,
                           threshold, points, fit, recipe_out, frame, seeds, seeds_file, frame_out,
                           centreline_out, labelmap_out)
    run_job(recipe, force, as_json)
