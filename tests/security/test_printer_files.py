"""Issue 56: printer files with exact geometry.

10,000 layers of 0.05 mm (a tall thin part, a coarse pixel): every layer's z exact in every file (whole
nanometres, no float drift), the part on the plate (layer 0 from z = 0, the first layer's top at one layer
height) and centred in the build area, a ``.cli`` binary past its ASCII size bound, ``--report FILE``
written (atomic, refused without ``--force``), the print time in hours and minutes. The files are read
with small readers written here from the formats' descriptions, not with porecad's own reader.
"""

from __future__ import annotations

import io
import json
import re
import struct
import zipfile
from decimal import Decimal

import numpy as np
import pytest
import trimesh

from porecad.cli.main import main
from porecad.fields.base import FunctionField
from porecad.printing import Part, Printer, slice_to

LAYER_NM = 50_000
N = 10_000
BUILD = (20.0, 30.0, 600.0)


def read_cli(data: bytes):
    """``(header lines, [(z text or float, [(dir, (n, 2) µm)])])`` of a CLI file, ASCII or binary (CLI 2.0)."""
    head, body = data.split(b"$$HEADEREND", 1)
    header = head.decode().split()
    layers = []
    if "$$BINARY" in header:
        body = body.lstrip(b"\r\n")
        i = 0
        while i < len(body):
            (cmd,) = struct.unpack_from("<H", body, i)
            if cmd == 127:
                layers.append((struct.unpack_from("<f", body, i + 2)[0], []))
                i += 6
            else:
                assert cmd == 130, cmd
                _, direction, n = struct.unpack_from("<iii", body, i + 2)
                pts = np.frombuffer(body, dtype="<f4", count=2 * n, offset=i + 14).reshape(n, 2)
                layers[-1][1].append((direction, pts))
                i += 14 + 8 * n
        return header, layers
    for line in body.decode().splitlines():
        if line.startswith("$$LAYER/"):
            layers.append((line[8:], []))
        elif line.startswith("$$POLYLINE/"):
            v = line[11:].split(",")
            layers[-1][1].append((int(v[1]), np.asarray(v[3:], dtype=float).reshape(-1, 2)))
    return header, layers


@pytest.fixture()
def tall():
    """A 2 x 3 x 500 mm post (a field: 10,000 layers of 4 x 6 pixels in seconds), off the design origin."""
    lo, hi = np.array([6.0, -5.5, 13.37]), np.array([8.0, -2.5, 513.37])

    def f(x, y, z):
        return np.maximum(np.maximum(np.maximum(lo[0] - x, x - hi[0]), np.maximum(lo[1] - y, y - hi[1])),
                          np.maximum(lo[2] - z, z - hi[2]))
    return Part(lo, hi, field=FunctionField(f))


def test_ten_thousand_layers_exact_on_the_plate(tall, tmp_path):
    part = tall
    printer = Printer(build=BUILD, pixel=0.5, layer=0.05)
    report = slice_to(part, tmp_path / "a.cli", printer, check=False)
    assert report["layers"] == N and report["format"] == "cli"
    header, layers = read_cli((tmp_path / "a.cli").read_bytes())
    assert "$$ASCII" in header and "$$UNITS/0.001000" in header and f"$$LAYERS/{N}" in header
    # the top of layer k is (k + 1) x 50 µm, written exactly: no 0.049999 anywhere in 10,000 layers
    assert [z for z, _ in layers] == [str((k + 1) * LAYER_NM // 1000) for k in range(N)]
    pts = np.vstack([p for _, lines in layers[::500] for _, p in lines]) / 1000
    assert np.allclose(pts.min(axis=0), [9.0, 13.5], atol=1e-3)  # centred in the 20 x 30 mm build area
    assert np.allclose(pts.max(axis=0), [11.0, 16.5], atol=1e-3)
    plate = report["manifest"]["plate"]
    assert plate["origin_nm"][2] == 0 and report["manifest"]["layer_height_nm"] == LAYER_NM
    report = slice_to(part, tmp_path / "a.svg", printer, check=False)
    zs = re.findall(rb'data-z="([^"]+)"', (tmp_path / "a.svg").read_bytes())
    assert [Decimal(z.decode()) for z in zs] == [(k + 1) * Decimal("0.05") for k in range(N)]  # mm, exact


def test_cli_binary_past_its_size_and_exact_z(tall, tmp_path, monkeypatch):
    import porecad.printing.slicing as slicing
    assert slicing.CLI_ASCII_MAX_BYTES == 50_000_000  # the bound (docs/printing.md); lowered for a small part
    monkeypatch.setattr(slicing, "CLI_ASCII_MAX_BYTES", 100_000)  # the 10,000 layers' ASCII is about 1 MB
    report = slice_to(tall, tmp_path / "b.cli", Printer(build=BUILD), pixel=0.5, layer=0.05, check=False)
    assert report["format"] == "cli-binary" and report["cli_ascii_bytes"] > 100_000
    header, layers = read_cli((tmp_path / "b.cli").read_bytes())
    assert "$$BINARY" in header and len(layers) == N
    assert [z for z, _ in layers] == [float((k + 1) * 50) for k in range(N)]  # µm, float32 exact
    assert all(len(lines) == 1 and lines[0][0] == 1 for _, lines in layers)


def test_png_manifest_states_exact_geometry(tall, tmp_path):
    slice_to(tall, tmp_path / "c.zip", Printer(build=BUILD), pixel=0.5, layer=0.05, check=False)
    with zipfile.ZipFile(tmp_path / "c.zip") as z:
        man = json.loads(z.read("manifest.json"))
        assert len([n for n in z.namelist() if n.startswith("layers/")]) == N
    assert man["layer_height_nm"] == LAYER_NM and man["pixel_size_nm"] == 500_000
    assert man["plate"]["origin_nm"] == [9_000_000, 13_500_000, 0]
    report = slice_to(tall, tmp_path / "d.zip", Printer(build=BUILD, place="design"), pixel=0.5, layer=0.05,
                      check=False)  # told otherwise: the design's x and y, still on the plate
    assert report["manifest"]["plate"]["origin_nm"] == [6_000_000, -5_500_000, 0]
    from porecad.errors import InputError
    from porecad.printing import printer_from_toml
    with pytest.raises(InputError, match="place must be one of centre, design"):
        printer_from_toml('place = "left"')


def test_slice_report_file(tmp_path, capsys):
    tall = tmp_path
    post = trimesh.creation.box(extents=[2.0, 3.0, 5.0])
    post.export(tall / "post.stl")
    (tall / "p.toml").write_text("pixel = 0.5\nlayer = 0.05\nlayer_time = 950.0\n")
    args = ["slice", str(tall / "post.stl"), "-o", str(tall / "r.zip"), "--printer", str(tall / "p.toml"),
            "--no-check", "--report", str(tall / "r.json")]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "print_time: 26 h 23 min" in out and "95000" not in out  # 100 x 950 s
    rep = json.loads((tall / "r.json").read_text())
    assert rep["layers"] == 100 and rep["print_time"] == "26 h 23 min" and rep["format"] == "png"
    before = (tall / "r.json").read_bytes()
    assert main(args) != 0  # both exist: refused without --force, the report untouched
    assert "exists" in capsys.readouterr().err and (tall / "r.json").read_bytes() == before
    assert main(args + ["--force", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["report_file"] == str(tall / "r.json")


# ---------------------------------------------------------------------------------------- resin archives
#: config.ini keys of an SL1 as PrusaSlicer writes it (uv3dp's SL1 test file; Prusa's sla-fw reads jobDir,
#: expTime, expTimeFirst, layerHeight, numFade, numFast, numSlow, printTime, ...)
SL1_CONFIG = {"action", "expTime", "expTimeFirst", "fileCreationTimestamp", "jobDir", "layerHeight", "materialName",
              "numFade", "numFast", "numSlow", "printProfile", "printTime", "printerModel", "printerProfile",
              "prusaSlicerVersion", "usedMaterial"}


def _ini(text: str) -> dict:
    import configparser
    cp = configparser.ConfigParser(interpolation=None)
    cp.optionxform = str
    cp.read_string("[top]\n" + text)
    return dict(cp["top"])


def _area(data: bytes, pitch_x: float, pitch_y: float) -> float:
    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(data)).convert("L"), dtype=np.float64)
    return img.sum() / 255 * pitch_x * pitch_y


def read_sl1(path):
    """``(config, slicer ini, [layer PNG bytes], names)``: layers are the PNGs named ``<jobDir>NNNNN.png``, in order."""
    with zipfile.ZipFile(path) as z:
        config = _ini(z.read("config.ini").decode())
        slicer = _ini(z.read("prusaslicer.ini").decode())
        names = z.namelist()
        layers = sorted(n for n in names if n.startswith(config["jobDir"]) and n.endswith(".png"))
        return config, slicer, [z.read(n) for n in layers], names


def read_uvj(path):
    """``(config.json, [layer PNG bytes], names)``: ``slice/NNNNNNNN.png`` in order."""
    with zipfile.ZipFile(path) as z:
        settings = json.loads(z.read("config.json"))
        names = z.namelist()
        return settings, [z.read(n) for n in sorted(n for n in names if n.startswith("slice/"))], names


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    """A ball of radius 2 mm sliced to the PNG ZIP, .sl1, .sl1s and .uvj at 50 µm pixels, 0.1 mm layers."""
    d = tmp_path_factory.mktemp("resin")
    part = Part(np.array([-2.0, -2, 0]), np.array([2.0, 2, 4]),
                field=FunctionField(lambda x, y, z: np.sqrt(x * x + y * y + (z - 2) ** 2) - 2.0))
    printer = Printer(exposure=2.5, bottom_exposure=30.0, bottom_layers=3, layer_time=7.0)
    for name in ("b.zip", "b.sl1", "b.sl1s", "b.uvj"):
        slice_to(part, d / name, printer, pixel=0.05, layer=0.1, check=False)
    with zipfile.ZipFile(d / "b.zip") as z:
        man = json.loads(z.read("manifest.json"))
        ref = [_area(z.read(f"layers/{k:05d}.png"), 0.05, 0.05) for k in range(man["layer_count"])]
    return d, man, ref


@pytest.mark.parametrize("name, model", [("b.sl1", "SL1"), ("b.sl1s", "SL1S")])
def test_sl1_read_back(ball, name, model):
    d, man, ref = ball
    config, slicer, layers, names = read_sl1(d / name)
    assert SL1_CONFIG <= set(config) and config["printerModel"] == model
    assert {"config.ini", "prusaslicer.ini", "thumbnail/thumbnail400x400.png",
            "thumbnail/thumbnail800x480.png"} <= set(names)
    assert Decimal(config["layerHeight"]) == Decimal("0.1") and int(config["numFast"]) == len(layers) == 40
    assert float(config["expTime"]) == 2.5 and float(config["expTimeFirst"]) == 30.0 and config["numFade"] == "3"
    w, h = int(slicer["display_pixels_x"]), int(slicer["display_pixels_y"])
    pitch = (Decimal(slicer["display_width"]) / w, Decimal(slicer["display_height"]) / h)
    assert pitch == (Decimal("0.05"), Decimal("0.05")) and (w, h) == (man["image_width"], man["image_height"])
    areas = [_area(png, 0.05, 0.05) for png in layers]
    assert max(abs(a - r) for a, r in zip(areas, ref)) <= 0.05 ** 2 and max(areas) > 12.0


def test_uvj_read_back(ball):
    d, man, ref = ball
    settings, layers, names = read_uvj(d / "b.uvj")
    size = settings["Properties"]["Size"]
    assert {"preview/tiny.png", "preview/huge.png"} <= set(names)
    assert size["Layers"] == len(layers) == len(settings["Layers"]) == 40
    assert Decimal(str(size["LayerHeight"])) == Decimal("0.1")
    assert [Decimal(str(layer["Z"])) for layer in settings["Layers"]] == [Decimal("0.1") * (k + 1) for k in range(40)]
    assert Decimal(str(size["Millimeter"]["X"])) / size["X"] == Decimal("0.05") == \
        Decimal(str(size["Millimeter"]["Y"])) / size["Y"]
    assert settings["Properties"]["Bottom"]["Count"] == 3 and settings["Properties"]["Exposure"]["LightOnTime"] == 2.5
    areas = [_area(png, 0.05, 0.05) for png in layers]
    assert max(abs(a - r) for a, r in zip(areas, ref)) <= 0.05 ** 2 and max(areas) > 12.0
    from PIL import Image
    tiny = np.asarray(Image.open(io.BytesIO(zipfile.ZipFile(d / "b.uvj").read("preview/tiny.png"))))
    assert tiny.shape == (400, 400) and tiny[200, 200] == 255 and tiny[0, 0] == 0  # the ball seen from above
