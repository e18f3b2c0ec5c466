"""The HTML report in a real browser (issue acceptance: renders offline, every image loaded and not blank).

The report directory is served on 127.0.0.1 (same origin, so the canvas the
check draws the images on is not tainted) and a copy of report.html with a
check script appended is loaded in headless Chromium (Debian ``chromium``,
installed by ``.ci/run``). The script writes a JSON verdict into the DOM,
which ``--dump-dom`` prints.

Without a browser the tests skip, unless ``PORECAD_REQUIRE_BROWSER`` is set
(as in CI), where they fail. ``PORECAD_CHROMIUM`` names the browser binary.
"""

import contextlib
import functools
import html
import io
import json
import os
import re
import shutil
import subprocess
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from porecad.analysis.report import OPTIONAL_REPORT_FILES, REPORT_FILES, analyze_mesh, write_report
from porecad.cli import main
from porecad.errors import InputError

pytest.importorskip("matplotlib")

CHECK_PAGE = "_browser_check.html"
# without the background-networking flags chromium waits on the closed network
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-extensions", "--disable-default-apps", "--no-proxy-server",
                  "--no-default-browser-check", "--mute-audio")

CHECK_SCRIPT = """
<script>
window.addEventListener("load", () => {
  const out = {images: [], resources: [], error: null};
  try {
    for (const img of Array.from(document.images)) {
      const r = {src: img.getAttribute("src"), complete: img.complete, width: img.naturalWidth,
                 height: img.naturalHeight, non_background: 0, colours: 0, std: 0};
      if (img.complete && img.naturalWidth > 0) {
        const c = document.createElement("canvas");
        c.width = img.naturalWidth;
        c.height = img.naturalHeight;
        const g = c.getContext("2d");
        g.drawImage(img, 0, 0);
        const d = g.getImageData(0, 0, c.width, c.height).data;
        const n = d.length / 4;
        const bg = [d[0], d[1], d[2]];
        const colours = new Set();
        let non = 0, sum = 0, sum2 = 0;
        for (let i = 0; i < d.length; i += 4) {
          if (Math.abs(d[i] - bg[0]) > 8 || Math.abs(d[i + 1] - bg[1]) > 8 || Math.abs(d[i + 2] - bg[2]) > 8) non++;
          if (colours.size < 4096) colours.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
          const y = 0.299 * d[i] + 0.587 * d[i + 1] + 0.114 * d[i + 2];
          sum += y;
          sum2 += y * y;
        }
        r.non_background = non / n;
        r.colours = colours.size;
        r.std = Math.sqrt(Math.max(sum2 / n - (sum / n) ** 2, 0));
      }
      out.images.push(r);
    }
    out.resources = performance.getEntriesByType("resource").map(e => e.name);
  } catch (e) {
    out.error = String(e);
  }
  const pre = document.createElement("pre");
  pre.id = "porecad-verdict";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>
"""


def _find_chromium():
    env = os.environ.get("PORECAD_CHROMIUM")
    if env:
        return env
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        exe = shutil.which(name)
        if exe:
            return exe
    return "/usr/bin/chromium" if os.access("/usr/bin/chromium", os.X_OK) else None


@pytest.fixture(scope="module")
def chromium():
    exe = _find_chromium()
    if exe is None:
        msg = "headless Chromium not found (Debian: apt-get install chromium; or set PORECAD_CHROMIUM)"
        if os.environ.get("PORECAD_REQUIRE_BROWSER"):
            pytest.fail(msg + " and PORECAD_REQUIRE_BROWSER is set")
        pytest.skip(msg)
    return exe


@pytest.fixture(scope="module")
def gyroid(tmp_path_factory):
    """A small gyroid-sheet scaffold built by the CLI, and its build report (the design)."""
    d = tmp_path_factory.mktemp("gyroid")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "2", "2", "2",
                     "--cell-size", "2", "--resolution", "20", "-o", str(d / "g.stl"), "--json"])
    assert code == 0
    return d / "g.stl", json.loads(out.getvalue())


@contextlib.contextmanager
def _serve(directory):
    """Serve ``directory`` on 127.0.0.1; yields (base URL, list of (path, status) requested)."""
    requests = []

    class Handler(SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

        def log_request(self, code="-", size="-"):
            requests.append((self.path, int(code) if str(code).isdigit() else code))

    server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(directory)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", requests
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5)


def _markup(page):
    """The page without the bodies of its inline scripts (the 3D view's three.js names URLs in comments and
    messages that it never fetches; what the browser fetches is checked from its own log below)."""
    return re.sub(r"(<script\b[^>]*>).*?(</script>)", r"\1\2", page, flags=re.S | re.I)


def _external_refs(page):
    """URLs in the page's markup that would need a network: anything with a scheme or ``//`` that is not local."""
    page = _markup(page)
    refs = re.findall(r"""(?:src|href|srcset|action|data)\s*=\s*["']([^"']*)["']""", page, re.I)
    refs += re.findall(r"""url\(\s*["']?([^"')]+)""", page, re.I)
    refs += re.findall(r"""@import\s+["']([^"']+)""", page, re.I)
    refs += re.findall(r"""\b(?:https?|ftp|wss?):(?://)?[^\s"'<>)]+""", page, re.I)
    return [r for r in refs if re.match(r"^\s*(?:[a-z][a-z0-9+.-]*:|//)", r, re.I)]


def _check_in_browser(chromium, directory, tmp_path):
    """Load ``directory/report.html`` in headless Chromium; return (verdict, img srcs in the page)."""
    directory = Path(directory)
    page = (directory / "report.html").read_text(encoding="utf-8")
    assert _external_refs(page) == [], "the report must render offline"
    srcs = re.findall(r"""<img\b[^>]*\bsrc\s*=\s*["']([^"']+)["']""", page, re.I)
    assert srcs and len(srcs) == len(set(srcs))
    assert set(re.findall(r"[\w.-]+\.png\b", _markup(page))) == set(srcs)
    assert "</body>" in page
    (directory / CHECK_PAGE).write_text(page.replace("</body>", CHECK_SCRIPT + "</body>", 1), encoding="utf-8")
    profile = tmp_path / "chromium-profile"
    env = dict(os.environ, HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path / "config"),
               XDG_CACHE_HOME=str(tmp_path / "cache"))
    try:
        with _serve(directory) as (base, requests):
            proc = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom",
                                   "--virtual-time-budget=10000", f"{base}/{CHECK_PAGE}"],
                                  capture_output=True, text=True, encoding="utf-8", timeout=90, env=env, stdin=subprocess.DEVNULL)
    finally:
        (directory / CHECK_PAGE).unlink()
    m = re.search(r'<pre id="porecad-verdict">(.*?)</pre>', proc.stdout, re.S)
    assert m, f"no verdict from chromium (rc {proc.returncode}): {proc.stderr[-2000:]}"
    verdict = json.loads(html.unescape(m.group(1)))
    assert verdict["error"] is None, verdict["error"]
    # only the page and its images were fetched, all from the local server, all found
    requests = [(p, status) for p, status in requests if p != "/favicon.ico"]
    assert all(status == 200 for _, status in requests), requests
    fetched = {p.lstrip("/") for p, _ in requests} - {CHECK_PAGE}
    assert fetched == set(srcs), requests
    assert all(r.startswith(base + "/") for r in verdict["resources"]), verdict["resources"]
    return verdict, srcs


def _assert_images_ok(verdict, srcs):
    images = verdict["images"]
    assert [i["src"] for i in images] == srcs
    for i in images:
        assert i["complete"] and i["width"] > 0 and i["height"] > 0, f"{i['src']} did not load: {i}"
        assert i["non_background"] > 0.01 and i["colours"] >= 8 and i["std"] > 2.0, f"{i['src']} is blank: {i}"


def test_cli_report_renders_offline_in_chromium(chromium, gyroid, tmp_path):
    """`porecad analyze --pores --report`: every image loads and is not blank; no curve without a design."""
    stl, _ = gyroid
    d = tmp_path / "report"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["analyze", str(stl), "--pores", "--report", str(d), "--json"])
    assert code == 0
    verdict, srcs = _check_in_browser(chromium, d, tmp_path)
    pngs = [f for f in REPORT_FILES if f.endswith(".png")]
    assert sorted(srcs) == sorted(pngs) == sorted(p.name for p in d.glob("*.png"))
    _assert_images_ok(verdict, srcs)
    assert "No porosity–threshold curve" in (d / "report.html").read_text(encoding="utf-8")
    assert not (d / "porosity_threshold.png").exists()


def test_report_with_design_has_porosity_threshold_curve(chromium, gyroid, tmp_path):
    """A known design adds porosity_threshold.png, and the browser check covers it too."""
    stl, build = gyroid
    design = {k: build[k] for k in ("type", "structure", "threshold", "target_porosity")}
    report, fields = analyze_mesh(stl, pores=True, keep_fields=True)
    d = write_report(tmp_path / "report", report, fields, design=design)
    assert (d / "porosity_threshold.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    verdict, srcs = _check_in_browser(chromium, d, tmp_path)
    pngs = [f for f in REPORT_FILES + OPTIONAL_REPORT_FILES if f.endswith(".png")]
    assert "porosity_threshold.png" in srcs
    assert sorted(srcs) == sorted(pngs) == sorted(p.name for p in d.glob("*.png"))
    _assert_images_ok(verdict, srcs)
    assert "No porosity–threshold curve" not in (d / "report.html").read_text(encoding="utf-8")


@pytest.mark.parametrize("design", [
    {"type": "P", "structure": "sheet", "porosity_min": 0.5, "porosity_max": 0.8},   # graded by porosity
    {"type": "neovius", "structure": "sheet", "threshold": [0.3, 0.9]},             # graded, partly outside
    {"type": "D", "structure": "rod", "porosity": 0.7},
    {"type": "G", "structure": "pore"},                                               # curve only
    {"type": "G", "structure": "sheet", "porosity": 0.58, "porosity_min": 0.5, "porosity_max": 0.7},
])
def test_porosity_threshold_plot_designs(design, tmp_path):
    d = write_report(tmp_path / "r", {"file": "x.stl"}, None, design=design)
    assert sorted(p.name for p in d.glob("*.png")) == ["porosity_threshold.png"]
    assert 'src="porosity_threshold.png"' in (d / "report.html").read_text(encoding="utf-8")


def test_porosity_threshold_plot_refusals(tmp_path):
    d = write_report(tmp_path / "s", {"file": "x.stl"}, None, design={"type": "G", "structure": "surface",
                                                                      "threshold": 0.0})
    assert not list(d.glob("*.png"))
    assert "bare surface has no porosity" in (d / "report.html").read_text(encoding="utf-8")
    for bad in ({"structure": "sheet"}, {"type": "G", "structure": "sheet", "threshold": float("nan")},
                {"type": "nope", "structure": "sheet", "threshold": 0.5},
                {"type": "G", "structure": "sheet", "porosity": "high"}):
        with pytest.raises(InputError):
            write_report(tmp_path / "bad", {"file": "x.stl"}, None, design=bad)
        assert not (tmp_path / "bad").exists()
