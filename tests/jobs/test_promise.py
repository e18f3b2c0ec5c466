"""The promise check (issue 37): one piece, on target, covering the body — or a clear no with --strict.

Small generated solids and bodies only: the check's own cases on crafted
results (no meshing), then the command line on one-cell lattices and a small
bar, measured back from the written file with trimesh.
"""

import json

import numpy as np
import pytest
import trimesh

from porecad.errors import PromiseError
from porecad.findings import codes
from porecad.jobs.contract import Result
from porecad.jobs.promise import Promise, keep_promise


def _box(size, centre=(0.0, 0.0, 0.0)):
    m = trimesh.creation.box(extents=size)
    m.apply_translation(centre)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _join(*meshes):
    vs, fs, n = [], [], 0
    for v, f in meshes:
        vs.append(v)
        fs.append(f + n)
        n += len(v)
    return np.concatenate(vs), np.concatenate(fs)


class _Spec:
    def __init__(self, asked=None, islands=None):
        self.asked, self.islands = asked, islands

    def asked_porosity(self):
        return self.asked


def _result(vertices, faces, domain_volume=None, body=None):
    from porecad.analysis.basic import mesh_report
    report = mesh_report(vertices, faces, domain_volume=domain_volume)
    report["warnings"] = []
    return Result(report, vertices, faces, domain_volume=domain_volume, body=body)


def _check(result, spec=None, **promise):
    keep_promise(result, spec or _Spec(), Promise(**promise))
    return result.report, codes(result.report)


def test_islands_dropped_by_default_kept_with_the_warning():
    two = _join(_box((2, 2, 2)), _box((0.8, 0.8, 0.8), (5, 0, 0)))  # an island of 6 % of the main piece
    r, found = _check(_result(*two, domain_volume=100.0))
    assert r["pieces"] == 1 and r["islands_dropped"] == 1 and "islands" not in found
    assert r["islands_volume_fraction"] == pytest.approx(0.512 / 8.512)
    assert r["volume"] == pytest.approx(8.0) and r["porosity"] == pytest.approx(0.92)  # measured after dropping
    assert found == ["islands-dropped"]  # 6 % of the material lost is more than debris: said, with the numbers
    assert r["warnings"][0].values["volume_fraction"] == pytest.approx(0.512 / 8.512)
    debris = _join(_box((2, 2, 2)), _box((0.4, 0.4, 0.4), (5, 0, 0)))  # 0.8 % of the material: dropped quietly
    r, found = _check(_result(*debris, domain_volume=100.0))
    assert r["islands_dropped"] == 1 and found == []
    r, found = _check(_result(*two, domain_volume=100.0), islands="keep")
    assert r["pieces"] == 2 and r["islands_dropped"] == 0 and found == ["islands"]
    r, found = _check(_result(*_box((2, 2, 2)), domain_volume=100.0), islands="keep")
    assert r["pieces"] == 1 and found == []
    # a job's own default (ARBF's islands key) holds unless the recipe's top-level key says otherwise
    r, found = _check(_result(*two, domain_volume=100.0), _Spec(islands="keep"))
    assert found == ["islands"]
    # a piece of a fifth of the largest within its bounds is an interwoven network, not debris: kept, with the
    # warning; beside it, a separate part: the job is refused (dropping it would leave another part)
    ring = trimesh.creation.torus(3.0, 1.0)
    woven = _join((np.asarray(ring.vertices), np.asarray(ring.faces)), _box((2.2, 2.2, 2.2)))
    r, found = _check(_result(*woven, domain_volume=100.0))
    assert r["pieces"] == 2 and r["islands_dropped"] == 0 and found == ["islands"]
    apart = _join(_box((2, 2, 2)), _box((1.2, 1.2, 1.2), (5, 0, 0)))
    body = _box((8, 3, 3), (2, 0, 0))  # one piece: the part asked for
    with pytest.raises(PromiseError, match="2 separate parts"):
        _check(_result(*apart, domain_volume=100.0, body=body))
    r, found = _check(_result(*apart, domain_volume=100.0, body=body), islands="keep")
    assert r["pieces"] == 2 and "islands" in found
    # unless the body is in as many pieces (two bodies filled, two parts) or there is none (a box of lattice cells,
    # one TPMS cell: its pieces join the next cells')
    bodies = _join(_box((2.2, 2.2, 2.2)), _box((1.4, 1.4, 1.4), (5, 0, 0)))
    for given in (bodies, None):
        r, found = _check(_result(*apart, domain_volume=100.0, body=given))
        assert r["pieces"] == 2 and r["islands_dropped"] == 0 and "islands" in found


def test_porosity_off_against_the_asked_porosity():
    solid = _box((2, 2, 2))  # 8 mm^3 in a 20 mm^3 domain: porosity 0.6
    r, found = _check(_result(*solid, domain_volume=20.0), _Spec(asked=0.6))
    assert found == [] and abs(r["porosity_error"]) < 1e-6
    r, found = _check(_result(*solid, domain_volume=20.0), _Spec(asked=0.5))
    assert found == ["porosity-off"] and r["porosity_error"] == pytest.approx(0.1)
    d = r["warnings"][0].values
    assert d["asked"] == 0.5 and d["achieved"] == pytest.approx(0.6)
    r, found = _check(_result(*solid, domain_volume=20.0), _Spec(asked=None))
    assert found == [] and r["porosity_error"] is None


def test_coverage_and_extents_of_the_body():
    body = _box((10, 10, 10))
    r, found = _check(_result(*_box((10, 10, 10)), domain_volume=1000.0, body=body))
    assert found == [] and r["coverage"] > 0.99 and min(r["extent_coverage"]) > 0.99
    r, found = _check(_result(*_box((10, 10, 4), (0, 0, -3)), domain_volume=1000.0, body=body))
    assert sorted(found) == ["coverage-low", "extent-short"]
    assert r["extent_coverage"] == pytest.approx([1.0, 1.0, 0.4])
    assert 0.4 <= r["coverage"] < 0.7  # generous by the reach (here 2.5 mm of the block)


def test_strict_refuses_any_warning_and_passes_a_clean_solid():
    with pytest.raises(PromiseError, match="porosity-off"):
        _check(_result(*_box((2, 2, 2)), domain_volume=20.0), _Spec(asked=0.5), strict=True)
    r, found = _check(_result(*_box((2, 2, 2)), domain_volume=20.0), _Spec(asked=0.6), strict=True)
    assert found == []


def _tpms(run_cli, out, resolution, *extra):
    return run_cli("tpms", "P", "--structure", "pore", "--porosity", "0.6", "--cells", "1", "1", "1",
                   "--cell-size", "1", "--resolution", resolution, "-o", out, "--json", *extra)


def test_strict_on_the_command_line_refuses_porosity_off_and_writes_on_target(run_cli, tmp_path):
    off = tmp_path / "off.stl"
    code, out, err = _tpms(run_cli, off, 5)  # too coarse for the walls: 0.63 for 0.6
    assert code == 0 and "porosity-off" in codes(json.loads(out)) and off.exists()
    off2 = tmp_path / "off2.stl"
    code, out, err = _tpms(run_cli, off2, 5, "--strict")
    assert code != 0 and not off2.exists()
    assert len(err.strip().splitlines()) == 1 and "porosity-off" in err and "Traceback" not in err
    good = tmp_path / "good.stl"
    code, out, err = _tpms(run_cli, good, 12, "--strict")
    assert code == 0 and good.exists(), err
    r = json.loads(out)
    m = trimesh.load(good)
    assert abs((1 - m.volume / r["domain_volume"]) - r["porosity"]) < 0.002
    assert abs(r["porosity_error"]) <= 0.01


def test_written_file_has_the_pieces_reported(run_cli, tmp_path):
    """A gyroid sheet cut to a box of 2x2x2 cells: the specks the box's faces cut off at its corners go on in the
    next cells (issue 52) — kept without a warning, even with ``--strict``, and the file holds what is reported."""
    args = ("tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "2", "2", "2", "--cell-size", "2",
            "--resolution", "30", "--json")
    out = tmp_path / "one.stl"
    code, text, err = run_cli(*args, "-o", out, "--strict")
    assert code == 0, err
    r = json.loads(text)
    m = trimesh.load(out)
    pieces = [p for p in m.split(only_watertight=False) if p.volume > 0]
    assert r["pieces"] == len(pieces) > 1 and r["islands_dropped"] == 0 and "islands" not in codes(r)
    assert abs((1 - m.volume / r["domain_volume"]) - r["porosity"]) < 0.002
    assert abs(m.volume - r["volume"]) < 0.002 * r["domain_volume"]


def test_a_streamed_mesh_is_held_to_its_porosity(run_cli, tmp_path):
    """Issue 52: a mesh streamed to its file is measured slab by slab: the same porosity error and pieces as in
    memory, porosity-off and islands when it misses (before, a streamed job skipped the checks)."""
    args = ("tpms", "G", "--porosity", "0.6", "--cells", "2", "2", "2", "--resolution", "6", "--islands", "keep",
            "--json")
    reports = []
    for mode in ("--stream", "--no-stream"):
        code, out, err = run_cli(*args, mode, "-o", tmp_path / f"{mode}.stl")
        assert code == 0, err
        reports.append(json.loads(out))
    streamed, in_memory = reports
    assert streamed["porosity_error"] == pytest.approx(in_memory["porosity_error"], abs=1e-9)
    assert streamed["porosity_error"] > 0.1 and "porosity-off" in codes(streamed)
    # its pieces counted slab by slab, joined across the seams: as in memory and as trimesh reads the file
    m = trimesh.load(tmp_path / "--stream.stl")
    split = [p for p in m.split(only_watertight=False) if p.volume > 0]
    assert streamed["pieces"] == in_memory["pieces"] == len(split) > 10 and "islands" in codes(streamed)
    assert streamed["islands_volume_fraction"] == pytest.approx(in_memory["islands_volume_fraction"], abs=1e-6)


def test_lattice_pieces_on_the_domain_faces_kept_loose_ones_dropped():
    """No body: a piece with a vertex on the design domain's faces is the lattice's own; one inside it is debris."""
    from porecad.analysis.domain import BoxDomain
    main = _box((2, 2, 2))
    corner = _box((0.4, 0.4, 0.4), (4.8, 0, 0))   # touches the domain's face x = 5
    loose = _box((0.4, 0.4, 0.4), (3.5, 0, 0))    # inside the domain, touching nothing
    res = _result(*_join(main, corner, loose), domain_volume=1000.0)
    res.domain = BoxDomain((-5, -5, -5), (5, 5, 5))
    r, found = _check(res)
    assert r["pieces"] == 2 and r["islands_dropped"] == 1 and not found
    assert r["volume"] == pytest.approx(8.0 + 0.064)


def test_recipe_keys_strict_and_islands(tmp_path):
    from porecad.errors import RecipeError
    from porecad.jobs import run_recipe
    recipe = {"job": "tpms", "tpms": {"type": "P", "structure": "pore", "porosity": 0.6, "cell_size": 1.0},
              "sampling": {"resolution": 5}, "strict": True, "output": {"mesh": str(tmp_path / "x.stl")}}
    with pytest.raises(PromiseError, match="porosity-off"):
        run_recipe(recipe)
    assert not (tmp_path / "x.stl").exists()
    with pytest.raises(RecipeError, match="islands"):
        run_recipe({**recipe, "islands": "sometimes"})


def test_infill_short_of_the_body_is_flagged(run_cli, tmp_path):
    """Complete cells only (boundary whole) leave the bar's ends and sides empty: coverage-low, extent-short."""
    bar = tmp_path / "bar.stl"
    trimesh.creation.box(extents=(8, 3, 3)).export(bar)
    base = ("infill", bar, "G", "--structure", "pore", "--porosity", "0.6", "--cell-size", "1.4", "--json")
    code, text, err = run_cli(*base, "--boundary", "whole", "-o", tmp_path / "whole.stl", "--strict")
    assert code != 0 and "coverage-low" in err and "extent-short" in err
    assert not (tmp_path / "whole.stl").exists()
    code, text, err = run_cli(*base, "--boundary", "cut", "-o", tmp_path / "cut.stl", "--strict")
    assert code == 0, err
    r = json.loads(text)
    assert r["coverage"] > 0.95 and min(r["extent_coverage"]) > 0.95 and r["pieces"] == 1


def _pinch(tip, gap=0.0):
    """A box and an octahedron whose lowest vertex lies on (or ``gap`` above) the box's top face at ``tip``."""
    x, y = tip
    v = np.array([[x, y, 1.0 + gap], [x + 1, y, 2], [x, y + 1, 2], [x - 1, y, 2], [x, y - 1, 2], [x, y, 3]])
    f = np.array([[0, 2, 1], [0, 3, 2], [0, 4, 3], [0, 1, 4], [5, 1, 2], [5, 2, 3], [5, 3, 4], [5, 4, 1]])
    return _join(_box((2, 2, 2)), (v, f))


@pytest.mark.parametrize("tip", [(0.3, -0.2), (0.0, 0.0), (1.0, 1.0)])  # inside a face, on its diagonal, a corner
def test_written_solid_check_finds_a_vertex_on_a_non_adjacent_face(tip):
    """Touching faces (issue 37): a pinch point is a self-intersection, not a valid solid; a gap is not one."""
    from porecad.mesh.validate import check_solid
    touching = check_solid(*_pinch(tip))
    assert touching["closed"] and touching["manifold"] and touching["self_intersections"] > 0
    assert check_solid(*_pinch(tip, gap=1e-3))["self_intersections"] == 0


def test_tbss_reads_a_body_as_every_job_does_and_a_singular_fit_is_one_line(tmp_path, monkeypatch, one_line_error):
    """Inward normals are turned outward on load (as infill, hex, TIS and ARBF do); a singular fit is a clear no."""
    from porecad.mesh.validate import signed_volume
    from porecad.splines import meshfit
    inward = tmp_path / "inward.stl"
    m = trimesh.creation.box(extents=(6, 4, 3))
    m.invert()
    m.export(inward)
    seen = []

    def singular(vertices, faces, **kw):
        seen.append(signed_volume(vertices, faces))
        raise RuntimeError("Factor is exactly singular")

    monkeypatch.setattr(meshfit, "fit_tbss_to_mesh", singular)
    err = one_line_error("tbss", inward, "G", "--structure", "sheet", "--periods", "2", "2", "2",
                         "-o", tmp_path / "t.stl", match="singular")
    assert "body.fit" in err or "--fit" in err
    assert seen and seen[0] == pytest.approx(72.0)  # read outward: the fit saw a positive volume
    assert not (tmp_path / "t.stl").exists()


def test_a_pinched_vertex_is_split_into_one_per_fan():
    """Two tetrahedra sharing one apex (a bowtie): closed, but not manifold; split, a manifold solid of the same volume."""
    from porecad.mesh.pinch import split_pinched_vertices
    from porecad.mesh.validate import check_solid
    v = np.array([[0, 0, 0], [1, 0, 1], [0, 1, 1], [-1, -1, 1], [1, 0, -1], [-1, -1, -1], [0, 1, -1]], float)
    f = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2], [0, 5, 4], [0, 6, 5], [0, 4, 6], [4, 5, 6]])
    before = check_solid(v, f)
    assert before["closed"] and before["nonmanifold_vertices"] == 1 and not before["manifold"]
    v2, f2, n = split_pinched_vertices(v, f)
    after = check_solid(v2, f2)
    assert n == 1 and len(v2) == 8 and after["manifold"] and after["oriented"] and after["self_intersections"] == 0
    assert after["volume"] == pytest.approx(before["volume"], rel=1e-6)
    assert split_pinched_vertices(v2, f2)[2] == 0  # nothing left to split


def test_corpus_bodies_are_what_their_names_say():
    """The issue-37 corpus: CSG bodies closed and outward of the stated genus; the faulty ones faulty as named."""
    from porecad import datasets
    from porecad.mesh.validate import check_solid
    for name, genus in (("y-tube", 0), ("plate-1cell", 0), ("bracket-2", 2), ("bracket-3", 3), ("bracket-6", 6)):
        c = check_solid(*datasets.body(name))
        assert c["closed"] and c["manifold"] and c["outward"] and c["self_intersections"] == 0, name
        assert c["euler"] == 2 - 2 * genus, name
    assert check_solid(*datasets.body("bracket-inward"))["volume"] < 0
    assert not check_solid(*datasets.body("blob-open"), check_self_intersections=False)["closed"]
    v, f = datasets.body("blob-metres")
    assert float(np.ptp(v, axis=0).max()) < 1.0  # a 100 mm body written in metres
    assert len(datasets.BODIES) >= 20


def test_a_streamed_infill_drops_its_islands_as_in_memory(run_cli, tmp_path):
    """Issue 52: a streamed infill writes the same part as in memory: its islands dropped as it is written (the
    same count), its porosity refined by a second pass when the first misses (within 0.002 of in memory), and
    the file one piece whose volume is the report's."""
    body = trimesh.creation.icosphere(3, radius=1.0)
    body.apply_scale([7.3, 6.1, 5.2])  # an ellipsoid: no face of it is aligned with the cells
    body.export(tmp_path / "ell.stl")
    reports = {}
    for mode in ("--stream", "--no-stream"):
        code, out, err = run_cli("infill", tmp_path / "ell.stl", "G", "--porosity", "0.6", "-L", "1.5", "--voxel",
                                 "0.15", "--json", mode, "-o", tmp_path / f"{mode}.stl")
        assert code == 0, err
        reports[mode] = json.loads(out)
    streamed, in_memory = reports["--stream"], reports["--no-stream"]
    assert streamed["scale"]["stream"] and not in_memory.get("scale")
    assert streamed["islands_dropped"] == in_memory["islands_dropped"] > 0
    assert streamed["pieces"] == in_memory["pieces"] == 1
    assert abs(streamed["porosity"] - in_memory["porosity"]) < 0.002
    assert abs(streamed["porosity"] - 0.6) < 0.01
    m = trimesh.load(tmp_path / "--stream.stl")
    assert len(m.split(only_watertight=False)) == 1
    assert m.volume == pytest.approx(streamed["volume"], rel=1e-6)
    assert streamed["triangles"] == len(m.faces)
    assert not [p for p in tmp_path.iterdir() if "tmp" in p.name]  # the missed pass left nothing behind
