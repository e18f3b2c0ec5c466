"""Vessels from a thoracic contrast CT (issue 55): the arch phantom, tube-following paths, frames, 3D Slicer files."""

import json

import numpy as np
import pytest

from porecad.vessels.arch_phantom import arch_phantom
from porecad.vessels.ct_phantom import bone_distances, to_ras, write_ct_phantom
from porecad.vessels.local_fields import tube_distance
from test_vessel_ct import inside_at_voxel_centres, scores

R_TRUE = 6.0


@pytest.fixture(scope="module")
def arch(tmp_path_factory):
    folder = tmp_path_factory.mktemp("arch")
    ph = arch_phantom(R_TRUE, seed=2)
    return ph, write_ct_phantom(folder, ph, "lps"), folder


def surface_distance(mesh, X, n=300_000):
    """Unsigned distance of points ``X`` to ``mesh`` (to within ~0.05 mm: the nearest of ``n`` surface samples)."""
    import trimesh
    from scipy.spatial import cKDTree
    S, _ = trimesh.sample.sample_surface_even(mesh, n, seed=1)
    return cKDTree(S).query(np.asarray(X).reshape(-1, 3))[0]


def _voxels(ph):
    h, o = np.asarray(ph.geometry["spacing"]), np.asarray(ph.geometry["origin"])
    return o + np.argwhere(np.ones(ph.array.shape, bool)) * h


def test_arch_phantom_has_a_chamber_at_the_root_and_a_spine_along_the_descending_part(arch):
    ph, _, _ = arch
    X = _voxels(ph)
    dv, dc = ph.distance(X), tube_distance(X, *ph.chamber)
    db, _ = bone_distances(X, ph.bone)
    assert (np.abs(dv) + np.abs(dc)).min() < 1.5 and (np.abs(dv) + np.abs(db)).min() < 1.0
    assert (np.abs(dc) + np.abs(db)).min() < 1.0                    # heart and spine touch: the shortcut
    lumen, chamber = ph.array.ravel()[dv < -1], ph.array.ravel()[dc < -1]
    assert abs(np.median(lumen) - np.median(chamber)) < 10        # as bright as the lumen
    assert ph.geometry["spacing"][2] == 1.5
    assert ph.axis[0][:, 2].max() > ph.ends[:, 2].max() + 3 * R_TRUE   # the arch climbs far above both ends


def test_two_seeds_at_the_ends_follow_the_arch(arch, run_json):
    ph, p, folder = arch
    out = folder / "seeds.stl"
    a, b = ph.ends
    r = run_json("vessel", "--image", p["ct"], "--seed", *a, "--seed", *b, "--voxel", "0.6", "-o", out,
                 "--centreline-out", folder / "lps.vtp", "--labelmap-out", folder / "lps.nrrd")
    s = scores(out, ph)
    assert s["closed"] and s["dice"] >= 0.90 and s["precision"] >= 0.95, s
    assert r["input"]["radius_max"] <= 1.5 * R_TRUE and r["branches"] == 1
    assert not r["warnings"] and r["frame"] == "LPS"


def test_markups_seeds_in_ras_give_ras_outputs_and_slicer_files_read_back(arch, run_json):
    import SimpleITK as sitk
    import trimesh
    from scipy.spatial import cKDTree
    vtk = pytest.importorskip("vtk")
    ph, p, folder = arch
    seeds = to_ras(ph.ends)
    mrk = {"@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/"
                      "Schema/markups-schema-v1.0.3.json#",
           "markups": [{"type": "Fiducial", "coordinateSystem": "RAS",
                        "controlPoints": [{"id": str(k + 1), "label": f"F-{k + 1}", "position": list(P)}
                                          for k, P in enumerate(seeds)]}]}
    (folder / "F.mrk.json").write_text(json.dumps(mrk))              # 3D Slicer's file names, in and out
    out, vtp, nrrd = folder / "ras.stl", folder / "Centerline model.vtp", folder / "Segmentation.seg.nrrd"
    r = run_json("vessel", "--image", p["ct"], "--seeds", folder / "F.mrk.json", "--voxel", "0.6", "-o", out,
                 "--centreline-out", vtp, "--labelmap-out", nrrd)
    assert r["frame"] == "RAS" and r["input"]["frame"] == "ras"
    m = trimesh.load(str(out), force="mesh")
    # the same solid as from the same seeds given in LPS, in RAS (x, y negated): meet the acceptance there
    lps = trimesh.Trimesh(to_ras(m.vertices), m.faces)
    lps.export(str(folder / "back-to-lps.stl"))
    s = scores(folder / "back-to-lps.stl", ph)
    assert s["dice"] >= 0.90 and s["precision"] >= 0.95, s
    # the centreline as VTK reads it: RAS, its radii, inside the solid
    rd = vtk.vtkXMLPolyDataReader()
    rd.SetFileName(str(vtp))
    rd.Update()
    pd = rd.GetOutput()
    assert pd.GetFieldData().GetAbstractArray("SPACE").GetValue(0) == "RAS"
    P = np.array([pd.GetPoint(i) for i in range(pd.GetNumberOfPoints())])
    Rad = np.array([pd.GetPointData().GetArray("MaximumInscribedSphereRadius").GetValue(i) for i in range(len(P))])
    assert np.all(np.abs(Rad - R_TRUE) < 1.0) and np.median(surface_distance(m, P)) > 0.8 * R_TRUE
    assert np.abs(ph.distance(to_ras(P)) + R_TRUE).max() < 1.5      # on the true axis (RAS back to LPS)
    # the same file through porecad's own XML reader (no VTK): the same points and radii
    from porecad.vessels.readers import read_centreline
    g = read_centreline(vtp)
    assert g.info.get("frame") == "ras" and len(g.points) <= len(P)
    dist, j = cKDTree(P).query(g.points)
    assert dist.max() < 1e-9 and np.allclose(g.radii, Rad[j])
    # the centreline's tube (its points swept by its radii) and the solid: the same surface to half a voxel
    S, _ = trimesh.sample.sample_surface(m, 4000, seed=0)
    gap = np.abs(tube_distance(S, P, Rad))
    half = 0.5 * min(ph.geometry["spacing"])
    assert np.median(gap) <= half and gap.mean() <= half, (gap.mean(), np.median(gap))
    # the labelmap as SimpleITK reads it: the image's grid, the solid's voxels to half a voxel
    im = sitk.ReadImage(str(nrrd))
    assert np.allclose(im.GetOrigin(), ph.geometry["origin"]) and np.allclose(im.GetSpacing(), ph.geometry["spacing"])
    lab = sitk.GetArrayFromImage(im).transpose(2, 1, 0).astype(bool)
    _, inside = inside_at_voxel_centres(folder / "back-to-lps.stl", ph)
    differ = _voxels(ph)[(lab != inside).ravel()]
    near = surface_distance(lps, differ) if len(differ) else np.zeros(1)
    assert len(differ) < 0.01 * inside.sum() and near.max() <= 0.5 * min(ph.geometry["spacing"]), near.max()
    ijk = np.rint((to_ras(P) - ph.geometry["origin"]) / ph.geometry["spacing"]).astype(int)
    assert lab[tuple(ijk.T)].all()                                  # the centreline lies in the labelmap


def test_path_forced_across_the_chamber_warns_where_it_leaves_the_vessel(arch):
    from porecad.vessels.ct_segment import Volume, guide_by_image
    from porecad.vessels.seed_path import seed_centreline
    from porecad.vessels.tube_path import not_tube_findings
    ph, _, _ = arch
    vol = Volume(ph.array, ph.geometry)
    S = np.stack([ph.chamber[0].mean(0), ph.ends[1]])            # a seed in the heart invites the crossing
    g, _ = seed_centreline(S, vol)
    guide_by_image(g, vol, "lps")
    found = not_tube_findings(g, g.tube_map.tubeness(g.points))
    assert [f.code for f in found] == ["path-not-tube"]
    at = np.array([found[0].values["at"]])
    assert ph.distance(at)[0] > R_TRUE / 2 and tube_distance(at, *ph.chamber)[0] < 0   # in the chamber
    assert found[0].values["seed"] == 1 and "move seed 1" in found[0].message   # the seed in the chamber
    # the good pair finds no such stretch
    g, _ = seed_centreline(ph.ends, vol)
    guide_by_image(g, vol, "lps")
    assert not not_tube_findings(g, g.tube_map.tubeness(g.points))


def test_path_not_tube_refuses_with_strict(arch, run_cli):
    ph, p, folder = arch
    a, b = ph.chamber[0].mean(0), ph.ends[1]
    out = folder / "strict.stl"
    code, _, err = run_cli("vessel", "--image", p["ct"], "--seed", *a, "--seed", *b, "--voxel", "1.0", "-o", out,
                           "--fit", "tube", "--strict")
    assert code != 0 and "path-not-tube" in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_vmtk_centreline_with_and_without_image_in_one_frame(arch, run_json):
    import trimesh
    from porecad.io.slicer import write_centreline_vtp
    ph, p, folder = arch
    g = ph.graph
    vtp = folder / "vmtk-ras.vtp"                                   # VMTK-style: RAS, no frame in the file
    write_centreline_vtp(vtp, g.branches(), to_ras(g.points), g.radii, None)
    r0 = run_json("vessel", vtp, "--voxel", "0.8", "-o", folder / "plain.stl")
    r1 = run_json("vessel", vtp, "--image", p["ct"], "--voxel", "0.8", "-o", folder / "image.stl")
    assert r0["frame"] == "as-input" and r1["frame"] == "RAS" and r1["input"]["frame"] == "ras"
    m0, m1 = (trimesh.load(str(folder / n), force="mesh") for n in ("plain.stl", "image.stl"))
    msd = [surface_distance(b, trimesh.sample.sample_surface(a, 4000, seed=0)[0], n=150_000).mean()
           for a, b in ((m1, m0), (m0, m1))]                          # both ways
    assert max(msd) <= 1.0, msd
    r2 = run_json("vessel", vtp, "--frame", "ras", "--frame-out", "lps", "--voxel", "0.8", "-o", folder / "l.stl")
    m2 = trimesh.load(str(folder / "l.stl"), force="mesh")
    assert r2["frame"] == "LPS" and np.allclose(m2.bounds[:, 2], m0.bounds[:, 2])
    # the STL's 80-byte header says the frame as 3D Slicer reads it (SPACE=...); none when it is not known
    head = {n: (folder / n).read_bytes()[:80] for n in ("plain.stl", "image.stl", "l.stl")}
    assert b"SPACE=" not in head["plain.stl"] and b"SPACE=RAS" in head["image.stl"] and b"SPACE=LPS" in head["l.stl"]
    assert np.allclose(np.sort(-m2.bounds[:, :2], axis=0), m0.bounds[:, :2], atol=1e-3)


def _markups(path, kind, points, frame):
    path.write_text(json.dumps({"markups": [{"type": kind, "coordinateSystem": frame, "controlPoints": [
        {"position": list(map(float, P))} for P in points]}]}))
    return path


def test_markups_curve_as_centreline_with_image(arch, run_json):
    ph, p, folder = arch
    curve = _markups(folder / "C.mrk.json", "Curve", to_ras(ph.axis[0][::4]), "RAS")
    r = run_json("vessel", curve, "--image", p["ct"], "--voxel", "0.8", "-o", folder / "curve.stl",
                 "--frame-out", "lps")
    assert r["input"]["frame"] == "ras" and r["frame"] == "LPS"
    s = scores(folder / "curve.stl", ph)
    assert s["dice"] >= 0.90 and s["precision"] >= 0.95, s


def test_bad_slicer_inputs_and_outputs_are_one_line(arch, run_cli, tmp_path):
    from porecad.io.slicer import write_centreline_vtp
    ph, p, _ = arch
    write_centreline_vtp(tmp_path / "c.vtp", ph.graph.branches(), ph.graph.points, ph.graph.radii, "LPS")
    cases = [
        (["vessel", "--image", p["ct"], "--seeds", _markups(tmp_path / "one.mrk.json", "Fiducial", ph.ends[:1], "LPS")],
         "2 to"),
        (["vessel", "--image", p["ct"], "--seeds", _markups(tmp_path / "xyz.mrk.json", "Fiducial", ph.ends, "XYZ")],
         "LPS or RAS"),
        (["vessel", _markups(tmp_path / "c.mrk.json", "Curve", ph.axis[0][::4], "LPS")], "no radii"),
        (["vessel", tmp_path / "c.vtp", "--labelmap-out", tmp_path / "l.nrrd"], "labelmap"),
    ]
    (tmp_path / "bad.mrk.json").write_text("{not json")
    cases.append((["vessel", "--image", p["ct"], "--seeds", tmp_path / "bad.mrk.json"], "markups"))
    for args, words in cases:
        code, _, err = run_cli(*args, "--voxel", "1", "-o", tmp_path / "o.stl")
        assert code != 0 and words in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "o.stl").exists()
