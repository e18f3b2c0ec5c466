"""The studio's server: safety (issue 24, acceptance 3), recipes from designs, exports and cancelling.

Requests go over real HTTP to an in-process server on 127.0.0.1 (the only
address any of this talks to).
"""

from __future__ import annotations

import http.client
import json
import time

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from porecad.studio.design import FieldError, design_of, recipe_of  # noqa: E402


@pytest.fixture(scope="module")
def server():
    from porecad.studio.launcher import make_studio
    from porecad.studio.server import Server
    srv = Server(make_studio(None, threads=1, max_upload=4 << 20)).start()
    try:
        yield srv
    finally:
        srv.stop()


def request(srv, method, path, body=None, headers=None, token=True, host=None):
    conn = http.client.HTTPConnection("127.0.0.1", srv.studio.port, timeout=60)
    prefix = f"/s/{srv.studio.session.token}/" if token is True else (f"/s/{token}/" if token else "/")
    hdrs = dict(headers or {})
    if host is not None:
        conn.putrequest(method, prefix + path, skip_host=True)
        conn.putheader("Host", host)
        for k, v in hdrs.items():
            conn.putheader(k, v)
        conn.endheaders(body)
    else:
        conn.request(method, prefix + path, body=body, headers=hdrs)
    resp = conn.getresponse()
    data = resp.read()
    conn.close()
    return resp.status, data


def api_json(srv, method, path, payload=None):
    status, data = request(srv, method, "api/" + path, json.dumps(payload).encode() if payload is not None else None,
                           {"content-type": "application/json"})
    return status, json.loads(data)


def serving(srv):
    status, data = api_json(srv, "GET", "schema")
    return status == 200 and "fields" in data


def wait_preview(srv, gen, timeout=600):
    t0 = time.time()
    while time.time() - t0 < timeout:
        status, s = api_json(srv, "GET", f"preview/{gen}")
        assert status == 200
        if s["state"] in ("done", "failed", "superseded"):
            return s
        time.sleep(0.1)
    raise AssertionError("preview did not finish")


# ------------------------------------------------------------------------------------------- safety

def test_listens_on_loopback_only(server):
    import psutil
    assert server.sock.getsockname()[0] == "127.0.0.1"
    port = server.studio.port
    listening = [c for c in psutil.Process().net_connections(kind="inet")
                 if c.status == psutil.CONN_LISTEN and c.laddr.port == port]
    assert listening and all(c.laddr.ip == "127.0.0.1" for c in listening)


def test_token_required(server):
    for token in (False, "x" * 32, server.studio.session.token[:-1]):
        for path in ("", "api/schema", "static/app.js", "api/export/1/file/x.stl"):
            status, body = request(server, "GET", path, token=token)
            assert status == 403, (token, path)
            assert b"token" in body
    status, _ = request(server, "PUT", "api/upload?name=a.stl", b"solid", token=False)
    assert status == 403
    # the right token but a foreign Host (DNS rebinding) is refused too
    status, _ = request(server, "GET", "api/schema", host="evil.example:80")
    assert status == 403
    status, body = request(server, "GET", "")
    assert status == 200 and b"porecad studio" in body
    status, _ = request(server, "GET", "static/vendor/three.classic.js")
    assert status == 200
    assert serving(server)


def test_errors_mapped_and_foreign_origin_refused(server):
    """Issue 41: a 5000-digit number in a path or a body is a 404 / 400, never a 500; a foreign Origin is refused."""
    status, data = request(server, "GET", "api/preview/" + "9" * 5000)
    assert status == 404
    status, data = request(server, "POST", "api/preview", b'{"design": {"cells": ' + b"9" * 5000 + b"}}",
                           {"content-type": "application/json"})
    assert status == 400 and b"internal" not in data.lower()
    status, _ = request(server, "GET", "api/schema", headers={"Origin": "http://evil.example"})
    assert status == 403
    status, _ = request(server, "GET", "api/schema", headers={"Origin": f"http://127.0.0.1:{server.studio.port}"})
    assert status == 200


def test_path_traversal_upload_name(server):
    work = server.studio.session.work
    for name in ("../evil.stl", "..%2Fevil.stl", "/etc/evil.stl", "a/../../evil.stl", ".hidden.stl", "x.exe"):
        status, data = request(server, "PUT", f"api/upload?name={name}", b"solid x\nendsolid x\n")
        assert status == 400, name
        msg = json.loads(data)["error"]
        assert msg and "\n" not in msg
    assert not (work.parent / "evil.stl").exists() and not (work / "evil.stl").exists()
    assert sorted(p.name for p in (work / "inputs").iterdir()) == []
    assert serving(server)


def test_huge_upload_refused_before_reading(server):
    conn = http.client.HTTPConnection("127.0.0.1", server.studio.port, timeout=30)
    conn.putrequest("PUT", f"/s/{server.studio.session.token}/api/upload?name=huge.stl")
    conn.putheader("Content-Length", str(2 << 30))  # 2 GB declared
    conn.putheader("Content-Type", "application/octet-stream")
    conn.endheaders()
    conn.send(b"\0" * 65536)  # a start of it; the server answers without reading on
    resp = conn.getresponse()
    body = json.loads(resp.read())
    conn.close()
    assert resp.status == 413
    assert "upload limit" in body["error"]
    assert serving(server)


def test_upload_over_limit_without_length(server):
    conn = http.client.HTTPConnection("127.0.0.1", server.studio.port, timeout=30)
    conn.putrequest("PUT", f"/s/{server.studio.session.token}/api/upload?name=big.stl")
    conn.putheader("Transfer-Encoding", "chunked")
    conn.endheaders()
    block = b"a" * (1 << 20)
    try:
        for _ in range(6):  # 6 MB, the limit is 4 MB
            conn.send(b"%x\r\n%s\r\n" % (len(block), block))
        conn.send(b"0\r\n\r\n")
    except OSError:
        pass  # the server may close as soon as it has answered
    resp = conn.getresponse()
    body = json.loads(resp.read())
    conn.close()
    assert resp.status == 413 and "upload limit" in body["error"]
    assert not list((server.studio.session.work / "inputs").glob("big*"))
    assert serving(server)


def test_garbage_upload(server):
    rng = np.random.default_rng(0)
    for name in ("garbage.stl", "garbage.ply", "garbage.3mf", "garbage.json"):
        status, data = request(server, "PUT", f"api/upload?name={name}", rng.bytes(5000))
        assert status == 400, name
        msg = json.loads(data)["error"]
        assert name in msg and "\n" not in msg and "Traceback" not in msg and "tmp" not in msg
    assert not any((server.studio.session.work / "inputs").iterdir())
    assert serving(server)


def _stl(triangles) -> bytes:
    lines = ["solid t"]
    for tri in triangles:
        lines.append("facet normal 0 0 0\nouter loop")
        lines += [f"vertex {x} {y} {z}" for x, y, z in tri]
        lines.append("endloop\nendfacet")
    lines.append("endsolid t")
    return "\n".join(lines).encode()


def test_non_manifold_upload(server):
    # two closed tetrahedra sharing one edge: four faces on that edge
    a = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    b = [(0, 0, 0), (1, 0, 0), (0, -1, 0), (0, 0, -1)]
    tris = []
    for p in (a, b):
        tris += [(p[0], p[2], p[1]), (p[0], p[1], p[3]), (p[0], p[3], p[2]), (p[1], p[2], p[3])]
    status, data = request(server, "PUT", "api/upload?name=pinched.stl", _stl(tris))
    assert status == 400
    msg = json.loads(data)["error"]
    assert "pinched.stl" in msg and "manifold" in msg
    assert serving(server)


def test_bad_parameters_and_client_paths(server):
    for design, field in (({"job": "tpms", "value": "abc"}, "value"),
                          ({"job": "tpms", "value": 1.5}, "value"),
                          ({"job": "tpms", "value": 0.7, "cells": "2 2"}, "cells"),
                          ({"job": "infill", "body": "/etc/passwd", "value": 0.7}, "body"),
                          ({"job": "infill", "body": "../../femur.stl", "value": 0.7}, "body"),
                          ({"job": "nope"}, "job")):
        status, data = api_json(server, "POST", "preview", {"design": design})
        assert status == 400, design
        assert data.get("field") == field, data
    status, data = api_json(server, "POST", "preview", {"design": {"job": "tpms", "value": 0.99}})
    assert status == 400 and "valid range" in data["error"]  # the job's own check, naming the recipe key
    status, data = request(server, "POST", "api/preview", b"{not json", {"content-type": "application/json"})
    assert status == 400
    status, data = request(server, "POST", "api/preview", b"x" * (2 << 20), {"content-type": "application/json"})
    assert status == 400
    status, data = request(server, "GET", "api/export/1/file/..%2F..%2Finputs")
    assert status == 404
    assert serving(server)


# ------------------------------------------------------------------------------------------- designs

def test_recipe_of_matches_the_cli():
    from porecad.cli.cmd_lattice import tpms_recipe
    design = {"job": "tpms", "type": "G", "structure": "sheet", "control": "porosity", "value": 0.6,
              "cell_size": 2.0, "cells": "2 2 2", "resolution": 40}
    cli = tpms_recipe("G", "sheet", None, "0.6", [2.0], (2, 2, 2), 40, None)
    mine = recipe_of(design)
    for key in ("tpms", "domain", "sampling"):
        assert mine[key] == cli[key] or key == "tpms" and mine["tpms"] == {**cli["tpms"], "cell_size": 2.0}
    assert design_of(mine)["value"] == 0.6
    with pytest.raises(FieldError) as err:
        recipe_of({"job": "tpms", "value": 0.6, "cell_size": -1})
    assert err.value.field == "cell_size"


def test_gradings_become_recipe_tables():
    r = recipe_of({"job": "tpms", "value": 0.6, "value_to": 0.8, "grading": "axial", "axis": "z",
                   "cells": [2, 2, 3], "cell_size": 2})
    assert r["grading"] == {"kind": "linear", "of": "porosity", "axis": "z", "start": 0.0, "end": 6.0,
                            "from": 0.6, "to": 0.8}
    r = recipe_of({"job": "infill", "body": "disc", "value": 0.6, "value_to": 0.8, "grading": "depth"})
    assert r["grading"]["kind"] == "expression" and "dn" in r["grading"]["expr"]


def test_the_readme_femur_recipe_opens_in_the_form():
    """Issue 42: the README's femur.toml (an expression grading) opens in the studio and comes back the same."""
    recipe = {"job": "infill", "tpms": {"type": "G", "structure": "sheet", "cell_size": 5.0},
              "domain": {"kind": "mesh", "path": "femur.stl"},
              "grading": {"kind": "expression", "of": "porosity", "expr": "0.5 + 0.3 * dn"}}
    d = design_of(recipe, upload_name=lambda p: "femur.stl")
    assert d["grading"] == "expression" and d["expression"] == "0.5 + 0.3 * dn"
    back = recipe_of({**d, "body": "disc"})
    assert back["grading"] == recipe["grading"] and "porosity" not in back["tpms"]
    with pytest.raises(FieldError) as err:
        recipe_of({**d, "body": "disc", "expression": " "})
    assert err.value.field == "expression"
    with pytest.raises(FieldError):
        recipe_of({"job": "tpms", "value": 0.6, "value_to": 0.8, "grading": "depth"})


def test_display_mesh_bounds_triangles():
    from porecad.api import polygonise, sheet, tpms
    from porecad.studio.preview import display_mesh, pack_mesh
    m = polygonise(sheet(tpms("G", cell_size=1.0), porosity=0.6), bounds=([0, 0, 0], [2, 2, 2]), voxel=0.04)
    v, f, cell = display_mesh(m.vertices, m.faces, max_faces=20_000)
    assert len(m.faces) > 20_000 >= len(f) > 2_000 and cell is not None
    assert np.abs(v.min(axis=0) - m.vertices.min(axis=0)).max() < 2 * cell
    blob = pack_mesh(v, f)
    assert blob[:4] == b"PCM1" and len(blob) == 12 + 12 * len(v) + 12 * len(f)


# ------------------------------------------------------------------------------------------- exports

def _export(server, design, report=False, fmt="stl"):
    status, data = api_json(server, "POST", "export", {"design": design, "format": fmt, "report": report})
    assert status == 200, data
    return data["id"]


def _wait_export(server, n, timeout=600):
    t0 = time.time()
    while time.time() - t0 < timeout:
        status, s = api_json(server, "GET", f"export/{n}")
        if s["state"] != "running":
            return s
        time.sleep(0.1)
    raise AssertionError("export did not finish")


def test_export_with_report_and_bundle(server):
    design = {"job": "tpms", "type": "P", "structure": "pore", "control": "threshold", "value": 0.0,
              "cells": [1, 1, 1], "cell_size": 2.0, "resolution": 16}
    n = _export(server, design, report=True, fmt="3mf")
    s = _wait_export(server, n)
    assert s["state"] == "done", s
    assert "lattice.3mf" in s["files"] and "lattice.toml" in s["files"]
    assert "report.html" in s["report_files"]
    assert s["summary"]["closed"] and abs(s["summary"]["porosity"] - 0.5) < 0.02
    status, page = request(server, "GET", f"api/export/{n}/report/report.html")
    assert status == 200 and b"<html" in page.lower()
    status, data = request(server, "GET", f"api/export/{n}/bundle")
    assert status == 200 and data[:2] == b"PK"
    import io
    import zipfile
    names = zipfile.ZipFile(io.BytesIO(data)).namelist()
    assert "lattice.toml" in names and "report/report.html" in names


def test_export_cancel_leaves_no_files(server):
    exports = server.studio.session.exports
    before = sorted(p.name for p in exports.iterdir())
    design = {"job": "tpms", "type": "G", "structure": "sheet", "control": "porosity", "value": 0.7,
              "cells": [3, 3, 3], "cell_size": 1.0, "resolution": 110}
    n = _export(server, design)
    t0 = time.time()
    while time.time() - t0 < 600:
        status, s = api_json(server, "GET", f"export/{n}")
        if s["state"] != "running" or s["done"] > 0:
            break
        time.sleep(0.05)
    assert s["state"] == "running", s  # still building: cancel it now
    status, data = api_json(server, "POST", f"export/{n}/cancel")
    assert data["cancelling"] is True
    s = _wait_export(server, n)
    assert s["state"] == "cancelled"
    after = sorted(p.name for p in exports.iterdir())
    assert after == before
    status, data = request(server, "GET", f"api/export/{n}/file/lattice.stl")
    assert status == 404
    assert serving(server)


def test_preview_of_a_box_lattice(server):
    status, data = api_json(server, "POST", "preview", {"design": {"job": "tpms", "type": "G", "structure": "sheet",
                                                                   "value": 0.7, "cell_size": 2, "cells": [2, 2, 2],
                                                                   "resolution": 20}})
    assert status == 200, data
    assert data["curve"]["valid"]["porosity"][0] < 0.7 < data["curve"]["valid"]["porosity"][1]
    assert abs(data["points"][0]["porosity"] - 0.7) < 1e-9
    s = wait_preview(server, data["gen"])
    assert s["state"] == "done", s
    assert abs(s["levels"]["coarse"]["report"]["porosity"] - 0.7) < 0.03
    assert s["levels"]["coarse"]["report"]["closed"] is True
    assert 0 < s["analysis"]["strut_size_d50"] < s["analysis"]["pore_size_d50"] < 2.0
    status, blob = request(server, "GET", f"api/preview/{data['gen']}/coarse")
    assert status == 200 and blob[:4] == b"PCM1"


def test_porecad_studio_command(tmp_path):
    """``porecad studio BODY --no-browser`` prints its address, serves the body's infill design, stops on SIGTERM."""
    import re
    import signal
    import subprocess
    import sys
    import urllib.request

    from porecad.datasets import femur_path
    proc = subprocess.Popen([sys.executable, "-m", "porecad", "studio", str(femur_path()), "--no-browser"],
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        line = proc.stderr.readline()
        m = re.search(r"(http://127\.0\.0\.1:\d+/s/[\w-]+/)", line)
        assert m, line
        with urllib.request.urlopen(m.group(1) + "api/schema", timeout=60) as resp:
            schema = json.loads(resp.read())
        assert schema["design"]["job"] == "infill" and schema["design"]["body"] == "femur.stl"
        assert [u["name"] for u in schema["uploads"]] == ["femur.stl"]
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    err = proc.stderr.read()
    assert proc.returncode in (0, 143), (proc.returncode, err)  # stopped cleanly (SIGTERM)
    assert "Traceback" not in err


def test_studio_opens_a_recipe(tmp_path):
    import shutil

    from porecad.datasets import femur_path
    from porecad.io.recipe import save_recipe
    from porecad.studio.launcher import make_studio
    shutil.copyfile(femur_path(), tmp_path / "bone.stl")
    save_recipe({"job": "infill", "tpms": {"type": "P", "structure": "pore", "porosity": 0.6, "cell_size": 6.0},
                 "domain": {"kind": "mesh", "path": "bone.stl", "boundary": "skin", "skin": 1.5},
                 "sampling": {"voxel": 1.0}}, tmp_path / "r.toml")
    studio = make_studio(tmp_path / "r.toml")
    try:
        d = studio.design
        assert d["job"] == "infill" and d["body"] == "bone.stl" and d["boundary"] == "skin" and d["skin"] == 1.5
        assert d["type"] == "P" and d["control"] == "porosity" and d["value"] == 0.6 and d["voxel"] == 1.0
        recipe = recipe_of(d, studio.session.resolve, studio.session.body_bounds)
        assert recipe["domain"]["path"] == str(studio.session.inputs / "bone.stl")
        assert recipe["tpms"]["porosity"] == 0.6 and recipe["domain"]["skin"] == 1.5
    finally:
        studio.close()
