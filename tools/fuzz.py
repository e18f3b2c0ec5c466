"""Seeded mutation fuzzer for porecad's readers and numeric command-line options (issue 19).

Every case runs the real command line (``porecad.cli.main.main``) in a
forked child process, in a fresh directory, under resource limits: address
space (``RLIMIT_AS``, default 4 GiB) and CPU time (``RLIMIT_CPU``, default
30 s; a case past it is a hang — CPU time, so that a loaded machine does not
turn slow cases into hangs), with a wall-clock limit several times longer
(then SIGKILL) for a case that sleeps. Each case is classified:

``refusal``      non-zero exit with exactly one ``porecad: error:`` line (warnings aside)
``success``      exit 0
``messy``        a refusal whose message is not one line
``traceback``    a Python traceback on stderr (an unhandled exception)
``crash``        killed by a signal (SIGSEGV, SIGABRT, ...)
``hang``         past the CPU-time limit, or still running at the wall-clock limit
``blow-up``      peak memory above the limit, or a MemoryError (nothing estimated it up front)
``leftover``     a temporary file left behind, or any new file after a refusal

Mutants are derived deterministically from small valid seed files that the
fuzzer writes itself (``--seed`` picks the random stream): byte flips,
interesting bytes, chunk deletion, duplication and truncation, and
replacement of number tokens with 0, -1, 1e30, 1e308, nan, inf, 2**62 and
very long digit strings; zip (3MF) and gzip (NIfTI) files are mutated inside
and re-packed as well as raw. The option sweep gives every numeric option
of every command (found by walking the click commands) the values 0, -1,
nan, inf, 1e308 and 2**62 on a baseline command line that succeeds.

Usage::

    python tools/fuzz.py --mutants 200 --jobs 2 --table fuzz-table.md     # the full run
    python tools/fuzz.py --formats stl,3mf --mutants 20 --no-options       # a few formats
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import io
import os
import random
import re
import resource
import shutil
import signal
import sys
import tempfile
import time
import zipfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MALLOC_ARENA_MAX", "2")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fuzz_hostile import GROUPS as HOSTILE_GROUPS, SIGNAL_OUTPUTS, hostile_cases  # noqa: E402, F401 (HOSTILE_GROUPS: read by the tests)

ROOT = Path(__file__).resolve().parents[1]
CLASSES = ("refusal", "success", "messy", "traceback", "crash", "hang", "blow-up", "leftover")
BAD_VALUES = ("0", "-1", "nan", "inf", "1e308", str(2 ** 62))
NUMBERS = ("0", "-1", "1e30", "-1e30", "1e308", "nan", "inf", "-inf", str(2 ** 62), str(2 ** 31), "4294967295",
           "9" * 400, "0.0000001", "1e-320", "65535", "-2147483648")
INTERESTING = (b"\x00", b"\xff", b"\x7f", b"\x80", b"<", b">", b"&", b"\"", b"\n", b"#", b"-", b"e", b"9")
_NUM = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


# ----------------------------------------------------------------------------------------------- seeds
def _box_mesh(size=10.0):
    v = np.array([[x, y, z] for z in (0, size) for y in (0, size) for x in (0, size)], float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
                  [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return v, f


def _cube_tets(n=2, size=10.0):
    """A cube of n^3 sub-cubes, 6 positive tets each (Kuhn split)."""
    g = np.stack(np.meshgrid(*[np.linspace(0, size, n + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    tets, hexes = [], []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                c = [idx[i + a, j + b, k + d] for d in (0, 1) for b in (0, 1) for a in (0, 1)]
                hexes.append([c[0], c[1], c[3], c[2], c[4], c[5], c[7], c[6]])
                for t in ((0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)):
                    tets.append([c[m] for m in t])
    tets = np.array(tets)
    p = g[tets]
    vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
    tets[vol < 0] = tets[vol < 0][:, [1, 0, 2, 3]]
    return g, tets, np.array(hexes)


def _ascii_stl(v, f) -> bytes:
    out = ["solid box"]
    for t in f:
        out.append("  facet normal 0 0 0\n    outer loop")
        out += [f"      vertex {v[i][0]:g} {v[i][1]:g} {v[i][2]:g}" for i in t]
        out.append("    endloop\n  endfacet")
    return ("\n".join(out) + "\nendsolid box\n").encode()


def make_seeds(where: Path) -> dict:
    """Write one small valid file per format; returns ``{format: path}``."""
    from porecad.io import write_mesh
    from porecad.io.tdf_file import TDFRecord, write_tdf
    from porecad.volmesh.tetio import write_tet_mesh
    import meshio

    where.mkdir(parents=True, exist_ok=True)
    v, f = _box_mesh()
    seeds = {}
    for fmt in ("stl", "obj", "ply", "3mf"):
        seeds[fmt] = write_mesh(where / f"box.{fmt}", v, f, force=True)
    (where / "box_ascii.stl").write_bytes(_ascii_stl(v, f))
    seeds["stl-ascii"] = where / "box_ascii.stl"
    off = ["OFF", f"{len(v)} {len(f)} 0"] + [" ".join(f"{x:g}" for x in p) for p in v] + \
        ["3 " + " ".join(map(str, t)) for t in f]
    (where / "box.off").write_text("\n".join(off) + "\n")
    seeds["off"] = where / "box.off"
    pts, tets, hexes = _cube_tets()
    seeds["vtu"] = write_tet_mesh(where / "cube.vtu", pts, tets, force=True)
    seeds["msh"] = write_tet_mesh(where / "cube.msh", pts, tets, force=True)
    seeds["vtk-tet"] = write_tet_mesh(where / "cube.vtk", pts, tets, force=True)
    meshio.write(where / "hexes.vtk", meshio.Mesh(pts, [("hexahedron", hexes)]), binary=False)
    seeds["vtk-hex"] = where / "hexes.vtk"
    shutil.copy(ROOT / "tests" / "data" / "vessel-y-binary-zlib.vtp", where / "y.vtp")
    shutil.copy(ROOT / "tests" / "data" / "vessel-y-ascii.vtp", where / "y_ascii.vtp")
    seeds["vtp"], seeds["vtp-ascii"] = where / "y.vtp", where / "y_ascii.vtp"
    (where / "y.json").write_text((ROOT / "tests" / "data" / "vessel-y-reference.json").read_text())
    seeds["json"] = where / "y.json"
    swc = ["# id type x y z r parent", "1 1 0 0 0 1.0 -1", "2 3 0 0 5 0.9 1", "3 3 0 0 10 0.8 2",
           "4 3 3 0 14 0.6 3", "5 3 -3 0 14 0.6 3"]
    (where / "y.swc").write_text("\n".join(swc) + "\n")
    seeds["swc"] = where / "y.swc"
    _images(where, seeds)
    rows = ["x,y,z,porosity"] + [f"{x},{y},{z},{0.5 + 0.05 * (x + y + z) / 10:.3f}"
                                 for x in (0, 10) for y in (0, 10) for z in (0, 10)]
    (where / "points.csv").write_text("\n".join(rows) + "\n")
    seeds["csv"] = where / "points.csv"
    k1 = (0.0, 0.0, 1.0, 1.0)
    ctrl = np.stack(np.meshgrid(*[np.array([0.0, 10.0])] * 3, indexing="ij"), -1)
    rec = TDFRecord(version=1, tpms_type="G", structure="sheet", periods=(1.0, 1.0, 1.0), tdf_degrees=(1, 1, 1),
                    tdf_knots=(k1, k1, k1), tdf_control=np.full((2, 2, 2), 0.4), tbss_degrees=(1, 1, 1),
                    tbss_knots=(k1, k1, k1), tbss_control=ctrl, tbss_periodic=(False, False, False))
    seeds["tdf"] = write_tdf(where / "box.tdf", rec, force=True)
    (where / "recipe.toml").write_text(
        'job = "tpms"\nformat = 2\n\n[tpms]\ntype = "G"\nstructure = "sheet"\ncell_size = 2.0\n\n'
        '[domain]\nkind = "box"\ncells = [1, 1, 1]\n\n[sampling]\nresolution = 12\n\n'
        '[grading]\nkind = "expression"\nof = "porosity"\nexpr = "0.5 + 0.02 * z"\n\n[output]\nmesh = "out.stl"\n')
    seeds["toml"] = where / "recipe.toml"
    return {k: Path(p) for k, p in seeds.items()}


def _images(where: Path, seeds: dict) -> None:
    import SimpleITK as sitk
    z, y, x = np.mgrid[0:16, 0:16, 0:16]
    ball = (((x - 7.5) ** 2 + (y - 7.5) ** 2 + (z - 7.5) ** 2) < 36).astype(np.uint8)
    img = sitk.GetImageFromArray(ball)
    img.SetSpacing((0.5, 0.5, 0.5))
    for name, fn, comp in (("nii", "ball.nii", False), ("nii.gz", "ball.nii.gz", True), ("mha", "ball.mha", False),
                           ("nrrd", "ball.nrrd", False)):
        sitk.WriteImage(img, str(where / fn), comp)
        seeds[name] = where / fn
    dicom = where / "ball_dcm"
    dicom.mkdir(exist_ok=True)
    for k in range(ball.shape[0]):
        sl = sitk.GetImageFromArray(ball[k].astype(np.int16))
        sl.SetSpacing((0.5, 0.5))
        writer = sitk.ImageFileWriter()
        writer.KeepOriginalImageUIDOn()
        for tag, val in (("0020|000e", "1.2.826.0.1.3680043.2.1125.1"), ("0020|0013", str(k + 1)),
                         ("0020|0032", f"0\\0\\{0.5 * k}"), ("0020|0037", "1\\0\\0\\0\\1\\0"),
                         ("0018|0050", "0.5"), ("0008|0060", "CT"), ("0020|000d", "1.2.826.0.1.3680043.2.1125.2"),
                         ("0008|0018", f"1.2.826.0.1.3680043.2.1125.3.{k + 1}")):
            sl.SetMetaData(tag, val)
        writer.SetFileName(str(dicom / f"s{k:03d}.dcm"))
        writer.Execute(sl)
    seeds["dcm"] = dicom / "s007.dcm"


# --------------------------------------------------------------------------------------------- mutants
def mutate(data: bytes, rng: random.Random) -> bytes:
    """One mutant of ``data`` (1 to 4 random edits)."""
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.random()
        n = len(b)
        if n == 0:
            b += rng.choice(INTERESTING)
            continue
        if op < 0.30:  # a number token replaced by an interesting number
            nums = list(_NUM.finditer(bytes(b)))
            if nums:
                m = rng.choice(nums)
                b[m.start():m.end()] = rng.choice(NUMBERS).encode()
                continue
        if op < 0.45:
            i = rng.randrange(n)
            b[i] ^= 1 << rng.randrange(8)
        elif op < 0.55:
            i = rng.randrange(n)
            b[i:i + 1] = rng.choice(INTERESTING)
        elif op < 0.65:
            i = rng.randrange(n)
            del b[i:i + rng.randint(1, max(1, n // 8))]
        elif op < 0.75:
            i = rng.randrange(n)
            j = min(n, i + rng.randint(1, 64))
            b[i:i] = bytes(b[i:j]) * rng.choice((2, 16, 1000))
        elif op < 0.85:
            del b[rng.randrange(n):]
        elif op < 0.92:  # duplicate a line many times
            lines = bytes(b).split(b"\n")
            k = rng.randrange(len(lines))
            lines[k:k + 1] = [lines[k]] * rng.choice((2, 100, 20000))
            b = bytearray(b"\n".join(lines))
        else:
            i = rng.randrange(n)
            b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    return bytes(b)


def mutant_file(seed: Path, out: Path, rng: random.Random) -> Path:
    """Write a mutant of ``seed`` at ``out`` (same name); zip and gzip are mutated inside half the time."""
    data = seed.read_bytes()
    inner = rng.random() < 0.5
    if seed.suffix == ".3mf" and inner:
        src = zipfile.ZipFile(io.BytesIO(data))
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as dst:
            for name in src.namelist():
                body = src.read(name)
                dst.writestr(name, mutate(body, rng) if name.endswith(".model") else body)
        data = buf.getvalue()
    elif seed.name.endswith(".gz") and inner:
        data = gzip.compress(mutate(gzip.decompress(data), rng), mtime=0)
    else:
        data = mutate(data, rng)
    out.write_bytes(data)
    return out


# ---------------------------------------------------------------------------------------- the commands
#: format -> (command line with {f} for the file, extra seed files the case needs)
READERS = {
    "stl": ["analyze", "{f}", "--json"], "stl-ascii": ["analyze", "{f}", "--json"],
    "obj": ["analyze", "{f}", "--json"], "ply": ["analyze", "{f}", "--json"], "off": ["analyze", "{f}", "--json"],
    "3mf": ["analyze", "{f}", "--json"],
    "vtp": ["vessel", "{f}", "--voxel", "0.25", "-o", "out.stl"],
    "vtp-ascii": ["vessel", "{f}", "--voxel", "0.25", "-o", "out.stl"],
    "swc": ["vessel", "{f}", "--voxel", "0.25", "-o", "out.stl"],
    "json": ["vessel", "{f}", "--voxel", "0.25", "-o", "out.stl"],
    "vtu": ["tis", "{f}", "--resolution", "6", "--relative-threshold", "0.3", "-o", "out.stl"],
    "msh": ["tis", "{f}", "--resolution", "6", "--relative-threshold", "0.3", "-o", "out.stl"],
    "vtk-tet": ["tis", "{f}", "--resolution", "6", "--relative-threshold", "0.3", "-o", "out.stl"],
    "vtk-hex": ["arbf", "{f}", "--resolution", "8", "-o", "out.stl"],
    "nii": ["infill", "{f}", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "out.stl"],
    "nii.gz": ["infill", "{f}", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "out.stl"],
    "mha": ["infill", "{f}", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "out.stl"],
    "nrrd": ["infill", "{f}", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "out.stl"],
    "dcm": ["infill", "{f}", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "out.stl"],
    "csv": ["infill", "{box}", "G", "--porosity-points", "{f}", "-L", "5", "--voxel", "0.5", "-o", "out.stl"],
    "tdf": ["tbss", "--from-tdf", "{f}", "--resolution", "4", "-o", "out.stl"],
    "toml": ["build", "{f}"],
}

#: command -> a baseline command line that succeeds quickly ({box}, {ph}, {pt}: seed files made first)
BASELINES = {
    "tpms": ["tpms", "G", "--cells", "1", "1", "1", "--cell-size", "2", "--resolution", "12", "--threshold", "0.5",
             "--decimate", "0", "--smooth-iterations", "2", "--retries", "1", "--chunk-mb", "4", "--threads", "1",
             "-o", "out.stl"],
    "infill": ["infill", "{box}", "G", "--threshold", "0", "-L", "5", "--voxel", "0.5", "--skin", "1",
               "--map-scale", "1", "--map-offset", "0", "--threads", "1", "-o", "out.stl"],
    "build": ["build", "{toml}", "--threads", "1", "--retries", "1", "--chunk-mb", "4"],
    "analyze": ["analyze", "{box}", "--json", "--domain-volume", "2000", "--voxel", "0.5", "--min-feature", "0.1",
                "--min-pore", "0.1"],
    "tbss": ["tbss", "box", "G", "--periods", "1", "1", "1", "--resolution", "6", "--tdf-grid", "8",
             "--tdf-control", "4", "--layers", "1", "-o", "out.stl"],
    "hex": ["hex", "frustum", "G", "--grid", "1", "1", "1", "--resolution", "6", "--threshold", "0", "--smooth", "0",
            "-o", "out.stl"],
    "tis": ["tis", "{vtu}", "--resolution", "6", "--lambda", "1", "--relative-threshold", "0.3", "--smooth", "0",
            "--size", "10", "-o", "out.stl"],
    "arbf": ["arbf", "{vtkhex}", "--resolution", "8", "--shape", "0.1", "--iso", "0", "--jitter", "0.5", "--seed", "1",
             "--size", "10", "-o", "out.stl"],
    "vessel": ["vessel", "{json}", "--voxel", "0.25", "--segment-angle", "45", "--workers", "1", "-o", "out.stl"],
    "phantom spine": ["phantom", "spine", "-o", "ph", "--discs", "1", "--seed", "0", "--spacing", "2", "1.25",
                      "1.25", "--noise", "0.04", "--bias", "0.15"],
    "seg classical": ["seg", "classical", "{ph}", "--threshold", "250", "--min-volume", "500", "-o", "seg.nii.gz"],
    "ivd": ["ivd", "{ph}", "--smooth-iterations", "2", "-o", "discs"],
    "seg train": ["seg", "train", "--phantoms", "1", "--iterations", "1", "--features", "4,8", "--lr", "0.001",
                  "--seed", "0", "--threads", "1", "-o", "w.pt"],
    "seg predict": ["seg", "predict", "{ph}", "--checkpoint", "{pt}", "--threads", "1", "-o", "pred.nii.gz"],
}


def numeric_options():
    """``[(command, option, nargs)]`` of every int/float option of every command (walking the click tree)."""
    import click

    from porecad.cli.main import cli

    def walk(cmd, prefix):
        if isinstance(cmd, click.Group):
            for name in sorted(cmd.commands):
                yield from walk(cmd.commands[name], prefix + [name])
        else:
            yield " ".join(prefix), cmd

    out = []
    for name, cmd in walk(cli, []):
        for p in cmd.params:
            if not isinstance(p, click.Option) or p.is_flag:
                continue
            types = p.type.types if isinstance(p.type, click.types.Tuple) else [p.type] * max(p.nargs, 1)
            kinds = [isinstance(t, (click.types.IntParamType, click.types.FloatParamType)) for t in types]
            if any(kinds):
                out.append((name, max(p.opts, key=len), len(types), kinds))
    return out


def option_case(command: str, opt: str, nargs: int, kinds, value: str, files: dict):
    """The baseline of ``command`` with option ``opt`` set to ``value`` (every numeric slot)."""
    base = [fill(a, files) for a in BASELINES[command]]
    args = [value if k else "1" for k in kinds]
    if opt == "--edit":
        args = ["u > 0.5", value]
    if opt in base:
        i = base.index(opt)
        return base[:i + 1] + args + base[i + 1 + nargs:]
    return base + [opt] + args


def fill(arg: str, files: dict) -> str:
    """``arg`` with ``{name}`` replaced by the path of seed file ``name`` (other braces kept)."""
    return re.sub(r"\{(\w+)\}", lambda m: str(files[m.group(1)]) if m.group(1) in files else m.group(0), arg)


# -------------------------------------------------------------------------------------------- running
def _child(argv, work: Path, log: Path, mem_bytes: int, cpu_seconds: float, program: bool = False) -> None:
    """In the forked child: limits, redirection, run the CLI, exit with its code.

    ``program``: run it as the ``porecad`` program runs (:func:`porecad.entry.main`: the
    command in a watched child, Ctrl-C handled by the parent), the way a person's
    signal reaches it; otherwise in this process, as a call from Python.
    """
    try:
        os.setsid()
        cpu = max(1, int(cpu_seconds))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))  # SIGXCPU past the CPU budget: a hang
        resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        os.chdir(work)
        out = os.open(log / "stdout", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        err = os.open(log / "stderr", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(out, 1)
        os.dup2(err, 2)
        sys.stdout = io.TextIOWrapper(os.fdopen(1, "wb", buffering=0), write_through=True)
        sys.stderr = io.TextIOWrapper(os.fdopen(2, "wb", buffering=0), write_through=True)
        if program:
            sys.argv = ["porecad", *argv]
            os.environ.pop("PORECAD_WATCH", None)
            from porecad.entry import main as program_main
            rc = program_main()
        else:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            from porecad.cli.main import main
            rc = main(list(argv))
    except BaseException:  # an unhandled exception is what we are looking for: print it as Python would
        import traceback
        traceback.print_exc()
        rc = 1
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(int(rc or 0) & 0xFF)


def classify(rc, sig, maxrss_kb, elapsed, timeout, stderr: str, before: set, after: set, mem_bytes: int) -> str:
    """The class of one finished case (see the module docstring)."""
    if sig in ("hang", "SIGXCPU"):
        return "hang"
    if "Traceback (most recent call last)" in stderr:
        return "traceback"
    if sig is not None:
        return "crash"
    if maxrss_kb * 1024 > mem_bytes or "out of memory" in stderr:
        return "blow-up"
    new = after - before
    if any(".tmp" in Path(n).name for n in new) or (rc != 0 and new):
        return "leftover"
    if rc == 0:
        return "success"
    lines = [l for l in stderr.splitlines() if l.strip() and not l.startswith("porecad: warning:")]
    if len(lines) == 1 and lines[0].startswith(("porecad: error:", "porecad: interrupted", "porecad: terminated")):
        return "refusal"
    return "messy"


def _snapshot(work: Path) -> set:
    return {str(p.relative_to(work)) for p in work.rglob("*")}


class Runner:
    """Runs cases in forked children, ``jobs`` at a time."""

    def __init__(self, root: Path, files: dict, jobs=2, timeout=30.0, mem_gb=4.0, keep=False):
        self.root, self.files, self.jobs, self.timeout = root, files, jobs, timeout
        # the time limit is CPU time (RLIMIT_CPU), so a loaded machine does not turn slow cases into "hangs";
        # the wall-clock limit, several times longer, catches a case that sleeps or deadlocks
        self.wall = max(8.0 * timeout, 120.0)
        self.mem = int(mem_gb * (1 << 30))
        self.keep = keep
        self.stream = None  # a file: one JSON line per finished case
        self.results = []
        self.count = 0

    def run(self, cases):
        """``cases``: iterable of ``(group, label, argv, setup)``; setup(work) writes the inputs."""
        running = {}
        cases = iter(cases)
        done = False
        while True:
            while not done and len(running) < self.jobs:
                try:
                    group, label, argv, setup, *rest = next(cases)
                except StopIteration:
                    done = True
                    break
                signal_at = rest[0] if rest else None
                self.count += 1
                case = self.root / f"case{self.count:05d}"
                work, log = case / "work", case / "log"
                work.mkdir(parents=True)
                log.mkdir()
                argv = [fill(a, self.files) for a in argv]
                argv = setup(work, argv) if setup else argv
                before = _snapshot(work)
                sys.stdout.flush()
                pid = os.fork()
                if pid == 0:
                    _child(argv, work, log, self.mem, self.timeout, program=signal_at is not None)
                running[pid] = (group, label, argv, case, before, time.monotonic(), signal_at)
            if not running:
                break
            self._reap(running)
        return self.results

    def _reap(self, running):
        time.sleep(0.01)
        for pid in list(running):
            group, label, argv, case, before, t0, signal_at = running[pid]
            if signal_at is not None and time.monotonic() - t0 >= signal_at[1]:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal_at[0])
                running[pid] = (group, label, argv, case, before, t0, None)
            wpid, status, usage = os.wait4(pid, os.WNOHANG)
            sig = None
            if wpid == 0:
                if time.monotonic() - t0 < self.wall:
                    continue
                try:
                    os.killpg(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                _, status, usage = os.wait4(pid, 0)
                sig = "hang"
            elif os.WIFSIGNALED(status):
                sig = signal.Signals(os.WTERMSIG(status)).name
            elapsed = time.monotonic() - t0
            rc = os.WEXITSTATUS(status) if os.WIFEXITED(status) else -1
            stderr = (case / "log" / "stderr").read_text(errors="replace")
            after = _snapshot(case / "work")
            if group == "signal" and after - before == SIGNAL_OUTPUTS and rc in (130, 143):
                after = before  # stopped after its outputs were complete: the whole set, as promised
            cls = classify(rc, sig, usage.ru_maxrss, elapsed, self.timeout, stderr, before, after, self.mem)
            if group == "signal" and (after - before) and (after - before) != SIGNAL_OUTPUTS:
                cls = "leftover"  # a stopped job left part of its output set
            result = {"group": group, "label": label, "argv": argv, "rc": rc, "signal": sig, "class": cls,
                      "seconds": round(elapsed, 2), "max_rss_mb": usage.ru_maxrss // 1024,
                      "stderr": stderr.strip().splitlines()[-3:]}
            self.results.append(result)
            if self.stream is not None:
                import json
                self.stream.write(json.dumps(result) + "\n")
                self.stream.flush()
            del running[pid]
            if not self.keep and cls in ("success", "refusal"):
                shutil.rmtree(case, ignore_errors=True)


def reader_cases(seeds: dict, formats, mutants: int, seed: int):
    """Mutant cases, ``(format, 'mutant N', argv, setup)``, round-robin over the formats.

    Mutant ``n`` of a format is the same whatever the other formats or the
    count (one random stream per format), and a run stopped early has covered
    every format about equally.
    """
    rngs = {fmt: random.Random(f"{seed}:{fmt}") for fmt in formats}
    for n in range(mutants):
        for fmt in formats:
            src = seeds[fmt]
            sub = rngs[fmt].getrandbits(64)

            def setup(work, argv, src=src, sub=sub):
                r = random.Random(sub)
                if src.parent.name.endswith("_dcm"):  # a DICOM series: mutate one slice of a copy
                    series = work / src.parent.name
                    shutil.copytree(src.parent, series)
                    target = series / src.name
                    mutant_file(src, target, r)
                else:
                    target = mutant_file(src, work / src.name, r)
                return [str(target) if a == "{f}" else a for a in argv]
            yield fmt, f"mutant {n}", list(READERS[fmt]), setup


def option_cases(files: dict, values=BAD_VALUES, only=None, rotate=False):
    """``(command, 'OPTION VALUE', argv, setup)`` for every numeric option of every command with a baseline.

    ``rotate``: one value per option, taken in turn from ``values`` (a quick sample).
    """
    k = 0
    for command, opt, nargs, kinds in numeric_options():
        if command not in BASELINES or (only and command not in only):
            continue
        chosen = values
        if rotate:
            chosen, k = [values[k % len(values)]], k + 1
        for value in chosen:
            yield command, f"{opt} {value}", option_case(command, opt, nargs, kinds, value, files), _own_copies


def _own_copies(work: Path, argv):
    """A recipe argument is copied into the case directory (its outputs are relative to it)."""
    out = []
    for a in argv:
        if a.endswith(".toml") and os.path.isfile(a):
            shutil.copy(a, work / Path(a).name)
            a = str(work / Path(a).name)
        out.append(a)
    return out


def prepare(root: Path, seeds_dir: Path, need=()) -> dict:
    """Seeds plus the derived inputs the baselines need (a phantom, a checkpoint) when asked for.

    Runs in a subprocess: the fuzzer's own process must not start numba's or
    OpenMP's threads before it forks the cases.
    """
    import json
    import subprocess
    cmd = [sys.executable, str(Path(__file__).resolve()), "--prepare", str(seeds_dir), "--need", ",".join(need)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"fuzz: preparing the seed files failed:\n{proc.stderr[-2000:]}")
    return {k: Path(v) for k, v in json.loads((seeds_dir / "files.json").read_text()).items()}


def _prepare_here(seeds_dir: Path, need) -> None:
    import json
    seeds = make_seeds(seeds_dir)
    files = {k.replace("-", "_").replace(".", "_"): str(v) for k, v in seeds.items()}
    files.update({"box": str(seeds["stl"]), "toml": str(seeds["toml"]), "vtkhex": str(seeds["vtk-hex"])})
    if {"ph", "pt"} & set(need):
        from porecad.cli.main import main
        os.chdir(seeds_dir)
        if main(["phantom", "spine", "-o", "ph", "--discs", "1", "--seed", "0", "--force"]):
            raise SystemExit("phantom failed")
        if "pt" in need and main(["seg", "train", "ph", "--iterations", "1", "--features", "4,8", "--threads", "1",
                                  "-o", "w.pt", "--force"]):
            raise SystemExit("seg train failed")
        files["ph"], files["pt"] = str(seeds_dir / "ph"), str(seeds_dir / "w.pt")
    (seeds_dir / "files.json").write_text(json.dumps(files))


def preload() -> None:
    """Import porecad and its heavy dependencies once, here, so that every forked case inherits them.

    Importing starts no thread (numba and OpenMP start theirs on first use), so forking stays safe.
    """
    import importlib
    import pkgutil

    import porecad
    for mod in ("trimesh", "scipy.spatial", "scipy.ndimage", "scipy.interpolate", "scipy.sparse.linalg",
                "skimage.measure", "SimpleITK", "meshio", "defusedxml.ElementTree", "click", "rich.progress"):
        try:
            importlib.import_module(mod)
        except ImportError:
            pass
    for info in pkgutil.walk_packages(porecad.__path__, "porecad."):
        if info.name.startswith(("porecad.seg", "porecad.studio")) or info.name.endswith("__main__"):
            continue  # torch: imported by the cases that need it
        try:
            importlib.import_module(info.name)
        except Exception:  # noqa: BLE001 - an optional extra missing
            pass


def table(results) -> str:
    """A markdown table: one row per group, one column per class."""
    groups = sorted({r["group"] for r in results}, key=lambda g: (g not in READERS, g))
    head = "| group | cases | " + " | ".join(CLASSES) + " | max s | max MB |\n|---|---|" + "---|" * (len(CLASSES) + 2)
    rows = [head]
    for g in groups:
        rs = [r for r in results if r["group"] == g]
        counts = [sum(r["class"] == c for r in rs) for c in CLASSES]
        rows.append(f"| {g} | {len(rs)} | " + " | ".join(map(str, counts)) +
                    f" | {max(r['seconds'] for r in rs):.1f} | {max(r['max_rss_mb'] for r in rs)} |")
    tot = [sum(r["class"] == c for r in results) for c in CLASSES]
    rows.append(f"| **all** | {len(results)} | " + " | ".join(map(str, tot)) + " | | |")
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mutants", type=int, default=200, help="mutants per format")
    ap.add_argument("--formats", default=",".join(READERS), help="comma-separated formats")
    ap.add_argument("--no-options", action="store_true", help="skip the numeric option sweep")
    ap.add_argument("--commands", default="", help="limit the option sweep to these commands (comma-separated)")
    ap.add_argument("--rotate-values", action="store_true", help="one bad value per option, in turn (a quick sample)")
    ap.add_argument("--no-hostile", action="store_true", help="skip the hostile cases (tools/fuzz_hostile.py)")
    ap.add_argument("--signals", type=int, default=20, help="signal-timing cases among the hostile ones")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=30.0, help="CPU seconds per case (a hang past it)")
    ap.add_argument("--memory-gb", type=float, default=4.0)
    ap.add_argument("--table", help="write the markdown table here")
    ap.add_argument("--summarise", help="print the table of a --json file of an earlier (or running) run")
    ap.add_argument("--json", help="write every case's result here (one JSON line each, as they finish)")
    ap.add_argument("--keep", action="store_true", help="keep the case directories")
    ap.add_argument("--prepare", help=argparse.SUPPRESS)
    ap.add_argument("--need", default="", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.prepare:
        _prepare_here(Path(args.prepare), [n for n in args.need.split(",") if n])
        return 0
    if args.summarise:
        import json
        done = [json.loads(line) for line in Path(args.summarise).read_text().splitlines() if line.strip()]
        print(table(done))
        return 0
    formats = [f for f in args.formats.split(",") if f]
    only = [c for c in args.commands.split(",") if c]
    root = Path(tempfile.mkdtemp(prefix="porecad-fuzz-"))
    need = set()
    if not args.no_options and (not only or set(only) & {"ivd", "seg classical", "seg predict"}):
        need.add("ph")
    if not args.no_options and (not only or "seg predict" in only):
        need.add("pt")
    files = prepare(root, root / "seeds", need)
    preload()
    import porecad.cli.main  # noqa: F401 - imported once here, so every forked case starts warm
    runner = Runner(root / "cases", files, jobs=args.jobs, timeout=args.timeout, mem_gb=args.memory_gb,
                    keep=args.keep)
    if args.json:
        runner.stream = open(args.json, "w")
    t0 = time.monotonic()
    seeds = {k: files[k.replace("-", "_").replace(".", "_")] for k in READERS}
    if not args.no_options:
        runner.run(option_cases(files, only=only, rotate=args.rotate_values))
    runner.run(reader_cases(seeds, formats, args.mutants, args.seed))
    if not args.no_hostile:
        runner.run(hostile_cases(files, signals=args.signals, seed=args.seed))
    results = runner.results
    text = table(results)
    print(text)
    print(f"\n{len(results)} cases in {time.monotonic() - t0:.0f} s; case directories under {root}")
    for r in results:
        if r["class"] not in ("success", "refusal"):
            print(f"{r['class']:>9}  {r['group']}  {r['label']}  {' '.join(r['argv'])[:160]}")
            for line in r["stderr"]:
                print(f"           {line[:200]}")
    if args.table:
        Path(args.table).write_text(text + "\n")
    return 1 if any(r["class"] not in ("success", "refusal") for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
