"""Issue 56: non-square pixels, shipped printer presets, printer-ready .sl1 canvases.

Areas are measured from the written files (Pillow) against trimesh sections of a mesh of the same design;
the .sl1/.sl1s/.uvj archives are read back with the small readers here (zipfile, configparser, json,
Pillow), written from the formats' descriptions (PrusaSlicer's SL1Archive writer and raster transform,
Prusa's SLA firmware reader, UVtools' UVJ), not with porecad's own code.
"""

from __future__ import annotations

import configparser
import io
import json
import zipfile
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from shapely.geometry import Polygon

from porecad.cli.main import main
from porecad.errors import InputError
from porecad.fields.base import FunctionField
from porecad.printing import Part, Printer, load_printer, printer_from_dict, slice_to
from porecad.printing.profile import preset_names
from section_reference import section_area

PX, PY = 0.019, 0.024  # the Saturn 4 Ultra's pixel (presets/elegoo-saturn-4-ultra.toml)


def grey_area(data: bytes, px: float, py: float) -> float:
    img = np.asarray(Image.open(io.BytesIO(data)).convert("L"), dtype=np.float64)
    return img.sum() / 255 * px * py


def zip_layers(path, prefix):
    with zipfile.ZipFile(path) as z:
        names = sorted(n for n in z.namelist() if n.startswith(prefix) and n.endswith(".png"))
        return [z.read(n) for n in names]


def ini(text: str) -> dict:
    cp = configparser.ConfigParser(interpolation=None)
    cp.optionxform = str
    cp.read_string("[top]\n" + text)
    return dict(cp["top"])


# ------------------------------------------------------------------------------------------ non-square pixels
@pytest.fixture(scope="module")
def gyroid_19x24(tmp_path_factory):
    """The gyroid sheet box of test_printing (2 x 2 x 1 cells of 2 mm) on 19 x 24 µm pixels, and a fine mesh."""
    from porecad.lattice.plan import plan_lattice
    from porecad.jobs.runner import parse
    from porecad.mesh.polygonise import polygonise
    from porecad.printing import from_source
    d = tmp_path_factory.mktemp("aniso")
    recipe = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": 2.0},
              "domain": {"kind": "box", "cells": [2, 2, 1]}, "sampling": {"resolution": 60}}
    plan = plan_lattice(parse(recipe, d)[1])
    res = polygonise(plan.field.sample_grid, plan.grid, caps=True)
    mesh = trimesh.Trimesh(res.vertices, res.faces)
    printer = printer_from_dict({"pixel_x": PX, "pixel_y": PY, "layer": 0.1})
    report = slice_to(from_source(recipe, d), d / "g.zip", printer, check=False)
    return d, mesh, report


def test_field_route_on_19_by_24_micron_pixels(gyroid_19x24):
    d, mesh, report = gyroid_19x24
    with zipfile.ZipFile(d / "g.zip") as z:
        man = json.loads(z.read("manifest.json"))
    assert (man["pixel_x_nm"], man["pixel_y_nm"]) == (19_000, 24_000)
    assert (man["image_width"], man["image_height"]) == (211, 167)  # ceil(4 / 0.019), ceil(4 / 0.024)
    layers = zip_layers(d / "g.zip", "layers/")
    assert len(layers) == man["layer_count"] == 20
    assert Image.open(io.BytesIO(layers[0])).size == (211, 167)
    errs = []
    for k, png in enumerate(layers):
        ref = section_area(mesh, man["origin"][2] + (k + 0.5) * man["layer_height"])
        errs.append(abs(grey_area(png, PX, PY) - ref) / ref)
    assert max(errs) < 0.01, max(errs)
    assert report["pixel_x"] == PX and report["pixel_y"] == PY


@pytest.fixture(scope="module")
def l_prism():
    """An L-shaped prism, 3 mm in x and 2 mm in y, 1 mm tall: its arm along x tells x from y in an image."""
    outline = Polygon([(0, 0), (3, 0), (3, 0.8), (0.8, 0.8), (0.8, 2), (0, 2)])
    m = trimesh.creation.extrude_polygon(outline, 1.0)
    m.apply_translation([0.3, -0.2, 0.0])
    return m


def test_mesh_route_on_19_by_24_micron_pixels(l_prism, tmp_path, capsys):
    l_prism.export(tmp_path / "l.stl")
    assert main(["slice", str(tmp_path / "l.stl"), "-o", str(tmp_path / "l.zip"), "--pixel-x", "0.019",
                 "--pixel-y", "0.024", "--layer", "0.1", "--no-check", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["route"] == "mesh" and report["layers"] == 10 and report["image"] == [158, 84]
    layers = zip_layers(tmp_path / "l.zip", "layers/")
    for k, png in enumerate(layers):
        ref = section_area(l_prism, (k + 0.5) * 0.1)
        assert abs(grey_area(png, PX, PY) - ref) / ref < 0.01
    img = np.asarray(Image.open(io.BytesIO(layers[5])), dtype=float) / 255
    assert img.shape == (84, 158)  # rows along y (24 µm), columns along x (19 µm)
    bottom, left = img[-int(0.7 / PY):].mean(), img[:, :int(0.7 / PX)].mean()
    assert bottom > 0.95 and left > 0.95 and img[:int(1.0 / PY), -int(1.0 / PX):].max() == 0  # row 0: largest y


def test_pixel_options_and_profile_keys(tmp_path, capsys):
    trimesh.creation.box([1, 1, 1]).export(tmp_path / "b.stl")
    base = ["slice", str(tmp_path / "b.stl"), "-o", str(tmp_path / "b.zip"), "--no-check"]
    assert main(base + ["--pixel", "0.05", "--pixel-x", "0.02"]) != 0
    assert "not both" in capsys.readouterr().err
    (tmp_path / "p.toml").write_text("pixel = 0.05\npixel_y = 0.1\nlayer = 0.5\n")
    assert main(base + ["--printer", str(tmp_path / "p.toml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["image"] == [20, 10]  # pixel sets x, pixel_y overrides y
    assert main(base + ["--printer", str(tmp_path / "p.toml"), "--pixel", "0.25", "--json", "--force"]) == 0
    assert json.loads(capsys.readouterr().out)["image"] == [4, 4]  # --pixel: both
    p = Printer(pixel=0.1)
    assert (p.pixel_x, p.pixel_y) == (0.1, 0.1)
    assert printer_from_dict({"pixel_x": 0.0190000004}).pixel_x == 0.019  # whole nanometres
    for bad, word in (({"pixel_x": 0}, "pixel_x"), ({"pixel_y": float("nan")}, "pixel_y"),
                      ({"display_pixels_x": 100}, "together"), ({"display_orientation": "sideways"}, "portrait"),
                      ({"display_pixels_x": 10, "display_pixels_y": 10, "display_width": 1.0, "pixel_x": 0.2},
                       "display_width"), ({"display_mirror_x": 1}, "true or false"), ({"format": "gcode"}, "format"),
                      ({"model": "SL1/../x"}, "model"), ({"display_pixels_x": 100_000, "display_pixels_y": 100_000},
                                                          "at most 100,000,000")):
        with pytest.raises(InputError, match=word):
            printer_from_dict(bad)


# ------------------------------------------------------------------------------------------------ presets
def test_presets_are_shipped_and_picked_by_name_only(tmp_path, capsys, monkeypatch):
    names = preset_names()
    assert {"prusa-sl1", "prusa-sl1s", "elegoo-saturn-4-ultra", "generic-slm"} <= set(names)
    root = Path(__file__).resolve().parents[2]
    for n in names:  # each preset names its public source
        text = (root / "src/porecad/printing/presets" / f"{n}.toml").read_text(encoding="utf-8")
        assert text.startswith("#") and ("http" in text or "Not a particular machine" in text)
    sl1 = load_printer("prusa-sl1")
    assert (sl1.pixel_x, sl1.display_pixels_x, sl1.display_pixels_y, sl1.format) == (0.04725, 2560, 1440, "sl1")
    sat = load_printer("elegoo-saturn-4-ultra")
    assert (sat.pixel_x, sat.pixel_y) == (PX, PY)
    # the package data line of pyproject.toml ships them in the wheel
    import tomllib
    data = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["porecad"]
    assert "printing/presets/*.toml" in data
    # a name is matched against the presets only, never used as a path
    monkeypatch.chdir(tmp_path)
    (tmp_path / "prusa-sl2").write_text('name = "a file, not a preset"\n')
    with pytest.raises(InputError, match="no such printer preset; presets: elegoo-saturn-4-ultra"):
        load_printer("prusa-sl2")
    for path_like in ("./prusa-sl1", "../presets/prusa-sl1", "prusa-sl1.toml"):
        with pytest.raises(InputError, match="not found"):
            load_printer(path_like)


def test_a_preset_names_its_format(tmp_path, capsys):
    part = tmp_path / "cube.stl"
    trimesh.creation.box([2, 2, 0.2]).export(part)
    assert main(["slice", str(part), "-o", str(tmp_path / "part"), "--printer", "prusa-sl1s", "--no-check",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == "sl1"
    with zipfile.ZipFile(tmp_path / "part") as z:
        assert ini(z.read("config.ini").decode())["printerModel"] == "SL1S"
    assert main(["slice", str(part), "-o", str(tmp_path / "part.svg"), "--printer", "prusa-sl1", "--no-check",
                 "--json"]) == 0  # the extension wins
    assert json.loads(capsys.readouterr().out)["format"] == "svg"
    assert main(["slice", str(part), "-o", str(tmp_path / "x"), "--printer", "no-such-printer"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such printer preset" in err[0] and "prusa-sl1" in err[0]


# ------------------------------------------------------------------------------------- printer-ready .sl1
def expected_canvas(mask_xy: np.ndarray, orientation: str, mirror_x: bool, mirror_y: bool) -> np.ndarray:
    """PrusaSlicer's SL1 raster of a mask indexed [x, y] on the display (RasterBase::Trafo, AGGRaster::to_path):
    portrait swaps x and y (flipXY), then the raster mirrors x when trafo.mirror_x (= !display_mirror_x in
    portrait, display_mirror_x in landscape) and y when trafo.mirror_y (= !display_mirror_y); rows go down."""
    portrait = orientation == "portrait"
    img = mask_xy if portrait else mask_xy.T  # [row, column] before mirroring: rows along y in landscape
    trafo_mirror_x = (not mirror_x) if portrait else mirror_x
    trafo_mirror_y = not mirror_y
    if trafo_mirror_x:
        img = img[:, ::-1]
    if trafo_mirror_y:
        img = img[::-1]
    return img


def ball_part():
    return Part(np.array([-2.0, -2, 0]), np.array([2.0, 2, 4]),
                field=FunctionField(lambda x, y, z: np.sqrt(x * x + y * y + (z - 2) ** 2) - 2.0))


@pytest.mark.parametrize("preset, ext, model, size", [("prusa-sl1", "sl1", "SL1", (1440, 2560)),
                                                      ("prusa-sl1s", "sl1s", "SL1S", (1620, 2560))])
def test_sl1_is_the_printers_whole_canvas(tmp_path, preset, ext, model, size):
    printer = load_printer(preset)
    part = ball_part()
    slice_to(part, tmp_path / "b.zip", printer, layer=0.1, check=False)
    slice_to(part, tmp_path / f"b.{ext}", printer, layer=0.1, check=False)
    ref = [grey_area(p, printer.pixel_x, printer.pixel_y) for p in zip_layers(tmp_path / "b.zip", "layers/")]
    with zipfile.ZipFile(tmp_path / f"b.{ext}") as z:
        names = z.namelist()
        config, slicer = ini(z.read("config.ini").decode()), ini(z.read("prusaslicer.ini").decode())
        thumbs = {n: Image.open(io.BytesIO(z.read(n))) for n in names if n.startswith("thumbnail/")}
    # the files and keys PrusaSlicer's SL1Archive::export_print writes (fill_iniconf, the sorted ini)
    assert {"config.ini", "prusaslicer.ini", "thumbnail/thumbnail400x400.png",
            "thumbnail/thumbnail800x480.png"} <= set(names)
    assert {"action", "expTime", "expTimeFirst", "expUserProfile", "fileCreationTimestamp", "hollow", "jobDir",
            "layerHeight", "materialName", "numFade", "numFast", "numSlow", "printProfile", "printTime",
            "printerModel", "printerProfile", "printerVariant", "prusaSlicerVersion", "usedMaterial"} <= set(config)
    assert config["printerModel"] == model and config["action"] == "print"
    assert all(t.mode == "RGBA" and t.size == tuple(map(int, n[19:-4].split("x"))) for n, t in thumbs.items())
    layers = zip_layers(tmp_path / f"b.{ext}", config["jobDir"])
    assert [n for n in names if n.startswith(config["jobDir"])][:2] == [f"{config['jobDir']}00000.png",
                                                                        f"{config['jobDir']}00001.png"]
    assert len(layers) == int(config["numFast"]) + int(config["numSlow"]) == len(ref) == 40
    assert Decimal(config["layerHeight"]) == Decimal("0.1")
    assert (slicer["display_orientation"], slicer["display_mirror_x"], slicer["display_mirror_y"]) == \
        ("portrait", "1", "0")
    nx, ny = int(slicer["display_pixels_x"]), int(slicer["display_pixels_y"])
    pitch = (Decimal(slicer["display_width"]) / nx, Decimal(slicer["display_height"]) / ny)
    assert pitch == (Decimal(str(printer.pixel_x)),) * 2
    for png, r in zip(layers, ref):
        img = Image.open(io.BytesIO(png))
        assert img.mode == "L" and img.size == size  # portrait: display_pixels_y wide, display_pixels_x tall
        assert abs(grey_area(png, printer.pixel_x, printer.pixel_y) - r) <= printer.pixel_x * printer.pixel_y


def test_canvas_place_orientation_and_mirrors(tmp_path):
    """A 2 x 1 mm block at x 10..12, y 5..6 on the plate (place = design) lands where PrusaSlicer's raster
    puts it, for portrait and landscape and every mirror."""
    block = Part(np.array([10.0, 5.0, 0.0]), np.array([12.0, 6.0, 0.2]), field=FunctionField(
        lambda x, y, z: np.maximum(np.maximum(np.maximum(10 - x, x - 12), np.maximum(5 - y, y - 6)),
                                   np.maximum(-z, z - 0.2))))
    base = {**load_printer("prusa-sl1").as_dict(), "place": "design", "display_pixels_x": 400,
            "display_pixels_y": 200, "display_width": 18.9, "display_height": 9.45, "build": [18.9, 9.45, 10.0]}
    xs = (np.arange(400) + 0.5) * 0.04725
    ys = (np.arange(200) + 0.5) * 0.04725
    mask = ((xs[:, None] > 10) & (xs[:, None] < 12)) & ((ys[None, :] > 5) & (ys[None, :] < 6))  # [x, y]
    for orientation in ("portrait", "landscape"):
        for mx in (False, True):
            for my in (False, True):
                printer = printer_from_dict({**base, "display_orientation": orientation, "display_mirror_x": mx,
                                             "display_mirror_y": my})
                out = tmp_path / f"{orientation}{mx:d}{my:d}.sl1"
                slice_to(block, out, printer, layer=0.1, check=False)
                img = np.asarray(Image.open(io.BytesIO(zip_layers(out, "porecad")[1]))) > 127
                want = expected_canvas(mask, orientation, mx, my)
                assert img.shape == want.shape and (img != want).sum() <= 2 * (60 + 30), (orientation, mx, my)
                with zipfile.ZipFile(out) as z:
                    s = ini(z.read("prusaslicer.ini").decode())
                assert (s["display_orientation"], s["display_mirror_x"], s["display_mirror_y"]) == \
                    (orientation, str(int(mx)), str(int(my)))


def test_sl1_refuses_another_pixel_and_a_part_off_the_display(tmp_path):
    printer = load_printer("prusa-sl1")
    with pytest.raises(InputError, match="display's canvas"):
        slice_to(ball_part(), tmp_path / "b.sl1", printer, pixel=0.05, layer=0.1, check=False)
    off = printer_from_dict({**printer.as_dict(), "place": "design"})
    far = Part(np.array([-3.0, 0, 0]), np.array([-1.0, 1, 1]), field=FunctionField(lambda x, y, z: 0 * x - 1))
    with pytest.raises(InputError, match="does not fit the printer's display"):
        slice_to(far, tmp_path / "f.sl1", off, layer=0.5, check=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_uvj_on_non_square_pixels_read_back(tmp_path):
    """A .uvj for the 19 x 24 µm printer: UVtools' Properties.Size gives the pitch; each layer's area is the
    PNG ZIP's within one pixel."""
    printer = load_printer("elegoo-saturn-4-ultra")
    part = ball_part()
    slice_to(part, tmp_path / "b.zip", printer, layer=0.2, check=False)
    slice_to(part, tmp_path / "b.uvj", printer, layer=0.2, check=False)
    ref = [grey_area(p, PX, PY) for p in zip_layers(tmp_path / "b.zip", "layers/")]
    with zipfile.ZipFile(tmp_path / "b.uvj") as z:
        settings = json.loads(z.read("config.json"))
    size = settings["Properties"]["Size"]
    pitch = (Decimal(str(size["Millimeter"]["X"])) / size["X"], Decimal(str(size["Millimeter"]["Y"])) / size["Y"])
    assert pitch == (Decimal("0.019"), Decimal("0.024"))
    layers = zip_layers(tmp_path / "b.uvj", "slice/")
    assert size["Layers"] == len(layers) == len(settings["Layers"]) == len(ref) == 20
    assert [Decimal(str(v["Z"])) for v in settings["Layers"]] == [Decimal("0.2") * (k + 1) for k in range(20)]
    areas = [grey_area(p, float(pitch[0]), float(pitch[1])) for p in layers]
    assert max(abs(a - r) for a, r in zip(areas, ref)) <= PX * PY and max(areas) > 12.0
