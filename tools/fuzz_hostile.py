"""Hostile cases for the fuzzer (issue 41): what a shared recipe, image or file can try beyond mutation.

Classes: ``confine`` (recipe outputs outside the recipe's folder, with
``--force``), ``detached`` (image headers naming data files elsewhere, a
device or a FIFO), ``special`` (FIFOs, devices, folders and ``/proc`` files
behind ordinary names), ``3mf-nest`` (components multiplying into billions
of placements), ``ivd-params`` (nested parameters of the wrong shape or
size), ``names`` (NUL, over 255 bytes, not encodable), ``bombs`` (headers
honestly declaring gigabytes) and ``signal`` (SIGINT/SIGTERM at seeded times
into a job with mesh, recipe and report). Every case is built in its own
folder; anything written outside the recipe's folder lands in ``outside/``
of the case and is caught as a leftover.

Each case is ``(group, label, argv, setup, signal_at)``: ``setup(work,
argv)`` writes the inputs and returns the argv; ``signal_at`` is None or
``(signal, seconds)``.
"""

from __future__ import annotations

import gzip
import json
import os
import random
import re
import signal
import struct
import zipfile
from pathlib import Path

GROUPS = ("confine", "detached", "special", "3mf-nest", "ivd-params", "names", "bombs", "signal")
#: outputs of the signal cases: after a stop, either all of them exist or none does
SIGNAL_OUTPUTS = {"out.stl", "out.toml", "rep.json"}


def _recipe(work: Path, seed_toml: Path, **outputs) -> Path:
    (work / "shared").mkdir(exist_ok=True)
    (work / "outside").mkdir(exist_ok=True)
    (work / "outside" / "victim.stl").write_bytes(b"do not touch")
    text = re.sub(r"\[output\][^\[]*", "", seed_toml.read_text())
    text += "\n[output]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in outputs.items())
    p = work / "shared" / "r.toml"
    p.write_text(text)
    return p


def confine_cases(files):
    toml = Path(files["toml"])
    escapes = [("absolute", "{work}/outside/victim.stl"), ("dotdot", "../outside/victim.stl"),
               ("dotdot-deep", "a/../../outside/x.stl"), ("home", "~/porecad-fuzz-escape.stl"),
               ("symlink", "link/victim.stl"), ("report-abs", "{work}/outside/r.json")]
    for label, value in escapes:
        def setup(work, argv, value=value):
            p = _recipe(work, toml, mesh="ok.stl", report=value.format(work=work))
            os.symlink(work / "outside", work / "shared" / "link")
            return ["build", str(p), "--force"]
        yield "confine", label, [], setup, None


def _meta(path: Path, data: str, dims="8 8 8") -> None:
    path.write_text(f"ObjectType = Image\nNDims = 3\nDimSize = {dims}\nElementType = MET_UCHAR\n"
                    f"ElementSpacing = 1 1 1\nElementDataFile = {data}\n")


def detached_cases(files):
    infill = ["infill", "{f}", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "out.stl"]
    variants = [("mha-etc", "a.mha", "/etc/passwd", "8 8 8"), ("mhd-dotdot", "b.mhd", "../../x.raw", "8 8 8"),
                ("mha-devzero", "c.mha", "/dev/zero", "1024 1024 1024"), ("mha-fifo", "d.mha", "fifo.raw", "8 8 8"),
                ("mha-list", "e.mha", "LIST", "8 8 8"), ("nhdr-etc", "f.nhdr", None, None)]
    for label, name, data, dims in variants:
        def setup(work, argv, name=name, data=data, dims=dims):
            os.mkfifo(work / "fifo.raw")
            if name.endswith(".nhdr"):
                (work / name).write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n"
                                         "data file: /etc/passwd\n\n")
            else:
                _meta(work / name, data, dims)
            return [str(work / name) if a == "{f}" else a for a in argv]
        yield "detached", label, infill, setup, None


def special_cases(files):
    commands = {".stl": ["analyze", "{f}"], ".3mf": ["analyze", "{f}"], ".nii": ["infill", "{f}", "G", "--label", "1",
                "--threshold", "0", "-o", "out.stl"], ".json": ["vessel", "{f}", "--voxel", "0.5", "-o", "out.stl"],
                ".vtp": ["vessel", "{f}", "--voxel", "0.5", "-o", "out.stl"], ".toml": ["build", "{f}"],
                ".tdf": ["tbss", "--from-tdf", "{f}", "-o", "out.stl"],
                ".csv": ["infill", "{box}", "G", "--porosity-points", "{f}", "--voxel", "0.5", "-o", "out.stl"]}
    for kind in ("fifo", "devzero", "urandom", "proc-mem", "dir"):
        for suffix, argv in commands.items():
            def setup(work, argv, kind=kind, suffix=suffix):
                p = work / f"special{suffix}"
                if kind == "fifo":
                    os.mkfifo(p)
                elif kind == "dir":
                    p.mkdir()
                else:
                    os.symlink({"devzero": "/dev/zero", "urandom": "/dev/urandom", "proc-mem": "/proc/self/mem"}[kind],
                               p)
                return [str(p) if a == "{f}" else a for a in argv]
            yield "special", f"{kind} {suffix}", argv, setup, None


def nested_3mf(path: Path, levels: int, fan: int) -> None:
    verts = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for z in (0, 1) for y in (0, 1) for x in (0, 1))
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in
                   [(0, 2, 1), (1, 2, 3), (4, 5, 6), (5, 7, 6), (0, 1, 4), (1, 5, 4), (2, 6, 3), (3, 6, 7),
                    (0, 4, 2), (2, 4, 6), (1, 3, 5), (3, 7, 5)])
    objs = [f'<object id="1" type="model"><mesh><vertices>{verts}</vertices><triangles>{tris}</triangles>'
            '</mesh></object>']
    for level in range(2, levels + 2):
        comps = "".join(f'<component objectid="{level - 1}" transform="1 0 0 0 1 0 0 0 1 {i} 0 0"/>'
                        for i in range(fan))
        objs.append(f'<object id="{level}" type="model"><components>{comps}</components></object>')
    model = ('<?xml version="1.0" encoding="UTF-8"?><model unit="millimeter" '
             'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02"><resources>' + "".join(objs) +
             f'</resources><build><item objectid="{levels + 1}"/></build></model>')
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("3D/3dmodel.model", model)


def nest_cases(files):
    for levels, fan in ((10, 10), (20, 3), (6, 40), (3, 3)):
        def setup(work, argv, levels=levels, fan=fan):
            nested_3mf(work / "n.3mf", levels, fan)
            return ["analyze", str(work / "n.3mf"), "--json"]
        yield "3mf-nest", f"{fan}^{levels}", [], setup, None


def ivd_cases(files):
    bad = [{"tbss": {"periods": ["x"]}}, {"tbss": {"periods": [[1]] * 16}}, {"tbss": {"fits": [[]]}},
           {"tis": {"tets": 1e6}}, {"arbf": {"tets": 1e6}}, {"tpms": {"porosity": "x"}},
           {"tbss": {"fits": [["sliced", 1e308]]}}, {"arbf": {"resolution": 4096}}]
    for i, params in enumerate(bad):
        def setup(work, argv, params=params):
            import tomli_w
            (work / "img.nii.gz").write_bytes(b"unread")
            r = {"job": "ivd", "input": {"path": "img.nii.gz"}, "methods": ["all"], "params": params,
                 "output": {"dir": "discs"}}
            (work / "ivd.toml").write_text(tomli_w.dumps(r))
            return ["build", str(work / "ivd.toml")]
        yield "ivd-params", f"params {i}", [], setup, None


def name_cases(files):
    base = ["tpms", "G", "--cells", "1", "1", "1", "--resolution", "8", "--threshold", "0.5"]
    for label, name in (("nul", "a\x00b.stl"), ("long", "x" * 300 + ".stl"), ("undecodable", "\udcff.stl"),
                        ("long-dir", "y" * 256 + "/a.stl")):
        for flag in ("-o", "--recipe", "--report"):
            argv = base + (["-o", "out.stl"] if flag != "-o" else []) + [flag, name]
            yield "names", f"{label} {flag}", argv, None, None
    for label, name in (("recipe-nul", "a\\u0000b.stl"), ("recipe-long", "z" * 300 + ".stl")):
        def setup(work, argv, name=name):
            p = _recipe(work, Path(files["toml"]), mesh="ok.stl")
            p.write_text(p.read_text().replace('"ok.stl"', f'"{name}"'))
            return ["build", str(p)]
        yield "names", label, [], setup, None


def _nifti_gz(path: Path, dims) -> None:
    hdr = bytearray(348)
    struct.pack_into("<i", hdr, 0, 348)
    struct.pack_into("<8h", hdr, 40, 3, *dims, 1, 1, 1, 1)
    struct.pack_into("<hh", hdr, 70, 2, 8)
    struct.pack_into("<8f", hdr, 76, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into("<f", hdr, 108, 352.0)
    hdr[344:348] = b"n+1\x00"
    path.write_bytes(gzip.compress(bytes(hdr) + b"\x00" * (4 + (1 << 20)), 1))


def bomb_cases(files):
    def nii(work, argv):
        _nifti_gz(work / "big.nii.gz", (1024, 1024, 1024))
        return ["infill", str(work / "big.nii.gz"), "G", "--label", "1", "--threshold", "0", "-o", "out.stl"]
    yield "bombs", "nii.gz declares 1024^3", [], nii, None

    def recipe_digits(work, argv):
        (work / "r.toml").write_text('job = "tpms"\nformat = 1' + "0" * 4400 + "\n")
        return ["build", str(work / "r.toml")]
    yield "bombs", "format with 4400 digits", [], recipe_digits, None
    yield "bombs", "tdf edit 1e308", ["tbss", "--from-tdf", "{tdf}", "--edit", "w > 0.75", "1e308", "-o", "out.stl"], \
        None, None


def signal_cases(files, count: int, seed: int, span: float = 1.2):
    rng = random.Random(f"signals:{seed}")
    job = ["tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "2", "2", "2", "--resolution", "20",
           "-o", "out.stl", "--recipe", "out.toml", "--report", "rep.json"]
    for i in range(count):
        sig = signal.SIGINT if i % 2 else signal.SIGTERM
        at = round(rng.uniform(0.05, span), 2)
        yield "signal", f"{sig.name} at {at} s", job, None, (sig, at)


def hostile_cases(files, signals: int = 20, seed: int = 0):
    """Every hostile case (see the module docstring)."""
    for gen in (confine_cases, detached_cases, special_cases, nest_cases, ivd_cases, name_cases, bomb_cases):
        yield from gen(files)
    yield from signal_cases(files, signals, seed)
