"""Tests for porecad.io: atomic writes and mesh file round trips."""

import os
import zipfile

import numpy as np
import pytest

from porecad.errors import InputError, OutputError, PorecadError
from porecad.io import atomic as atomic_mod
from porecad.io import (
    atomic_write,
    check_output_path,
    meshfiles,
    read_mesh,
    write_mesh,
)

# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------


def cube(size=2.0, origin=(0.5, -1.25, 3.0)):
    """Closed, outward-oriented cube: 8 vertices, 12 triangles."""
    corners = np.array(
        [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=np.float64
    )
    v = corners * size + np.asarray(origin)
    # vertex index = 4x + 2y + z
    quads = [
        (0, 1, 3, 2),  # x = 0, normal -x
        (4, 6, 7, 5),  # x = 1, normal +x
        (0, 4, 5, 1),  # y = 0, normal -y
        (2, 3, 7, 6),  # y = 1, normal +y
        (0, 2, 6, 4),  # z = 0, normal -z
        (1, 5, 7, 3),  # z = 1, normal +z
    ]
    f = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int64)
    return v, f


def octahedron():
    v = (
        np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
        * np.array([1.5, 0.25, 0.1])
        + 0.1
    )  # non-round coordinates
    f = np.array(
        [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    )
    return v, f


def canonical(v, f):
    """Sort vertices lexicographically, rotate each face to start at its
    smallest index (keeping orientation) and sort the faces."""
    v = np.asarray(v, dtype=np.float64)
    order = np.lexsort(v.T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    f = rank[np.asarray(f)]
    shift = np.argmin(f, axis=1)
    f = np.stack([np.roll(row, -s) for row, s in zip(f, shift, strict=True)])
    f = f[np.lexsort(f.T[::-1])]
    return v[order], f


def assert_same_mesh(a, b, exact=True):
    va, fa = canonical(*a)
    vb, fb = canonical(*b)
    assert va.shape == vb.shape
    np.testing.assert_array_equal(fa, fb)
    if exact:
        np.testing.assert_array_equal(va, vb)
    else:
        np.testing.assert_allclose(va, vb, rtol=1e-6, atol=1e-6)


def signed_volume(v, f):
    t = v[f]
    return np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0


# --------------------------------------------------------------------------
# round trips
# --------------------------------------------------------------------------


@pytest.mark.parametrize("mesh", [cube, octahedron])
@pytest.mark.parametrize("ext", ["stl", "ply", "obj", "3mf"])
def test_round_trip(tmp_path, ext, mesh):
    v, f = mesh()
    path = tmp_path / f"m.{ext}"
    assert write_mesh(path, v, f) == path
    v2, f2 = read_mesh(path)
    assert v2.dtype == np.float64 and v2.shape == v.shape
    assert f2.dtype == np.int64 and f2.shape == f.shape
    # STL and PLY store float32; OBJ and 3MF keep float64 exactly
    if ext in ("stl", "ply"):
        v = v.astype(np.float32).astype(np.float64)
    assert_same_mesh((v2, f2), (v, f))
    assert signed_volume(v2, f2) == pytest.approx(signed_volume(v, f))
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]


@pytest.mark.parametrize("ext", ["ply", "obj", "3mf"])
def test_indexed_formats_keep_vertex_order(tmp_path, ext):
    v, f = octahedron()
    write_mesh(tmp_path / f"m.{ext}", v, f)
    v2, f2 = read_mesh(tmp_path / f"m.{ext}")
    np.testing.assert_array_equal(f2, f)
    np.testing.assert_allclose(v2, v, rtol=1e-7)


@pytest.mark.parametrize("ext", ["stl", "ply", "obj", "3mf"])
def test_multi_block_writes(tmp_path, monkeypatch, ext):
    monkeypatch.setattr(meshfiles, "_BLOCK", 5)
    monkeypatch.setattr(meshfiles, "_TEXT_BLOCK", 3)
    v, f = cube()
    write_mesh(tmp_path / f"m.{ext}", v, f)
    assert_same_mesh(read_mesh(tmp_path / f"m.{ext}"), (v, f))


def test_fmt_overrides_extension(tmp_path):
    v, f = cube()
    path = tmp_path / "mesh.dat"
    write_mesh(path, v, f, fmt="PLY")
    assert path.read_bytes().startswith(b"ply\n")
    assert_same_mesh(read_mesh(path, fmt=".ply"), (v, f))


def test_uppercase_extension(tmp_path):
    v, f = cube()
    write_mesh(tmp_path / "M.STL", v, f)
    assert_same_mesh(read_mesh(tmp_path / "M.STL"), (v, f))


# --------------------------------------------------------------------------
# format details
# --------------------------------------------------------------------------


def test_stl_size_header_and_normals(tmp_path):
    v, f = cube()
    path = tmp_path / "c.stl"
    write_mesh(path, v, f)
    data = path.read_bytes()
    assert len(data) == 84 + 50 * len(f)
    assert b"porecad" in data[:80]
    assert not data.startswith(b"solid")
    assert np.frombuffer(data, "<u4", 1, 80)[0] == len(f)
    rec = np.frombuffer(data, dtype=meshfiles._STL_DTYPE, offset=84)
    np.testing.assert_array_equal(rec["v"], v[f].astype(np.float32))
    np.testing.assert_allclose(np.linalg.norm(rec["normal"], axis=1), 1.0, rtol=1e-6)
    centroid = v.mean(axis=0)
    outward = rec["v"].mean(axis=1) - centroid
    assert (np.einsum("ij,ij->i", rec["normal"], outward) > 0).all()
    assert (rec["attr"] == 0).all()


def test_stl_degenerate_normal_is_zero(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 3]])
    write_mesh(tmp_path / "d.stl", v, f)
    rec = np.fromfile(tmp_path / "d.stl", dtype=meshfiles._STL_DTYPE, offset=84)
    np.testing.assert_array_equal(rec["normal"][0], 0.0)
    np.testing.assert_allclose(rec["normal"][1], [0, 0, 1])


def test_ply_header(tmp_path):
    v, f = cube()
    path = tmp_path / "c.ply"
    write_mesh(path, v, f)
    data = path.read_bytes()
    head, body = data.split(b"end_header\n", 1)
    assert b"format binary_little_endian 1.0" in head
    assert b"element vertex 8" in head and b"element face 12" in head
    assert b"property list uchar int vertex_indices" in head
    assert len(body) == 8 * 12 + 12 * 13


def test_obj_text(tmp_path):
    v, f = cube()
    path = tmp_path / "c.obj"
    write_mesh(path, v, f)
    lines = path.read_text(encoding="utf-8").splitlines()
    vl = [ln for ln in lines if ln.startswith("v ")]
    fl = [ln for ln in lines if ln.startswith("f ")]
    assert len(vl) == 8 and len(fl) == 12
    assert fl[0] == "f %d %d %d" % tuple(f[0] + 1)  # 1-based
    assert min(int(t) for ln in fl for t in ln.split()[1:]) == 1


def test_3mf_package(tmp_path):
    v, f = cube()
    path = tmp_path / "c.3mf"
    write_mesh(path, v, f)
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
        assert {"[Content_Types].xml", "_rels/.rels", "3D/3dmodel.model"} <= names
        assert all(i.compress_type == zipfile.ZIP_DEFLATED for i in zf.infolist())
        model = zf.read("3D/3dmodel.model").decode()
    assert 'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02"' in model
    assert 'unit="millimeter"' in model
    assert model.count("<vertex ") == 8 and model.count("<triangle ") == 12


def test_3mf_reads_with_lib3mf(tmp_path):
    import lib3mf

    from porecad.io.implicit_3mf import kept_locale
    v, f = octahedron()
    path = tmp_path / "o.3mf"
    write_mesh(path, v, f)
    model = lib3mf.get_wrapper().CreateModel()
    reader = model.QueryReader("3mf")
    with kept_locale():  # lib3mf's reader sets LC_ALL to C for the whole process: later text reads turn ASCII
        reader.ReadFromFile(str(path))
    assert reader.GetWarningCount() == 0
    objects = model.GetMeshObjects()
    assert objects.MoveNext()
    mesh = objects.GetCurrentMeshObject()
    assert mesh.GetVertexCount() == len(v)
    assert mesh.GetTriangleCount() == len(f)
    assert not objects.MoveNext()


def test_read_3mf_units_and_transform(tmp_path):
    model = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<model unit="centimeter" xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
        '<resources><object id="7" type="model"><mesh><vertices>'
        '<vertex x="0" y="0" z="0"/><vertex x="1" y="0" z="0"/><vertex x="0" y="1" z="0"/>'
        '</vertices><triangles><triangle v1="0" v2="1" v3="2"/></triangles></mesh></object>'
        '</resources><build><item objectid="7" transform="1 0 0 0 1 0 0 0 1 5 0 0"/></build>'
        "</model>"
    )
    path = tmp_path / "t.3mf"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("3D/3dmodel.model", model)
    v, f = read_mesh(path)
    np.testing.assert_allclose(v, [[50, 0, 0], [60, 0, 0], [50, 10, 0]])
    np.testing.assert_array_equal(f, [[0, 1, 2]])


def test_read_ascii_stl_and_off(tmp_path):
    v, f = octahedron()
    lines = ["solid test"]
    for tri in v[f]:
        lines += ["facet normal 0 0 0", "outer loop"]
        lines += ["vertex %r %r %r" % tuple(p) for p in tri.tolist()]
        lines += ["endloop", "endfacet"]
    lines.append("endsolid test")
    (tmp_path / "a.stl").write_text("\n".join(lines) + "\n")
    assert_same_mesh(read_mesh(tmp_path / "a.stl"), (v, f))

    off = ["OFF", f"{len(v)} {len(f)} 0"]
    off += ["%r %r %r" % tuple(p) for p in v.tolist()]
    off += ["3 %d %d %d" % tuple(t) for t in f]
    (tmp_path / "a.off").write_text("\n".join(off) + "\n")
    vv, ff = read_mesh(tmp_path / "a.off")
    np.testing.assert_array_equal(ff, f)
    np.testing.assert_array_equal(vv, v)


def test_read_merges_exact_duplicates_only(tmp_path):
    # two triangles sharing an edge, written with duplicated vertices (an OBJ
    # can do that); a third vertex sits 1e-12 away and must stay separate
    obj = (
        "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
        "v 1 0 0\nv -0.0 1 0\nv 1 1 0\n"
        "v 1.000000000001 1 0\n"
        "f 1 2 3\nf 4 6 5\nf 4 7 5\n"
    )
    (tmp_path / "d.obj").write_text(obj)
    v, f = read_mesh(tmp_path / "d.obj")
    np.testing.assert_array_equal(
        v, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [1.000000000001, 1, 0]]
    )
    np.testing.assert_array_equal(f, [[0, 1, 2], [1, 3, 2], [1, 4, 2]])


# --------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------


def test_write_unknown_extension(tmp_path):
    v, f = cube()
    with pytest.raises(InputError, match="not a supported mesh format"):
        write_mesh(tmp_path / "m.xyz", v, f)
    with pytest.raises(InputError, match="unknown mesh format"):
        write_mesh(tmp_path / "m.stl", v, f, fmt="off")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "vertices, faces",
    [
        (np.zeros((4, 2)), [[0, 1, 2]]),
        (np.zeros((4, 3)), [[0, 1, 2, 3]]),
        (np.zeros((4, 3)), [[0, 1, 4]]),
        (np.zeros((4, 3)), [[-1, 1, 2]]),
        (np.zeros((4, 3)), [[0.0, 1.0, 2.0]]),
        (np.full((4, 3), np.nan), [[0, 1, 2]]),
    ],
)
def test_write_rejects_bad_arrays(tmp_path, vertices, faces):
    with pytest.raises(InputError):
        write_mesh(tmp_path / "m.stl", vertices, faces)
    assert not list(tmp_path.iterdir())


def test_read_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_mesh(tmp_path / "nope.stl")


def test_read_unknown_extension(tmp_path):
    (tmp_path / "m.xyz").write_text("1 2 3\n")
    with pytest.raises(InputError, match="not a supported mesh format"):
        read_mesh(tmp_path / "m.xyz")


def test_read_directory(tmp_path):
    (tmp_path / "d.stl").mkdir()
    with pytest.raises(InputError):
        read_mesh(tmp_path / "d.stl")


GARBAGE = bytes(np.random.default_rng(0).integers(0, 256, 1000, dtype=np.uint8))


@pytest.mark.parametrize("ext", ["stl", "ply", "obj", "off", "3mf"])
@pytest.mark.parametrize(
    "content", [b"", b"   \n", GARBAGE, b"hello world\n"], ids=["empty", "blank", "random", "text"]
)
def test_read_garbage(tmp_path, ext, content):
    path = tmp_path / f"g.{ext}"
    path.write_bytes(content)
    with pytest.raises(InputError, match="not a readable mesh") as info:
        read_mesh(path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("ext", ["stl", "ply", "3mf"])
@pytest.mark.parametrize("keep", [0.3, 0.9])
def test_read_truncated(tmp_path, ext, keep):
    v, f = cube()
    path = tmp_path / f"c.{ext}"
    write_mesh(path, v, f)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(InputError, match="not a readable mesh") as info:
        read_mesh(path)
    assert "\n" not in str(info.value)


def test_read_3mf_bad_index(tmp_path):
    model = (
        '<model xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
        '<resources><object id="1"><mesh><vertices><vertex x="0" y="0" z="0"/></vertices>'
        '<triangles><triangle v1="0" v2="1" v3="2"/></triangles></mesh></object></resources>'
        "</model>"
    )
    path = tmp_path / "b.3mf"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("3D/3dmodel.model", model)
    with pytest.raises(InputError, match="out of range"):
        read_mesh(path)


# --------------------------------------------------------------------------
# output paths and atomic writes
# --------------------------------------------------------------------------


def test_existing_file_refused_without_force(tmp_path):
    v, f = cube()
    path = tmp_path / "c.stl"
    path.write_bytes(b"old")
    with pytest.raises(OutputError, match="already exists"):
        write_mesh(path, v, f)
    assert path.read_bytes() == b"old"
    write_mesh(path, v, f, force=True)
    assert len(path.read_bytes()) == 84 + 50 * len(f)
    assert sorted(os.listdir(tmp_path)) == ["c.stl"]


def test_check_output_path(tmp_path):
    assert check_output_path(tmp_path / "new.stl") == tmp_path / "new.stl"
    (tmp_path / "old.stl").write_bytes(b"x")
    with pytest.raises(OutputError, match="already exists"):
        check_output_path(tmp_path / "old.stl")
    check_output_path(tmp_path / "old.stl", force=True)
    with pytest.raises(OutputError, match="directory"):
        check_output_path(tmp_path, force=True)
    with pytest.raises(OutputError, match="does not exist"):
        check_output_path(tmp_path / "missing" / "a.stl")
    with pytest.raises(OutputError, match="not a directory"):
        check_output_path(tmp_path / "old.stl" / "a.stl")
    assert issubclass(OutputError, PorecadError)


def test_unwritable_directory_simulated(tmp_path, monkeypatch):
    # works as root too: pretend the directory denies write access
    monkeypatch.setattr(atomic_mod.os, "access", lambda *a, **k: False)
    with pytest.raises(OutputError, match="not writable") as info:
        write_mesh(tmp_path / "c.stl", *cube())
    assert "\n" not in str(info.value)
    assert not list(tmp_path.iterdir())


def test_oserror_becomes_output_error(tmp_path, monkeypatch):
    def deny(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(atomic_mod.os, "replace", deny)
    with pytest.raises(OutputError, match="Permission denied") as info:
        write_mesh(tmp_path / "c.ply", *cube())
    assert "\n" not in str(info.value)
    assert not list(tmp_path.iterdir())


def test_oserror_on_create_becomes_output_error(tmp_path, monkeypatch):
    def deny(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(atomic_mod.os, "open", deny)
    with pytest.raises(OutputError, match="cannot create"):
        with atomic_write(tmp_path / "x.bin"):
            pass
    assert not list(tmp_path.iterdir())


def test_atomic_write_success(tmp_path):
    path = tmp_path / "x.bin"
    with atomic_write(path) as fh:
        fh.write(b"hello")
        tmp_names = os.listdir(tmp_path)
        assert len(tmp_names) == 1
        assert tmp_names[0].startswith(".x.bin.tmp-")
    assert path.read_bytes() == b"hello"
    assert os.listdir(tmp_path) == ["x.bin"]


def test_atomic_write_exception_leaves_nothing(tmp_path):
    path = tmp_path / "x.bin"
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write(path) as fh:
            fh.write(b"partial data" * 1000)
            raise RuntimeError("boom")
    assert not list(tmp_path.iterdir())


def test_atomic_write_exception_keeps_old_file(tmp_path):
    path = tmp_path / "x.bin"
    path.write_bytes(b"old")
    with pytest.raises(KeyError):
        with atomic_write(path, force=True) as fh:
            fh.write(b"new")
            raise KeyError("mid-write")
    assert path.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["x.bin"]


def test_write_mesh_exception_mid_write(tmp_path, monkeypatch):
    calls = []

    real_fill = meshfiles.fill_stl_records

    def exploding_fill(v, f, start, out):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("disk on fire")
        real_fill(v, f, start, out)

    monkeypatch.setattr(meshfiles, "_STL_BLOCK", 4)
    monkeypatch.setattr(meshfiles, "NUMPY_STL_FACES", 0)      # the kernel path, as for a large mesh
    monkeypatch.setattr(meshfiles, "fill_stl_records", exploding_fill)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_mesh(tmp_path / "c.stl", *cube())
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("block", [3, 7, 1 << 18])
def test_stl_records_match_numpy_reference(tmp_path, monkeypatch, block):
    # the parallel record kernel against a plain numpy construction, across block seams
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 3)) * 10
    f = rng.integers(0, 40, size=(25, 3))
    f[5] = (1, 1, 2)  # degenerate: zero normal
    monkeypatch.setattr(meshfiles, "_STL_BLOCK", block)
    write_mesh(tmp_path / "small.stl", v, f)              # a small mesh: numpy records
    monkeypatch.setattr(meshfiles, "NUMPY_STL_FACES", 0)  # a large one: the compiled kernel
    write_mesh(tmp_path / "r.stl", v, f)
    data = (tmp_path / "r.stl").read_bytes()
    assert (tmp_path / "small.stl").read_bytes() == data
    assert int(np.frombuffer(data[80:84], "<u4")[0]) == len(f)
    rec = np.frombuffer(data[84:], dtype=meshfiles._STL_DTYPE)
    tri = v[f]
    assert np.array_equal(rec["v"], tri.astype(np.float32))
    assert np.allclose(rec["normal"], meshfiles._unit_normals(tri).astype(np.float32), atol=1e-7)
    assert np.all(rec["normal"][5] == 0) and np.all(rec["attr"] == 0)


def test_streamed_stl_equals_plain_stl(tmp_path, monkeypatch):
    # the page-cache-bounded writer (sync_file_range + fadvise) must write the same bytes
    from porecad.io import streaming
    rng = np.random.default_rng(5)
    v = rng.normal(size=(200, 3))
    f = rng.integers(0, 200, size=(1000, 3))
    monkeypatch.setattr(meshfiles, "_STL_BLOCK", 64)
    write_mesh(tmp_path / "plain.stl", v, f)                # numpy records (a small mesh)
    monkeypatch.setattr(meshfiles, "NUMPY_STL_FACES", 0)    # the kernel and the streamed writer
    monkeypatch.setattr(streaming, "STREAM_MIN_BYTES", 0)
    seen = []
    real_write = streaming.StreamedWriter.write

    def spy(self, data):
        seen.append(self.enabled)
        real_write(self, data)

    monkeypatch.setattr(streaming.StreamedWriter, "write", spy)
    write_mesh(tmp_path / "streamed.stl", v, f)
    assert len(seen) == 16
    if streaming._sync_file_range is not None:
        assert seen[0]  # the streaming path ran (Linux)
    assert (tmp_path / "streamed.stl").read_bytes() == (tmp_path / "plain.stl").read_bytes()


def test_atomic_write_caller_closes_file(tmp_path):
    path = tmp_path / "x.bin"
    with atomic_write(path) as fh:
        fh.write(b"abc")
        fh.close()
    assert path.read_bytes() == b"abc"


def test_atomic_write_file_mode_follows_umask(tmp_path):
    if os.name != "posix":
        pytest.skip("POSIX permissions")
    old = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "x.bin") as fh:
            fh.write(b"x")
    finally:
        os.umask(old)
    assert (tmp_path / "x.bin").stat().st_mode & 0o777 == 0o644
