"""The studio driven in real headless Chromium (issue 24, acceptance 1).

Selenium drives Debian's ``chromium`` through ``chromium-driver`` (both
installed by ``.ci/run``): the page loads from the in-process server, a gyroid
sheet at porosity 0.7 is set in the form, the preview mesh and the porosity
readout change, the femur is uploaded through the file input, the job becomes
an infill of it, the export's mesh and recipe are downloaded by the browser,
and ``porecad build`` of the downloaded recipe (a separate process, the real
command line) gives the identical mesh, which is closed. A screenshot of the
page is saved and checked for content.

Without a browser the test skips, unless ``PORECAD_REQUIRE_BROWSER`` is set
(as in CI), where it fails. ``PORECAD_STUDIO_SCREENSHOT`` names a file to
keep the screenshot in (the README's picture is made this way).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from browser_support import CHROMIUM, DRIVER, browser_or_skip
FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-extensions", "--disable-default-apps", "--no-proxy-server", "--no-default-browser-check",
         "--enable-unsafe-swiftshader", "--window-size=1400,900")
#: the first preview compiles numba kernels when their cache is cold (minutes on a loaded 2-core machine)
SLOW = 600



@pytest.fixture
def browser(tmp_path):
    webdriver = browser_or_skip()
    from selenium.webdriver.chrome.service import Service
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="porecad-chromium-")
    for flag in FLAGS + (f"--user-data-dir={profile}",):
        opts.add_argument(flag)
    downloads = tmp_path / "downloads"
    downloads.mkdir()
    opts.add_experimental_option("prefs", {"download.default_directory": str(downloads),
                                           "download.prompt_for_download": False})
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    driver.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
    driver.downloads = downloads
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture
def studio():
    from porecad.studio.launcher import make_studio
    from porecad.studio.server import Server
    server = Server(make_studio(None, threads=2)).start()
    try:
        yield server
    finally:
        server.stop()


def wait(driver, predicate, timeout=SLOW, what="the page"):
    t0 = time.time()
    last = None
    while time.time() - t0 < timeout:
        try:
            last = predicate()
            if last:
                return last
        except Exception as exc:  # noqa: BLE001 - the DOM changes under us
            last = exc
        time.sleep(0.2)
    status = driver.find_element("id", "preview-status").text
    message = driver.find_element("id", "message").text
    raise AssertionError(f"timed out waiting for {what} (last: {last!r}; status: {status!r}; message: {message!r})")


def set_field(driver, name, value):
    """Type into / choose in a form field the way a person does (the page listens to input and change)."""
    from selenium.webdriver.support.ui import Select
    el = driver.find_element("id", f"f-{name}")
    if el.tag_name == "select":
        Select(el).select_by_value(str(value))
    else:
        el.clear()
        el.send_keys(str(value))


def readout(driver, name):
    text = driver.find_element("id", f"readout-{name}").text.split(" ")[0]
    return float(text) if text not in ("–", "") else None


def part_faces(driver):
    return driver.execute_script("const m = window.porecadStudio.meshes.part; "
                                 "return m ? m.geometry.index.count / 3 : 0;")


def preview_done(driver):
    return driver.execute_script("const s = window.porecadStudio.state; return s.analysis !== null && "
                                 "!document.getElementById('preview-status').textContent.includes('computing');")


def test_studio_in_chromium(browser, studio, tmp_path):
    from porecad.datasets import femur_path
    from porecad.io import read_mesh
    from porecad.mesh.validate import check_solid

    femur = femur_path()
    browser.get(studio.url)
    wait(browser, lambda: readout(browser, "porosity") is not None, what="the first preview")

    # a gyroid sheet: porosity 0.5 first, then 0.7 — the readout and the mesh follow
    set_field(browser, "type", "G")
    set_field(browser, "structure", "sheet")
    set_field(browser, "control", "porosity")
    set_field(browser, "value", 0.5)
    wait(browser, lambda: abs((readout(browser, "porosity") or 0) - 0.5) < 0.03, what="porosity 0.5")
    faces_05 = part_faces(browser)
    set_field(browser, "value", 0.7)
    wait(browser, lambda: abs((readout(browser, "porosity") or 0) - 0.7) < 0.03, what="porosity 0.7")
    wait(browser, lambda: part_faces(browser) != faces_05, what="a new preview mesh")
    wait(browser, lambda: preview_done(browser), what="the analysis")
    assert "0.700" in browser.find_element("id", "readout-target").text
    assert browser.find_element("id", "readout-pore").text != "–"
    assert "G sheet" in browser.find_element("id", "curve").text  # the porosity–threshold curve is drawn

    # a bad parameter is a message in the page, and the page goes on
    set_field(browser, "value", 1.5)
    wait(browser, lambda: "value" in browser.find_element("id", "message").text, what="the error message")
    assert "bad" in browser.find_element("css selector", "[data-field=value]").get_attribute("class")
    set_field(browser, "value", 0.7)
    wait(browser, lambda: not browser.find_element("id", "message").is_displayed(), what="the message to clear")

    # the femur, uploaded through the file input; then the infill job
    browser.find_element("id", "upload-input").send_keys(str(femur))
    wait(browser, lambda: "femur.stl" in browser.find_element("id", "uploads").text, what="the upload")
    assert "femur.stl uploaded" in browser.find_element("id", "message").text
    from selenium.webdriver.support.ui import Select
    Select(browser.find_element("id", "job")).select_by_value("infill")
    set_field(browser, "body", "femur.stl")
    set_field(browser, "cell_size", 12)
    set_field(browser, "voxel", 0.8)
    wait(browser, lambda: "refined" in browser.find_element("id", "preview-status").text
         and "voxel" in browser.find_element("id", "preview-status").text and preview_done(browser),
         what="the femur preview")
    assert 'path = "' in browser.find_element("id", "recipe").get_attribute("textContent")
    por = readout(browser, "window")
    assert por is not None and abs(por - 0.7) < 0.05, por

    # screenshot of the page, checked for content (the 3D view is not blank)
    shot = tmp_path / "studio.png"
    browser.save_screenshot(str(shot))
    keep = os.environ.get("PORECAD_STUDIO_SCREENSHOT")
    if keep:
        shutil.copyfile(shot, keep)
    _check_not_blank(shot, browser)

    # export (mesh and recipe; the HTML report has its own, smaller test), downloaded by the browser
    report_box = browser.find_element("id", "export-report")
    if report_box.is_selected():
        report_box.click()
    browser.find_element("id", "export-btn").click()
    wait(browser, lambda: browser.find_elements("id", "dl-recipe"), what="the export")
    assert "closed and manifold" in browser.find_element("id", "export-status").text
    browser.find_element("id", "dl-mesh").click()
    browser.find_element("id", "dl-recipe").click()
    got = wait(browser, lambda: _downloaded(browser.downloads, ("infill.stl", "infill.toml")), timeout=120,
               what="the downloads")
    mesh, recipe = got

    # porecad build of the downloaded recipe (its body beside it, under the name it gives) = the exported mesh
    rebuild = tmp_path / "rebuild"
    rebuild.mkdir()
    shutil.copyfile(recipe, rebuild / "infill.toml")
    shutil.copyfile(femur, rebuild / "femur.stl")
    proc = subprocess.run([sys.executable, "-m", "porecad", "build", str(rebuild / "infill.toml")],
                          capture_output=True, text=True, timeout=SLOW, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    v1, f1 = read_mesh(mesh)
    v2, f2 = read_mesh(rebuild / "infill.stl")
    assert len(f1) > 1000
    np.testing.assert_array_equal(f1, f2)
    np.testing.assert_array_equal(v1, v2)
    chk = check_solid(v1, f1, check_self_intersections=False)
    assert chk["closed"] and chk["manifold"] and chk["oriented"]


def _downloaded(folder: Path, names):
    paths = [folder / n for n in names]
    if all(p.is_file() for p in paths) and not list(folder.glob("*.crdownload")):
        return paths
    return None


def _check_not_blank(path: Path, driver):
    """The screenshot has the page's colours and, in the 3D view, a rendered part (not the background)."""
    import matplotlib.image as mpimg
    img = mpimg.imread(str(path))[..., :3]
    assert img.shape[0] > 400 and img.shape[1] > 800
    assert float(img.std()) > 0.05
    rect = driver.execute_script("const r = document.getElementById('canvas').getBoundingClientRect(); "
                                 "return [r.left, r.top, r.width, r.height, window.devicePixelRatio];")
    x, y, w, h, dpr = (float(v) for v in rect)
    view = img[int(y * dpr):int((y + h) * dpr), int(x * dpr):int((x + w) * dpr)]
    background = np.array([0xE9, 0xED, 0xF2]) / 255.0
    differs = np.abs(view - background).max(axis=-1) > 0.08
    assert differs.mean() > 0.03, f"the 3D view is blank ({differs.mean():.3%} of its pixels differ)"
    assert len(np.unique((view * 31).astype(int).reshape(-1, 3), axis=0)) > 50  # shaded, not flat
