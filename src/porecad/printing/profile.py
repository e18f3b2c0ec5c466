"""Printer profiles: the machine a part is sliced for (TOML, untrusted like a recipe).

Keys (all optional; mm unless said)::

    name = "generic DLP"
    build = [120.0, 68.0, 150.0]   # build volume x, y, z
    pixel = 0.05                   # xy pixel
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
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from ..errors import InputError

MAX_PROFILE_BYTES = 64 << 10
PLACES = ("centre", "design")


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

    def as_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}


def _number(key, v, lo, hi):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)) \
            or not lo <= float(v) <= hi:
        raise InputError(f"printer profile: {key} must be a number from {lo:g} to {hi:g}, got {v!r}")
    return float(v)


_RANGES = {"pixel": (1e-4, 10.0), "layer": (1e-4, 10.0), "min_feature": (0.0, 100.0),
           "min_channel": (0.0, 100.0), "max_overhang": (0.0, 90.0), "layer_time": (0.0, 3600.0),
           "exposure": (0.0, 3600.0), "bottom_exposure": (0.0, 3600.0), "bottom_layers": (0, 10000)}


def printer_from_dict(data: dict) -> Printer:
    """A checked :class:`Printer` from a table; unknown keys are refused."""
    if not isinstance(data, dict):
        raise InputError("printer profile: must be a table of keys")
    known = {f.name for f in dataclasses.fields(Printer)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"printer profile: unknown key {unknown[0]!r}; known: {', '.join(sorted(known))}")
    out = {}
    for k, v in data.items():
        if k == "name":
            if not isinstance(v, str) or len(v) > 200:
                raise InputError("printer profile: name must be a text of at most 200 characters")
            out[k] = v
        elif k == "place":
            if v not in PLACES:
                raise InputError(f"printer profile: place must be one of {', '.join(PLACES)}, got {str(v)[:40]!r}")
            out[k] = v
        elif k == "build":
            if not isinstance(v, list) or len(v) != 3:
                raise InputError(f"printer profile: build must be [x, y, z] in mm, got {v!r}")
            out[k] = tuple(_number(f"build[{i}]", b, 0.1, 1e5) for i, b in enumerate(v))
        elif k == "bottom_layers":
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= _RANGES[k][1]:
                raise InputError("printer profile: bottom_layers must be a whole number from 0 to 10000, "
                                 f"got {str(v)[:40]!r}")
            out[k] = v
        else:
            out[k] = _number(k, v, *_RANGES[k])
    return Printer(**out)


def load_printer(path) -> Printer:
    """Read a TOML profile (a regular file of at most 64 KiB)."""
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
