"""Issue 22, pictures a person would look at: `porecad demo` writes the HTML report, its 3D view draws offline.

* The software renderer (:mod:`porecad.analysis.render`) against known
  silhouettes (a sphere's disc, a cube's hexagon) and its cut-away (the
  section colour appears only with a cut); decimation keeps the shape.
* ``porecad demo`` (the README's first command) writes the STL, recipe,
  JSON report and ``demo_report/report.html``; that page is opened from the
  file in headless Chromium (Selenium, as the studio test): the 3D viewer's
  canvas is drawn (not blank), the section slider changes it, and nothing is
  fetched from outside (every resource ``file:`` or ``data:``, no http(s)
  source or link in the page). Without a browser the browser test skips,
  unless ``PORECAD_REQUIRE_BROWSER`` is set (as in CI), where it fails.
  ``PORECAD_REPORT_SCREENSHOT`` names a file to keep the page's screenshot in.
"""

from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest
import trimesh

from porecad.analysis.view_copy import cluster, view_copy
from porecad.analysis.render import SECTION, render

from browser_support import CHROMIUM, DRIVER, browser_or_skip
FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-extensions", "--disable-default-apps", "--no-proxy-server", "--no-default-browser-check",
         "--enable-unsafe-swiftshader", "--allow-file-access-from-files", "--window-size=1200,1000")


def _drawn(img, background=1.0):
    """Share of pixels that differ from the white background."""
    return float((np.abs(img - background).max(axis=-1) > 0.02).mean())


def test_render_sphere_silhouette_is_its_disc():
    m = trimesh.creation.icosphere(subdivisions=4, radius=5.0)
    img = render(m.vertices, m.faces, 200, 200, supersample=1)
    # fitted with a 4 % margin on each side: the disc's diameter is 92 % of the image
    assert _drawn(img) == pytest.approx(np.pi / 4 * 0.92 ** 2, rel=0.03)
    assert img.std() > 0.05  # shaded, not a flat silhouette


def test_render_cube_from_a_corner_is_a_hexagon_and_the_cut_shows_the_section():
    m = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    img = render(m.vertices, m.faces, 240, 240, direction=(1, 1, 1), supersample=1)
    # a cube seen along its diagonal: a regular hexagon, area 3√3/2 s² with s its circumradius;
    # the fit puts the hexagon's height (2 s·cos 30°) or width (2 s) at 92 % of the image
    s = 0.92 * 240 / 2
    assert _drawn(img) * 240 ** 2 == pytest.approx(1.5 * np.sqrt(3) * s ** 2, rel=0.04)
    sec = np.all(np.abs(img - SECTION) < 0.3, axis=-1).mean()
    assert sec < 0.001  # a closed solid shows no cut material
    cut = render(m.vertices, m.faces, 240, 240, direction=(1, 1, 1), cut=((0, 0, 0), (1, 1, 1)), supersample=1)
    assert np.all(np.abs(cut - SECTION) < 0.3, axis=-1).mean() > 0.1  # the hexagonal section, in its colour


@pytest.mark.parametrize("how", ["library", "cluster"])
def test_decimate_keeps_the_shape(how):
    m = trimesh.creation.icosphere(subdivisions=5, radius=3.0)  # 20480 triangles
    if how == "library":
        pytest.importorskip("fast_simplification")
        v, f = view_copy(m.vertices, m.faces, 2000)
    else:
        v, f = cluster(m.vertices, m.faces, 2000)
    assert 500 < len(f) <= 2400 and f.max() < len(v)
    r = np.linalg.norm(np.asarray(v, float), axis=1)
    assert np.all(np.abs(r - 3.0) < 0.15)


@pytest.fixture(scope="module")
def demo():
    """`porecad demo` as a user runs it (a fresh process), in a fresh folder."""
    out = tempfile.mkdtemp(prefix="porecad-demo-")
    try:
        res = subprocess.run([sys.executable, "-m", "porecad.cli", "demo", "-o", out, "--json"], capture_output=True,
                             text=True, encoding="utf-8", timeout=1200)
        assert res.returncode == 0, res.stderr
        yield out, json.loads(res.stdout)
    finally:
        shutil.rmtree(out, ignore_errors=True)


def test_demo_writes_closed_stl_recipe_and_report(demo, run_cli):
    d, r = demo
    assert r["closed"] and r["manifold"] and r["outward"]
    assert 0.55 < r["porosity"] < 0.85 and r["body_volume"] > 5000
    stl = os.path.join(d, "disc_scaffold.stl")
    assert os.path.getsize(stl) == 84 + 50 * r["triangles"]
    assert os.path.exists(os.path.join(d, "disc_scaffold.recipe.toml"))
    with open(os.path.join(d, "disc_scaffold.report.json"), encoding="utf-8") as fh:
        assert json.load(fh)["triangles"] == r["triangles"]
    code, out, err = run_cli("analyze", stl, "--json", "--no-check-intersections")
    a = json.loads(out)
    assert code == 0 and a["closed"] and a["manifold"] and a["triangles"] == r["triangles"]
    assert abs(a["volume"] - r["volume"]) / r["volume"] < 1e-3


def test_demo_report_page_is_self_contained(demo):
    d, r = demo
    rep = os.path.join(d, "demo_report")
    assert r["report_dir"] == rep
    with open(os.path.join(rep, "report.json"), encoding="utf-8") as fh:
        analysis = json.load(fh)
    # measured inside the disc (a field domain), agreeing with the mesh porosity
    assert analysis["domain"] == "field" and abs(analysis["porosity_voxel"] - r["porosity"]) < 0.01
    with open(os.path.join(rep, "report.html"), encoding="utf-8") as fh:
        page = fh.read()
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, re.I)
    assert "<script src" not in page and "<link" not in page
    data = json.loads(re.search(r'<script type="application/json" id="porecad-mesh">(.*?)</script>', page, re.S)[1])
    pos = np.frombuffer(base64.b64decode(data["positions"]), "<f4").reshape(-1, 3)
    idx = np.frombuffer(base64.b64decode(data["indices"]), "<u4").reshape(-1, 3)
    assert data["triangles"] == len(idx) <= 180_000 and data["source_triangles"] == r["triangles"]
    assert idx.max() < len(pos)
    lo, hi = np.asarray(analysis["bounds"])
    assert np.allclose(pos.min(axis=0), lo, atol=0.5) and np.allclose(pos.max(axis=0), hi, atol=0.5)
    for name in ("Mesh quality", "slivers", "finite-element", "trimmed mean", "3D view"):
        assert name in page



def _canvas(driver):
    from matplotlib.image import imread
    url = driver.execute_script("return document.getElementById('porecad-view').toDataURL('image/png');")
    return imread(io.BytesIO(base64.b64decode(url.split(",", 1)[1])), format="png")[..., :3]


def test_demo_report_3d_view_draws_offline_in_chromium(demo, tmp_path):
    webdriver = browser_or_skip()
    from selenium.webdriver.chrome.service import Service
    d, _ = demo
    page = os.path.join(d, "demo_report", "report.html")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="porecad-chromium-")
    for flag in FLAGS + (f"--user-data-dir={profile}",):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    try:
        driver.get("file://" + page)
        t0 = time.time()
        while time.time() - t0 < 120 and not driver.execute_script("return !!(window.porecadViewer && "
                                                                    "window.porecadViewer.drawn);"):
            time.sleep(0.2)
        status = driver.find_element("id", "porecad-view-status").text
        assert driver.execute_script("return !!(window.porecadViewer && window.porecadViewer.drawn);"), status
        img = _canvas(driver)
        assert img.shape[0] > 200 and img.shape[1] > 400
        assert _drawn(img) > 0.05 and img.std() > 0.03, "the 3D view is blank"
        # move the section plane: the picture changes (less of the part, more cut material)
        driver.execute_script("const s = document.getElementById('porecad-section'); s.value = 800; "
                              "s.dispatchEvent(new Event('input'));")
        moved = _canvas(driver)
        assert np.abs(moved - img).mean() > 0.005
        resources = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name);")
        assert all(u.startswith(("file:", "data:", "blob:")) for u in resources), resources
        shot = os.environ.get("PORECAD_REPORT_SCREENSHOT") or str(tmp_path / "report.png")
        driver.save_screenshot(shot)
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
