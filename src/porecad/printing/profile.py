"""Printer profiles: the machine a part is sliced for (TOML, untrusted like a recipe), and the shipped presets.

Keys (all optional; mm unless said)::

    name = "generic DLP"
    build = [120.0, 68.0, 150.0]   # build volume x, y, z
    pixel = 0.05                   # xy pixel: sets pixel_x and pixel_y both
    pixel_x = 0.019                # the pixel along x (a display's columns), when not square
    pixel_y = 0.024                # the pixel along y
    layer = 0.05                   # layer height
    min_feature = 0.2              # thinnest wall or strut it prints
    min_channel = 0.3              # narrowest pore that still drains
    max_overhang = 45.0            # degrees from vertical printed without supports
    layer_time = 8.0               # seconds per layer (print-time estimate)
    exposure = 2.0                 # resin: seconds of light per layer (.sl1, .uvj)
    bottom_exposure = 20.0         # resin: seconds for each of the first bottom_layers
    bottom_layers = 4
    place = "centre"               # the part on the plate (z from 0), centred in the build area;
                                   # "design": at its design x and y (still z from 0)
    display_pixels_x = 2560        # the display as PrusaSlicer names it: pixels along the plate's x and y,
    display_pixels_y = 1440        #   its size (mm; default pixels x pitch), orientation and mirroring;
    display_width = 120.96         #   with a display, a .sl1 is the printer's whole canvas (formats.py)
    display_height = 68.04
    display_orientation = "portrait"
    display_mirror_x = true
    display_mirror_y = false
    model = "SL1"                  # printerModel of a .sl1 (default: SL1, or SL1S for a .sl1s)
    format = "sl1"                 # the format an output without a known extension gets

Every length is held in whole nanometres (rounded when read). A preset is a shipped profile picked by name
(:func:`preset_names`); a name is looked up in that list only, never used as a path.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from ..errors import InputError

MAX_PROFILE_BYTES = 64 << 10
PLACES = ("centre", "design")
ORIENTATIONS = ("landscape", "portrait")
#: the largest display canvas (a 16K display is 15120 x 6230 = 94 M pixels): one layer's image is held whole
MAX_DISPLAY_PIXELS = 100_000_000
#: the slice formats a profile's ``format`` may name (:data:`porecad.printing.formats.NAMES`)
FORMAT_NAMES = ("png", "svg", "cli", "cli-binary", "sl1", "uvj")


def _nm_mm(v: float) -> float:
    return int(round(float(v) * 1e6)) / 1e6


@dataclasses.dataclass(frozen=True)
class Printer:
    name: str = "generic DLP (50 µm)"
    build: tuple = (120.0, 68.0, 150.0)
    pixel: float = 0.05
    layer: float = 0.05
    min_feature: float = 0.2
    min_channel: float = 0.3
    max_overhang: float = 45.0
    layer_time: float = 8.0
    exposure: float = 2.0
    bottom_exposure: float = 20.0
    bottom_layers: int = 4
    place: str = "centre"
    pixel_x: float | None = None  # None: ``pixel``
    pixel_y: float | None = None
    display_pixels_x: int = 0  # 0: no display given
    display_pixels_y: int = 0
    display_width: float = 0.0  # 0: display_pixels_x x pixel_x
    display_height: float = 0.0
    display_orientation: str = "landscape"
    display_mirror_x: bool = False
    display_mirror_y: bool = False
    model: str = ""
    format: str = ""

    def __post_init__(self):
        for k in ("pixel_x", "pixel_y"):
            object.__setattr__(self, k, _nm_mm(self.pixel if getattr(self, k) is None else getattr(self, k)))
        if self.display_pixels_x and not self.display_width:
            object.__setattr__(self, "display_width", self.display_pixels_x * self.pixel_x)
        if self.display_pixels_y and not self.display_height:
            object.__setattr__(self, "display_height", self.display_pixels_y * self.pixel_y)

    @property
    def has_display(self) -> bool:
        return self.display_pixels_x > 0 and self.display_pixels_y > 0

    def as_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}


def _number(key, v, lo, hi):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)) \
            or not lo <= float(v) <= hi:
        raise InputError(f"printer profile: {key} must be a number from {lo:g} to {hi:g}, got {v!r}")
    return float(v)


def _whole(key, v, lo, hi):
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise InputError(f"printer profile: {key} must be a whole number from {lo} to {hi}, got {str(v)[:40]!r}")
    return v


def _choice(key, v, options):
    if not isinstance(v, str) or v not in options:
        raise InputError(f"printer profile: {key} must be one of {', '.join(o for o in options if o)}, "
                         f"got {str(v)[:40]!r}")
    return v


_RANGES = {"pixel": (1e-4, 10.0), "pixel_x": (1e-4, 10.0), "pixel_y": (1e-4, 10.0), "layer": (1e-4, 10.0),
           "min_feature": (0.0, 100.0), "min_channel": (0.0, 100.0), "max_overhang": (0.0, 90.0),
           "layer_time": (0.0, 3600.0), "exposure": (0.0, 3600.0), "bottom_exposure": (0.0, 3600.0),
           "display_width": (0.0, 1e5), "display_height": (0.0, 1e5)}  # a display's 0: not given
_WHOLE = {"bottom_layers": (0, 10000), "display_pixels_x": (0, 100_000), "display_pixels_y": (0, 100_000)}
_CHOICES = {"place": PLACES, "display_orientation": ORIENTATIONS, "format": ("",) + FORMAT_NAMES}


def _value(k, v):
    """One checked key of a profile."""
    if k in ("name", "model"):
        if not isinstance(v, str) or len(v) > 200 or (k == "model" and v and not v.replace("-", "").isalnum()):
            raise InputError(f"printer profile: {k} must be a text of at most 200 characters"
                             + (" (letters, digits and -)" if k == "model" else ""))
        return v
    if k in _CHOICES:
        return _choice(k, v, _CHOICES[k])
    if k in ("display_mirror_x", "display_mirror_y"):
        if not isinstance(v, bool):
            raise InputError(f"printer profile: {k} must be true or false, got {str(v)[:40]!r}")
        return v
    if k == "build":
        if not isinstance(v, list) or len(v) != 3:
            raise InputError(f"printer profile: build must be [x, y, z] in mm, got {str(v)[:60]!r}")
        return tuple(_number(f"build[{i}]", b, 0.1, 1e5) for i, b in enumerate(v))
    if k in _WHOLE:
        return _whole(k, v, *_WHOLE[k])
    out = _number(k, v, *_RANGES[k])
    return _nm_mm(out) if k.startswith("pixel") or k == "layer" else out


def _display(out: dict) -> None:
    """Check the display keys together; a pixel not given is the display's pitch (width / pixels)."""
    given = [k for k in ("display_pixels_x", "display_pixels_y") if out.get(k)]
    if len(given) == 1 or (not given and (out.get("display_width") or out.get("display_height"))):
        raise InputError("printer profile: give display_pixels_x and display_pixels_y together "
                         "(display_width and display_height need them)")
    if not given:
        return
    if out["display_pixels_x"] * out["display_pixels_y"] > MAX_DISPLAY_PIXELS:  # one layer's canvas in memory
        raise InputError(f"printer profile: display_pixels_x x display_pixels_y is at most {MAX_DISPLAY_PIXELS:,}, "
                         f"got {out['display_pixels_x']} x {out['display_pixels_y']}")
    for axis, size in (("x", "display_width"), ("y", "display_height")):
        px_key, n = f"pixel_{axis}", out[f"display_pixels_{axis}"]
        if not out.get(size):
            continue
        pitch = out[size] / n
        if px_key not in out and "pixel" not in out:
            out[px_key] = _nm_mm(pitch)
            continue
        have = out.get(px_key, out.get("pixel"))
        if abs(have - pitch) * 1e6 > 0.5 + 1e-6:  # a nanometre's rounding
            raise InputError(f"printer profile: {size} ({out[size]:g} mm) over display_pixels_{axis} ({n}) is a "
                             f"{pitch:.6g} mm pixel, but {px_key} is {have:g} mm")


def printer_from_dict(data: dict) -> Printer:
    """A checked :class:`Printer` from a table; unknown keys are refused."""
    if not isinstance(data, dict):
        raise InputError("printer profile: must be a table of keys")
    known = {f.name for f in dataclasses.fields(Printer)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"printer profile: unknown key {str(unknown[0])[:40]!r}; known: {', '.join(sorted(known))}")
    out = {k: _value(k, v) for k, v in data.items()}
    _display(out)
    return Printer(**out)


def preset_names() -> list:
    """The names of the shipped printer presets (``porecad/printing/presets/<name>.toml``)."""
    from importlib import resources
    root = resources.files(__package__).joinpath("presets")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def is_preset_name(name) -> bool:
    """Whether ``name`` asks for a preset: a bare name, no path separator, no ``.toml``."""
    s = str(name)
    return "/" not in s and "\\" not in s and not s.lower().endswith(".toml") and s not in ("", ".", "..")


def load_preset(name: str) -> Printer:
    """A shipped preset by name: matched against :func:`preset_names` only, never used as a path."""
    from importlib import resources
    names = preset_names()
    if name not in names:
        raise InputError(f"{str(name)[:60]!r}: no such printer preset; presets: {', '.join(names)} "
                         "(or give a .toml profile file)")
    raw = resources.files(__package__).joinpath("presets", f"{names[names.index(name)]}.toml").read_bytes()
    return printer_from_toml(raw, f"the {name} preset")


def load_printer(path) -> Printer:
    """A TOML profile file (a regular file of at most 64 KiB), or a preset by its bare name (:func:`load_preset`)."""
    if is_preset_name(path):
        return load_preset(str(path))
    p = Path(path)
    try:
        if not p.is_file():
            raise InputError(f"{path}: printer profile not found (or not a regular file)")
        raw = p.read_bytes()[:MAX_PROFILE_BYTES + 1]
    except OSError as exc:
        raise InputError(f"{path}: cannot read the printer profile ({exc.strerror})") from None
    return printer_from_toml(raw, str(path))


def printer_from_toml(raw, where: str = "the printer profile") -> Printer:
    """A checked :class:`Printer` from TOML text or bytes (at most 64 KiB; ``where`` names it in errors)."""
    import tomllib
    if isinstance(raw, str):
        raw = raw.encode("utf-8", "surrogatepass")
    if len(raw) > MAX_PROFILE_BYTES:
        raise InputError(f"{where}: a printer profile is at most 64 KiB")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError) as exc:
        raise InputError(f"{where}: not a valid TOML printer profile ({' '.join(str(exc).split())[:100]})") from None
    return printer_from_dict(data)


def printer_toml(printer: Printer) -> str:
    """The profile as TOML text (every key; :func:`printer_from_toml` reads it back)."""
    import tomli_w
    return tomli_w.dumps(printer.as_dict())
