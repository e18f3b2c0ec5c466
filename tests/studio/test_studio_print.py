"""The studio's Print panel (issue 40, build item 4): profile, slicing in the background, layers, ZIP, report.

Requests go over real HTTP to an in-process server on 127.0.0.1. The slices
the panel serves are checked against the ZIP it downloads and against the
report's own layer areas, read back with Pillow.
"""

from __future__ import annotations

import io
import json
import time
import zipfile

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from test_studio_browser import browser, preview_done, wait  # noqa: E402,F401 - the Chromium fixture
from test_studio_server import api_json, request  # noqa: E402

#: a gyroid sheet of one 2 mm cell: 20 layers of 20 x 20 pixels at 0.1 mm
SMALL = {"job": "tpms", "type": "G", "structure": "sheet", "control": "porosity", "value": 0.7, "cell_size": 2.0,
         "cells": [1, 1, 1], "resolution": 16}


@pytest.fixture(scope="module")
def server():
    from porecad.studio.launcher import make_studio
    from porecad.studio.server import Server
    srv = Server(make_studio(None, threads=1)).start()
    try:
        yield srv
    finally:
        srv.stop()


def wait_slice(srv, n, timeout=300):
    t0 = time.time()
    while time.time() - t0 < timeout:
        status, s = api_json(srv, "GET", "print/status")
        assert status == 200
        if s.get("id") == n and s["state"] != "running":
            return s
        time.sleep(0.1)
    raise AssertionError("the slice did not finish")


def slice_(srv, design=SMALL, **opts):
    status, res = api_json(srv, "POST", "print/slice", {"design": design, **opts})
    assert status == 200, res
    return wait_slice(srv, res["id"])


def test_profile_is_read_like_a_printer_file(server):
    status, prof = api_json(server, "GET", "print/profile")
    assert status == 200 and prof["printer"]["pixel"] == 0.05 and len(prof["directions"]) == 26
    from porecad.printing import printer_from_toml
    assert printer_from_toml(prof["text"]).as_dict() == prof["printer"]  # the text the page shows reads back
    text = 'name = "test"\nbuild = [50.0, 50.0, 50.0]\npixel = 0.1\nlayer = 0.1\nmin_feature = 0.3\n'
    status, res = api_json(server, "POST", "print/profile", {"text": text})
    assert status == 200 and res["printer"]["name"] == "test" and res["printer"]["min_feature"] == 0.3
    bad = {"colour = 1\n": "unknown key 'colour'", "pixel = 0\n": "pixel must be a number",
           "layer = 1e308\n": "layer must be a number", "build = [1, 2]\n": "build must be",
           "pixel = [\n": "not a valid TOML", "#" * 70000: "at most 64 KiB", 'name = "\\ud800"\n': "not a valid"}
    for text, words in bad.items():
        status, res = api_json(server, "POST", "print/profile", {"text": text})
        assert status == 400 and words in res["error"] and "\n" not in res["error"], (text[:20], res)
    status, res = api_json(server, "POST", "print/profile", {"text": 3})
    assert status == 400
    status, res = api_json(server, "GET", "print/profile")
    assert res["printer"]["name"] == "test"  # a refused profile leaves the last good one in use


def test_slice_layers_zip_and_report(server):
    api_json(server, "POST", "print/profile", {"text": "pixel = 0.1\nlayer = 0.1\nmin_feature = 0.3\n"})
    s = slice_(server)
    assert s["state"] == "done", s
    r = s["summary"]
    assert r["route"] == "field" and r["layers"] == 20 and r["image"] == [20, 20] and r["pixel"] == 0.1
    status, data = request(server, "GET", "api/print/zip")
    assert status == 200 and len(data) == s["bytes"]
    z = zipfile.ZipFile(io.BytesIO(data))
    manifest = json.loads(z.read("manifest.json"))
    assert manifest["layer_count"] == 20 and manifest["recipe"]["tpms"]["type"] == "G"
    status, report = api_json(server, "GET", "print/report")
    assert status == 200 and report["layers"] == 20
    from PIL import Image
    for k in (0, 7, 19):
        status, png = request(server, "GET", f"api/print/layer/{k}.png")
        assert status == 200 and png == z.read(f"layers/{k:05d}.png")  # the layer shown is the file's
        grey = np.asarray(Image.open(io.BytesIO(png)), dtype=float)
        area = grey.sum() / 255 * 0.1 ** 2
        assert area == pytest.approx(report["layer_area"][k], rel=0.01)
        assert 0.5 < area < 4.0  # a sheet: part of the 2 x 2 mm layer
    # the findings the panel lists are the report's, by code; the sheet's walls are under 0.3 mm
    codes = [w["code"] for w in r["warning_details"]]
    assert codes == [w["code"] for w in report["warning_details"]] and "thin-wall" in codes
    assert set(r["marks"]) <= set(codes)
    assert all(0 <= m["layer"] < 20 and -0.01 <= m["u"] <= 1.01 and -0.01 <= m["v"] <= 1.01
               for pts in r["marks"].values() for m in pts)
    status, res = request(server, "GET", "api/print/layer/20.png")
    assert status == 404 and b"no layer 20" in res


def test_orientation_auto_and_picked(server):
    api_json(server, "POST", "print/profile", {"text": "pixel = 0.1\nlayer = 0.1\n"})
    long = dict(SMALL, cells=[2, 1, 1])  # 4 x 2 x 2 mm: built along x it is 4 mm high
    s = slice_(server, long, orient=[1, 0, 0])
    assert s["summary"]["layers"] == 40 and s["summary"]["orientation"]["chosen"] == [1.0, 0.0, 0.0]
    s = slice_(server, long, orient="auto")
    o = s["summary"]["orientation"]
    assert len(o["ranking"]) == 5 and o["chosen"] == o["ranking"][0]["direction"]
    height = float(np.abs(o["chosen"]) @ [4.0, 2.0, 2.0])  # the box's extent along the chosen direction
    assert s["summary"]["layers"] == round(height / 0.1) and s["summary"]["height"] == pytest.approx(height, abs=0.1)
    areas = [x["unsupported_area"] for x in o["ranking"]]
    assert areas == sorted(areas)


def test_bad_slice_requests_are_one_line_errors(server):
    api_json(server, "POST", "print/profile", {"text": "pixel = 0.1\nlayer = 0.1\n"})
    for opts, words in (({"pixel": 0}, "the pixel"), ({"layer": -1}, "the layer height"),
                        ({"pixel": 1e308}, "the pixel"), ({"orient": "sideways"}, "`orient`"),
                        ({"orient": [0, 0, 0]}, "`orient`"), ({"orient": ["a", 1, 2]}, "`orient`")):
        status, res = api_json(server, "POST", "print/slice", {"design": SMALL, **opts})
        assert status == 400 and words in res["error"] and "\n" not in res["error"], (opts, res)
    status, res = api_json(server, "POST", "print/slice", {"design": dict(SMALL, value=1.5)})
    assert status == 400 and res.get("field") == "value"
    # a part larger than the build area: refused by the slicer, the message in the status, no file left
    api_json(server, "POST", "print/profile", {"text": "build = [1.0, 1.0, 1.0]\npixel = 0.1\nlayer = 0.1\n"})
    s = slice_(server)
    assert s["state"] == "failed" and "larger than the printer's build volume" in s["error"]
    assert not list((server.studio.session.work / "prints").glob("*.zip"))
    status, _ = request(server, "GET", "api/print/zip")
    assert status == 404


def test_a_new_slice_supersedes_the_running_one(server):
    api_json(server, "POST", "print/profile", {"text": "pixel = 0.02\nlayer = 0.02\n"})
    status, first = api_json(server, "POST", "print/slice", {"design": dict(SMALL, cells=[2, 2, 2]), "orient": "none"})
    assert status == 200
    api_json(server, "POST", "print/profile", {"text": "pixel = 0.1\nlayer = 0.1\n"})
    s = slice_(server)
    assert s["state"] == "done" and s["id"] == first["id"] + 1
    folder = server.studio.session.work / "prints"
    t0 = time.time()
    while len(list(folder.iterdir())) > 1 and time.time() - t0 < 120:  # the first stops at its next step
        time.sleep(0.2)
    assert [p.relative_to(folder).as_posix() for p in folder.rglob("*")] == [str(s["id"]), f"{s['id']}/{s['id']}.zip"]
    # cancelling
    api_json(server, "POST", "print/profile", {"text": "pixel = 0.02\nlayer = 0.02\n"})
    status, res = api_json(server, "POST", "print/slice", {"design": dict(SMALL, cells=[2, 2, 2])})
    assert api_json(server, "POST", "print/cancel")[1]["cancelling"] is True
    now = api_json(server, "GET", "print/status")[1]
    assert now["cancelling"] or now["state"] != "running"
    s = wait_slice(server, res["id"])
    assert s["state"] in ("cancelled", "done")  # done only when it finished before the next progress step
    if s["state"] == "cancelled":
        assert not list(folder.rglob("*"))


def test_marks_and_preview_cap(tmp_path, monkeypatch):
    from porecad.studio import print_panel as pp
    report = {"manifest": {"origin": [1.0, 2.0, 3.0], "pixel_size": 0.5, "image_width": 8, "image_height": 4,
                           "layer_count": 10, "layer_height": 0.25, "first_layer_z": 3.125},
              "warning_details": [
                  {"code": "thin-wall", "values": {"at": [[1.0, 2.0, 3.0], [5.0, 4.0, 5.4]]}},
                  {"code": "mid-air-start", "values": {"at": [[3.0, 3.0]], "z": [4.0]}},
                  {"code": "unsupported-overhang", "values": {"area": 2.0}}]}
    m = pp.marks(report)
    assert m == {"thin-wall": [{"layer": 0, "u": 0.0, "v": 1.0}, {"layer": 9, "u": 1.0, "v": 0.0}],
                 "mid-air-start": [{"layer": 4, "u": 0.5, "v": 0.5}]}
    from PIL import Image
    grey = np.zeros((30, 50), dtype=np.uint8)
    grey[:, :25] = 255
    path = tmp_path / "s.zip"
    with zipfile.ZipFile(path, "w") as z:
        buf = io.BytesIO()
        Image.fromarray(grey).save(buf, format="PNG")
        z.writestr("layers/00000.png", buf.getvalue())
    monkeypatch.setattr(pp, "PREVIEW_PIXELS", 200)
    png, factor = pp.layer_png(path, 0)
    img = np.asarray(Image.open(io.BytesIO(png)))
    assert factor == 3 and img.shape == (10, 17) and img.size <= 200
    assert img[:, :8].min() == 255 and img[:, 9:].max() == 0  # a box average: half covered stays half


# ------------------------------------------------------------------------------------------- in Chromium

@pytest.fixture
def small_studio():
    from porecad.studio.server import Server, Studio
    srv = Server(Studio(design=dict(SMALL), threads=1)).start()
    try:
        yield srv
    finally:
        srv.stop()


def test_print_panel_in_chromium(browser, small_studio, tmp_path):  # noqa: F811 - the fixture imported above
    """The panel driven as a person would: a profile, auto orientation, Slice, the layers, a finding, the ZIP."""
    import os
    import shutil

    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select
    srv, driver = small_studio, browser
    driver.set_window_size(1400, 1800)  # the whole left column in view (and in the screenshot)
    find = lambda i: driver.find_element("id", i)  # noqa: E731
    driver.get(srv.url)
    wait(driver, lambda: len(find("print-orient").find_elements("tag name", "option")) == 28
         and find("f-cells").get_attribute("value") == "1 1 1", what="the form and the Print panel")
    find("print-profile-box").find_element("tag name", "summary").click()
    find("print-profile").clear()
    find("print-profile").send_keys('name = "test resin"\npixel = 0.1\nlayer = 0.1\nmin_feature = 0.3\n')
    find("print-profile-apply").click()
    wait(driver, lambda: "test resin: 100 µm pixel" in find("print-printer").text, what="the profile")
    Select(find("print-orient")).select_by_value("auto")
    wait(driver, lambda: preview_done(driver), what="the preview")  # not competing with it for the 2 cores
    find("print-btn").click()
    wait(driver, lambda: find("print-result").is_displayed() and find("print-canvas").get_attribute("data-layer"),
         timeout=120, what="the slices")
    s = srv.studio.prints.state()
    r = s["summary"]
    n = r["layers"]
    assert f"{n} layers of {r['image'][0]}×{r['image'][1]} px" in find("print-status").text
    # the findings, listed by code with the slicer's sentence
    items = find("print-warnings").find_elements("tag name", "li")
    assert [li.get_attribute("data-code") for li in items] == [w["code"] for w in r["warning_details"]]
    assert "thin-wall" in [w["code"] for w in r["warning_details"]]
    for li, w in zip(items, r["warning_details"]):
        assert w["message"] in li.text
    # the layer slider: the last layer, drawn as the file's grey (mean brightness = the covered fraction)
    find("print-slider").send_keys(Keys.END)
    wait(driver, lambda: find("print-canvas").get_attribute("data-layer") == str(n - 1), what="the last layer")
    assert f"layer {n} of {n}" in find("print-layer-info").text
    report = srv.studio.prints.done()["report"]
    shown = driver.execute_script(
        "const c = document.getElementById('print-canvas'), x = c.getContext('2d');"
        f"const w = {r['image'][0]}, h = {r['image'][1]}, s = Math.min(c.width / w, c.height / h);"
        "const d = x.getImageData((c.width - w * s) / 2 + 1, (c.height - h * s) / 2 + 1, w * s - 2, h * s - 2).data;"
        "let t = 0; for (let i = 0; i < d.length; i += 4) t += Math.min(d[i], d[i + 1], d[i + 2]);"
        "return t / (d.length / 4) / 255;")
    fraction = report["layer_area"][n - 1] / (r["image"][0] * r["image"][1] * r["pixel"] ** 2)
    assert abs(shown - fraction) < 0.05, (shown, fraction)
    # a finding with a place: clicking it shows its layer, marked
    jump = [li for li in items if "jump" in li.get_attribute("class")]
    assert [li.get_attribute("data-code") for li in jump] == list(r["marks"]) and "thin-wall" in r["marks"]
    jump[0].click()
    k = r["marks"][jump[0].get_attribute("data-code")][0]["layer"]
    wait(driver, lambda: find("print-canvas").get_attribute("data-layer") == str(k), what="the finding's layer")
    assert int(find("print-canvas").get_attribute("data-marks")) >= 1
    shot = tmp_path / "print.png"
    find("print").screenshot(str(shot))
    if os.environ.get("PORECAD_PRINT_SCREENSHOT"):
        shutil.copyfile(shot, os.environ["PORECAD_PRINT_SCREENSHOT"])
    from PIL import Image
    assert np.asarray(Image.open(shot).convert("L"), dtype=float).std() > 20
    # the slice ZIP, downloaded by the browser: the form's design, the slices shown
    find("print-zip").click()
    zpath = driver.downloads / "tpms-slices.zip"
    wait(driver, lambda: zpath.is_file() and not list(driver.downloads.glob("*.crdownload")), timeout=60,
         what="the download")
    with zipfile.ZipFile(zpath) as z:
        manifest = json.loads(z.read("manifest.json"))
        assert manifest["layer_count"] == n and manifest["recipe"]["domain"]["cells"] == [1, 1, 1]
        assert manifest["rotation"] == report["rotation"]
