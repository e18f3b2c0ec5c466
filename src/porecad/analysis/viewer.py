"""The report's interactive 3D view: a decimated copy of the part, three.js inlined, a section plane.

The page must open offline, from a file, by double click: browsers refuse
ES modules from ``file://`` pages, so the page inlines three.js as one
classic script, ``porecad/vendor/three.classic.js`` (MIT; built once from
the npm modules by ``tools/build_viewer_script.py``, and loaded by the
studio too). The geometry is embedded as base64 float32 positions and
uint32 indices. Nothing is fetched at view time.

The view draws the outside of the part in blue and, behind a movable
clipping plane (axis and position set by the controls), the backs of faces
in a flat section colour, so the plane shows the cut material.
"""

from __future__ import annotations

import base64
import functools
from pathlib import Path

import numpy as np

THREE_SCRIPT = Path(__file__).resolve().parent.parent / "vendor" / "three.classic.js"


@functools.lru_cache(maxsize=1)
def three_classic_script() -> str:
    """three.js (core, renderer, OrbitControls) as one classic script defining ``window.THREE``: the vendored
    ``porecad/vendor/three.classic.js`` (built once by ``tools/build_viewer_script.py``), made safe to inline."""
    return THREE_SCRIPT.read_text(encoding="utf-8").replace("</script", "<\\/script")


VIEWER_JS = r"""
(function () {
  const data = JSON.parse(document.getElementById("porecad-mesh").textContent);
  const bytes = s => { const b = atob(s); const a = new Uint8Array(b.length);
                       for (let i = 0; i < b.length; i++) a[i] = b.charCodeAt(i); return a.buffer; };
  const canvas = document.getElementById("porecad-view");
  const status = document.getElementById("porecad-view-status");
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({canvas, antialias: true, preserveDrawingBuffer: true});
  } catch (e) {
    status.textContent = "This browser cannot show the 3D view (WebGL is off): " + e;
    return;
  }
  renderer.localClippingEnabled = true;
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xffffff);
  const geo = new THREE.BufferGeometry();
  geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(bytes(data.positions)), 3));
  geo.setIndex(new THREE.BufferAttribute(new Uint32Array(bytes(data.indices)), 1));
  geo.computeVertexNormals();
  geo.computeBoundingBox();
  const box = geo.boundingBox, centre = box.getCenter(new THREE.Vector3()), size = box.getSize(new THREE.Vector3());
  const plane = new THREE.Plane(new THREE.Vector3(0, -1, 0), 0);
  const outside = new THREE.MeshStandardMaterial({color: 0xb3c4e6, roughness: 0.55, metalness: 0.05,
                                                  side: THREE.FrontSide, clippingPlanes: [plane]});
  const cut = new THREE.MeshBasicMaterial({color: 0xdb614d, side: THREE.BackSide, clippingPlanes: [plane]});
  scene.add(new THREE.Mesh(geo, outside), new THREE.Mesh(geo, cut));
  scene.add(new THREE.HemisphereLight(0xffffff, 0x445566, 1.4));
  const radius = size.length() / 2 || 1;
  const cam = new THREE.PerspectiveCamera(35, 1, radius / 100, radius * 100);
  const key = new THREE.DirectionalLight(0xffffff, 1.6);
  key.position.set(-1, 1, 2);
  cam.add(key);
  scene.add(cam);
  cam.up.set(0, 0, 1);
  cam.position.copy(centre).add(new THREE.Vector3(0.55, -1.0, 0.8).normalize().multiplyScalar(radius * 2.3));
  const controls = new THREE.OrbitControls(cam, canvas);
  controls.target.copy(centre);
  const axisSel = document.getElementById("porecad-section-axis");
  const slider = document.getElementById("porecad-section");
  const readout = document.getElementById("porecad-section-at");
  function section() {
    const a = axisSel.value;
    if (a === "off") { plane.normal.set(0, 0, -1); plane.constant = box.max.z + radius; readout.textContent = "";
                       return; }
    const i = {x: 0, y: 1, z: 2}[a];
    const lo = box.min.getComponent(i), hi = box.max.getComponent(i);
    const at = lo + (hi - lo) * slider.value / 1000;
    // three.js keeps where normal·p + constant >= 0: the part beyond `at`; the near side (towards the eye) goes
    const n = new THREE.Vector3(); n.setComponent(i, 1);
    plane.normal.copy(n);
    plane.constant = -at;
    readout.textContent = a + " = " + at.toFixed(2) + " mm";
  }
  function draw() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * renderer.getPixelRatio())) {
      renderer.setSize(w, h, false); cam.aspect = w / h; cam.updateProjectionMatrix();
    }
    renderer.render(scene, cam);
  }
  axisSel.addEventListener("change", () => { section(); draw(); });
  slider.addEventListener("input", () => { section(); draw(); });
  controls.addEventListener("change", draw);
  window.addEventListener("resize", draw);
  section();
  controls.update();
  draw();
  status.textContent = data.triangles.toLocaleString() + " triangles shown (a decimated copy of " +
                       data.source_triangles.toLocaleString() + "). Drag to turn, scroll to zoom, right-drag to pan.";
  window.porecadViewer = {renderer, scene, camera: cam, draw, drawn: true};
})();
"""


def viewer_section(vertices, faces, source_triangles: int):
    """The HTML of the 3D view (canvas, section controls, three.js, geometry, viewer script): template
    ``porecad/pages/templates/viewer.html``, as markup ready to place in a page."""
    from markupsafe import Markup

    from ..pages import render
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.uint32)
    data = {"positions": base64.b64encode(v.astype("<f4").tobytes()).decode("ascii"),
            "indices": base64.b64encode(f.astype("<u4").tobytes()).decode("ascii"),
            "triangles": int(len(f)), "source_triangles": int(source_triangles)}
    return Markup(render("viewer.html", data=data, three=three_classic_script(), viewer_js=VIEWER_JS))
