"""Issue 51, problems 3 and 4: the trust model (docs/security.md).

Recipes and everything the studio's page sends are untrusted; the command
line and Python arguments are the user's. Keys that name server paths,
schedulers, worker counts or stores are declared local-only
(:attr:`porecad.recipes.key.Key.local_only`): the studio neither shows nor
accepts them, and a recipe file may ask only for ``threads`` or ``local:N``
with N at most the machine's cores; a remote scheduler is chosen on the
command line or in Python.
"""

from __future__ import annotations

import http.client
import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from porecad.cli.main import main
from porecad.errors import RecipeError
from porecad.jobs import parse

RECIPE = """job = "tpms"
[tpms]
type = "G"
porosity = 0.6
[domain]
cells = [1, 1, 1]
[sampling]
resolution = 8
[output]
mesh = "m.stl"
"""

SWC = "1 1 0 0 0 1 -1\n2 1 0 0 5 1 1\n"


@pytest.fixture
def listener():
    """A TCP socket listening on 127.0.0.1 (a stand-in for a hostile dask scheduler)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    s.listen(8)
    s.settimeout(0.3)
    try:
        yield s
    finally:
        s.close()


def _connected(sock) -> bool:
    """Whether anything connected to the listener (the kernel queues a connection even before accept)."""
    try:
        conn, _ = sock.accept()
    except TimeoutError:
        return False
    conn.close()
    return True


def _recipe(tmp_path, scale: str) -> Path:
    p = tmp_path / "r.toml"
    p.write_text(RECIPE + "[scale]\n" + scale + "\n")
    return p


def _parse_file(path: Path, typed=frozenset()):
    from porecad.io.recipe import read_recipe
    return parse(read_recipe(path), path.parent, confine=(path.parent, typed))


# --------------------------------------------------------------------------------------- problem 4: recipes

def test_a_recipe_cannot_connect_to_a_scheduler(tmp_path, listener):
    """A separate process with a time limit: before the fix the build connected and then waited on the handshake."""
    port = listener.getsockname()[1]
    r = _recipe(tmp_path, f'scheduler = "tcp://127.0.0.1:{port}"')
    try:
        run = subprocess.run([sys.executable, "-m", "porecad", "build", r.name], cwd=tmp_path, capture_output=True,
                             text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("porecad build connected to the scheduler and waited on it")
    assert run.returncode != 0 and "Traceback" not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert re.search(r"scale\.scheduler.*command line or in Python.*pickle", run.stderr), run.stderr
    assert not _connected(listener)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.toml"]


@pytest.mark.parametrize("spec", ["local:5", "local:64", "local:1024", "threads:5"])
def test_a_recipe_asks_for_at_most_the_cores(tmp_path, monkeypatch, spec):
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    with pytest.raises(RecipeError, match=r"scale\.scheduler: .*at most 4 workers"):
        _parse_file(_recipe(tmp_path, f'scheduler = "{spec}"'))
    for ok in ("local:4", "threads", "threads:2", "local:1"):
        _parse_file(_recipe(tmp_path, f'scheduler = "{ok}"'))


def test_the_user_still_picks_any_scheduler(tmp_path, capsys, monkeypatch):
    """The command line and Python are the user's: a remote scheduler or more workers stay theirs to choose."""
    from porecad.io.recipe import read_recipe
    remote = read_recipe(_recipe(tmp_path, 'scheduler = "tcp://127.0.0.1:9"'))
    parse(remote, tmp_path)  # a recipe built in Python (or from command-line flags): not confined
    parse(remote, tmp_path, confine=(tmp_path, frozenset({"tcp://127.0.0.1:9"})))  # typed on the command line
    monkeypatch.chdir(tmp_path)
    n = (os.cpu_count() or 1) + 1
    r = _recipe(tmp_path, 'retries = 1')
    code = main(["build", str(r), "--scheduler", f"threads:{n}"])
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "m.stl").is_file()
    capsys.readouterr()
    code = main(["build", "--help"])
    assert code == 0 and "pickle" in " ".join(capsys.readouterr().out.split())


def test_a_recipe_starts_at_most_the_cores_of_vessel_workers(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    (tmp_path / "c.swc").write_text(SWC)
    base = {"job": "vessel", "input": {"path": "c.swc"}, "voxel": 0.5, "executor": "process"}
    with pytest.raises(RecipeError, match=r"^workers: .*at most 2 workers"):
        parse({**base, "workers": 64}, tmp_path, confine=(tmp_path, frozenset()))
    parse({**base, "workers": 2}, tmp_path, confine=(tmp_path, frozenset()))
    parse({**base, "workers": 64}, tmp_path)  # porecad vessel --workers 64: the user's


def test_every_key_naming_a_server_path_is_local_only():
    """The schema declares it: every input and output path, the scheduler, the store and the worker counts."""
    from porecad.recipes.keys import JOBS
    from porecad.recipes.schema import json_schema, walk
    for job, keys in JOBS.items():
        for dotted, key in walk(keys):
            if key.kind in ("path", "output") or dotted in ("scale.scheduler", "workers", "executor"):
                assert key.local_only, f"{job}: {dotted}"
    assert json_schema("tpms")["properties"]["scale"]["properties"]["scheduler"]["x-local-only"] is True


# ---------------------------------------------------------------------------------------- problem 3: studio

@pytest.fixture(scope="module")
def server():
    pytest.importorskip("starlette")
    pytest.importorskip("uvicorn")
    from porecad.studio.launcher import make_studio
    from porecad.studio.server import Server
    srv = Server(make_studio(None, threads=1, max_upload=1 << 20)).start()
    try:
        yield srv
    finally:
        srv.stop()


def _api(srv, method, path, body=None, query=""):
    conn = http.client.HTTPConnection("127.0.0.1", srv.studio.port, timeout=60)
    data = body if isinstance(body, (bytes, type(None))) else json.dumps(body).encode()
    conn.request(method, f"/s/{srv.studio.session.token}/api/{path}{query}", body=data,
                 headers={"content-type": "application/json"})
    resp = conn.getresponse()
    out = json.loads(resp.read())
    conn.close()
    return resp.status, out


def test_the_studio_shows_no_local_only_setting(server):
    status, schema = _api(server, "GET", "schema")
    assert status == 200
    names = {f["name"] for f in schema["fields"]}
    assert "vessel.segment_angle" in names  # the "more settings" are there ...
    for hidden in ("vessel.workers", "vessel.executor", "tpms.scale.scheduler", "tpms.scale.zarr",
                   "vessel.input.image", "vessel.input.points", "infill.grading.file"):
        assert hidden not in names  # ... but none that names something on the server


def test_the_studio_refuses_server_paths_and_schedulers(server, tmp_path, listener):
    status, up = _api(server, "PUT", "upload", SWC.encode(), "?name=c.swc")
    assert status == 200, up
    dicom = tmp_path / "series"
    dicom.mkdir()
    (dicom / "a.dcm").write_bytes(b"\0" * 132 + b"DICM")
    zarr = tmp_path / "field.zarr"
    vessel = {"job": "vessel", "centreline": "c.swc", "voxel": 0.5}
    tpms = {"job": "tpms", "value": 0.6, "cells": [1, 1, 1], "resolution": 8}
    port = listener.getsockname()[1]
    for design, field in (({**vessel, "vessel.input.image": "/etc/passwd"}, "vessel.input.image"),
                          ({**vessel, "vessel.input.points": "/etc/passwd"}, "vessel.input.points"),
                          ({**vessel, "vessel.input.image": str(dicom)}, "vessel.input.image"),
                          ({**vessel, "vessel.workers": 2}, "vessel.workers"),
                          ({**tpms, "tpms.scale.zarr": str(zarr)}, "tpms.scale.zarr"),
                          ({**tpms, "tpms.scale.scheduler": f"tcp://127.0.0.1:{port}"}, "tpms.scale.scheduler"),
                          ({"job": "infill", "value": 0.7, "infill.domain.path": "/etc/passwd"},
                           "infill.domain.path")):
        for route in ("preview", "export"):
            status, data = _api(server, "POST", route, {"design": design})
            assert status == 400, (design, data)
            assert data.get("field") == field, data
            assert "local-only" in data["error"] and "\n" not in data["error"]
    assert not _connected(listener)
    assert not zarr.exists()


def test_the_studio_starts_no_workers():
    """``tpms.scale.scheduler = "local:64"`` started 64 worker processes from one request: refused now."""
    from porecad.studio.design import FieldError, recipe_of
    for design in ({"job": "tpms", "value": 0.6, "tpms.scale.scheduler": "local:64"},
                   {"job": "vessel", "centreline": "c.swc", "vessel.workers": 64, "vessel.executor": "process"}):
        with pytest.raises(FieldError, match="local-only"):
            recipe_of(design, resolve_input=lambda name, kinds: Path("/nonexistent") / name)
