"""The flying-edges marching-cubes pass (``porecad.mesh._mc_kernel``) against references.

skimage's marching cubes for counts and areas, an independent numpy count
of the case table for the active-cube scan (rows trimmed, 8 cubes a word),
trimesh for closedness, and the same grid cut into 1 or many slabs.
"""

import importlib

import numpy as np
import pytest

from porecad.mesh.mc_tables import CUBE_COUNT, CUBE_CENTRE_COUNT

P = importlib.import_module("porecad.mesh.polygonise")
trimesh = pytest.importorskip("trimesh")

N = 64


def _axes(n=N):
    g = np.linspace(-1.0, 1.0, n)
    return g, g[1] - g[0]


def _field(name, n=N):
    g, _ = _axes(n)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    if name == "sphere":
        f = x * x + y * y + z * z - 0.6 ** 2
    else:  # gyroid, two periods over the box
        a, b, c = 2 * np.pi * x, 2 * np.pi * y, 2 * np.pi * z
        f = np.sin(a) * np.cos(b) + np.sin(b) * np.cos(c) + np.sin(c) * np.cos(a)
    return np.ascontiguousarray(f, dtype=np.float32)


def _mesh(F, caps, chunk_bytes=16 << 20, threads=None, spacing=None):
    nz, ny, nx = F.shape
    h = _axes(N)[1] if spacing is None else spacing
    grid = P.Grid((-1.0, -1.0, -1.0), (h, h, h), (nx, ny, nz))
    return P.polygonise(P.GridArraySampler(F, grid), grid, caps=caps, chunk_bytes=chunk_bytes, threads=threads)


def _tm(res):
    return trimesh.Trimesh(res.vertices, res.faces, process=False)


@pytest.mark.parametrize("name", ["sphere", "gyroid"])
def test_matches_skimage_counts_and_area(name):
    measure = pytest.importorskip("skimage.measure")
    F = _field(name)
    h = _axes()[1]
    res = _mesh(F, caps=False)
    v, f, _, _ = measure.marching_cubes(F, 0.0, spacing=(h, h, h))
    assert abs(len(res.faces) / len(f) - 1) < 0.01
    area = _tm(res).area
    assert abs(area / measure.mesh_surface_area(v, f) - 1) < 0.01
    if name == "sphere":
        m = _tm(res)
        assert m.is_watertight and m.is_winding_consistent and m.volume > 0


@pytest.mark.parametrize("name", ["sphere", "gyroid"])
def test_capped_is_closed_and_manifold(name):
    F = _field(name)
    m = _tm(_mesh(F, caps=True))
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0
    if name == "gyroid":  # half the box by symmetry
        assert abs(m.volume / 8.0 - 0.5) < 1e-3


@pytest.mark.parametrize("caps", [False, True])
def test_seams_one_slab_vs_many(caps):
    F = _field("gyroid")
    plane = 4 * N * N
    one = _mesh(F, caps, chunk_bytes=N * plane, threads=1)
    many = _mesh(F, caps, chunk_bytes=5 * plane, threads=2)
    assert one.stats["slabs"] == 1 and many.stats["slabs"] > 10
    assert len(one.vertices) == len(many.vertices) and len(one.faces) == len(many.faces)
    a, b = _tm(one), _tm(many)
    assert a.area == pytest.approx(b.area, rel=1e-12)
    if caps:
        assert b.is_watertight and b.is_winding_consistent
        assert a.volume == pytest.approx(b.volume, rel=1e-12)
    # the same triangles: sorted rows of vertex positions agree
    ta = np.sort(np.sort(one.vertices[one.faces].reshape(-1, 9), axis=1), axis=0)
    tb = np.sort(np.sort(many.vertices[many.faces].reshape(-1, 9), axis=1), axis=0)
    assert np.array_equal(ta, tb)


def _reference_cube_tris(F, eta):
    """Triangles of marching cubes by the case table, counted with numpy (no caps)."""
    b = (F.astype(np.float64) <= -eta).astype(np.int64)
    case = np.zeros(tuple(s - 1 for s in F.shape), np.int64)
    for c in range(8):
        dx, dy, dz = c & 1, (c >> 1) & 1, (c >> 2) & 1
        case |= b[dz:dz + case.shape[0], dy:dy + case.shape[1], dx:dx + case.shape[2]] << c
    return int(CUBE_COUNT[case].sum()), int(CUBE_CENTRE_COUNT[case].astype(bool).sum())


@pytest.mark.parametrize("seed", range(6))
def test_active_scan_counts_every_cube(seed):
    """Odd widths (not whole words, under one word), uniform rows next to mixed ones."""
    from porecad.mesh._mc_kernel import mesh_slab
    rng = np.random.default_rng(seed)
    nz, ny, nx = int(rng.integers(2, 7)), int(rng.integers(2, 12)), [2, 3, 7, 8, 9, 17][seed]
    F = rng.choice([-1.0, 1.0], size=(nz, ny, nx)).astype(np.float32)
    F[:, rng.random(ny) < 0.3, :] = 1.0       # rows all outside
    F[:, rng.random(ny) < 0.3, :] = -1.0      # rows all inside
    F += rng.uniform(-0.1, 0.1, F.shape).astype(np.float32)
    eta = 1e-6
    v, f, bottom, top, w = mesh_slab(F, 0, np.zeros(3), np.ones(3), np.zeros(6, bool), np.ones(nz), np.ones(ny),
                                     np.ones(nx), 16, eta)
    n_tri, n_centres = _reference_cube_tris(F, eta)
    assert len(f) == n_tri
    assert w == float(np.count_nonzero(F.astype(np.float64) <= -eta))
    # every vertex is on an intersected edge (or a star centre) and used
    assert len(np.unique(f)) == len(v)
    assert np.all(np.diff(bottom[0]) > 0) and np.all(np.diff(top[0]) > 0)


def test_threshold_is_exact_at_eta():
    """float32 samples next to ``-eta`` classify as the float64 rule ``f <= -eta`` says."""
    from porecad.mesh._mc_kernel import mesh_slab
    eta = 1e-5
    t = np.float32(-eta)
    vals = [np.nextafter(t, np.float32(-1)), t, np.nextafter(t, np.float32(1)), np.float32(-1), np.float32(1)]
    F = np.array(vals * 4, np.float32)[:18].reshape(2, 3, 3)
    _, _, _, _, w = mesh_slab(F, 0, np.zeros(3), np.ones(3), np.ones(6, bool), np.ones(2), np.ones(3), np.ones(3),
                              16, eta)
    assert w == float(np.count_nonzero(F.astype(np.float64) <= -eta))


def test_threads_give_the_same_mesh():
    F = _field("gyroid")
    a = _mesh(F, True, chunk_bytes=7 * 4 * N * N, threads=1)
    b = _mesh(F, True, chunk_bytes=7 * 4 * N * N, threads=2)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert a.inside_fraction == b.inside_fraction
    assert {"sample_cpu_s", "mesh_cpu_s", "weld_cpu_s"} <= set(b.stats)
    P.load_kernels()     # loads the kernel a job then uses (on a tiny slab): no error, no output


def test_output_sized_short_is_joined_the_same(monkeypatch):
    """The joined output grows by further blocks when the first slab's rate underestimates the rest."""
    F = _field("gyroid")
    a = _mesh(F, True, chunk_bytes=5 * 4 * N * N, threads=2)
    monkeypatch.setattr(P, "_EST_MARGIN", 0.05)     # far too little room: a block per slab or so
    b = _mesh(F, True, chunk_bytes=5 * 4 * N * N, threads=2)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert b.vertices.flags.c_contiguous and b.faces.flags.c_contiguous and b.faces.dtype == np.int32


def test_mesh_slab_into_given_buffers():
    """``out=`` buffers (the driver's pool) give the same slab as the thread's own, grown when too small."""
    from porecad.mesh._mc_kernel import mesh_slab
    F = _field("gyroid")[:9]
    args = (F, 0, np.zeros(3), np.ones(3), np.ones(6, bool), np.ones(9), np.ones(N), np.ones(N), 16, 1e-6)
    ref = mesh_slab(*args)
    out = [np.empty((5, 3)), np.empty((7, 3), np.int32)]
    got = mesh_slab(*args, out=out)
    assert len(out[0]) >= len(ref[0]) and len(out[1]) >= len(ref[1])
    assert np.shares_memory(got[0], out[0]) and np.shares_memory(got[1], out[1])
    for x, y in zip(ref[:2], got[:2]):
        assert np.array_equal(x, y)
    again = mesh_slab(*args, out=out)       # reused as they are
    assert np.array_equal(again[1], ref[1]) and again[4] == ref[4]


@pytest.mark.parametrize("nx", [2, 3, 8, 9, 31])
def test_trapezoid_rows_count_as_the_weights_say(nx):
    """The trapezoid shortcut (count less half the end bits) gives the weighted sum exactly."""
    from porecad.mesh import _mc_kernel as K
    rng = np.random.default_rng(nx)
    ny = 7
    F = rng.uniform(-1, 1, (1, ny, nx)).astype(np.float32)
    wx = np.ones(nx)
    wx[0] = wx[-1] = 0.5
    wy = rng.uniform(0, 2, ny)
    res = []
    for trap in (True, False):
        E, xe, ye, ze, touched, sv, ts, inb, in64, sq64, rowcnt, acol, acase, arow = K._scratch(ny, nx)
        tot = K._classify_plane(F, 0, 0, np.float32(0.0), inb, in64, sq64, rowcnt, wx, wy, trap)
        res.append((tot, rowcnt[0].copy(), sq64[0].copy()))
    ins = F[0] <= 0
    assert np.array_equal(res[0][1], ins.sum(axis=1)) and np.array_equal(res[0][1], res[1][1])
    assert np.array_equal(res[0][2], res[1][2])
    assert res[0][0] == pytest.approx(float(wy @ (ins @ wx)), rel=1e-15)
    assert res[0][0] == pytest.approx(res[1][0], rel=1e-15)


@pytest.mark.parametrize("caps", [[0, 0, 0, 0, 0, 1], [0, 0, 0, 0, 1, 0]])
def test_end_caps_only_on_one_thread(caps):
    """Slabs without caps leave the caps' scratch a stand-in; the capped last (or first) slab on the same
    thread gets the real one: the mesh is that of one slab."""
    F = _field("gyroid")
    plane = 4 * N * N
    one = _mesh(F, np.array(caps, bool), chunk_bytes=N * plane, threads=1)
    many = _mesh(F, np.array(caps, bool), chunk_bytes=5 * plane, threads=1)
    assert many.stats["slabs"] > 10
    assert np.array_equal(one.vertices, many.vertices) and np.array_equal(one.faces, many.faces)
