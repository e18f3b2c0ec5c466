"""Timings and memory of refusing hostile inputs (issue 19, Acceptance 1 and 3).

* every expression escape of ``tests/cli/test_untrusted.py`` on the command line
  (``tpms --threshold``, ``tbss --tdf``, ``tbss --edit``) and in a recipe run
  by ``porecad build``: the time ``porecad.cli.main.main`` takes to refuse it
  (in-process, so Python's start-up is not counted) — the target is < 1 s each;
* a 3MF zip bomb (a member inflating to 11 GiB) and a billion-laughs VTP, each
  refused by a fresh ``porecad`` process: wall time and peak resident memory
  of that process (``os.wait4``) — targets < 2 s and < 200 MB.

Run: ``python bench/untrusted.py`` (numbers depend on the machine's load).
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def refusal_times(where: Path) -> list[tuple[str, float]]:
    from porecad.cli.main import main
    from test_untrusted import ESCAPES, toml_string  # noqa: E402

    out = []
    os.chdir(where)
    for i, e in enumerate(ESCAPES):
        expr = e.format(c=str(where / "CANARY"))
        recipe = where / "r.toml"
        recipe.write_text(f'job = "tpms"\n[tpms]\ntype = "G"\n[domain]\nkind = "box"\n[grading]\n'
                          f'kind = "expression"\nexpr = {toml_string(expr)}\n[output]\nmesh = "g.stl"\n')
        for ctx, argv in (("cli --threshold", ["tpms", "G", "--threshold", expr, "-o", "a.stl"]),
                          ("cli --tdf", ["tbss", "box", "G", "--tdf", expr, "-o", "b.stl"]),
                          ("cli --edit", ["tbss", "box", "G", "--edit", expr, "0.5", "-o", "c.stl"]),
                          ("recipe", ["build", str(recipe)])):
            err = io.StringIO()
            t = time.perf_counter()
            with contextlib.redirect_stderr(err):
                code = main(argv)
            dt = time.perf_counter() - t
            assert code != 0 and len(err.getvalue().strip().splitlines()) == 1, (argv, err.getvalue())
            out.append((f"escape {i} {ctx}", dt))
    assert not (where / "CANARY").exists()
    return out


def process_cost(argv, cwd) -> tuple[float, float, int, str]:
    """Wall seconds, peak RSS (MB), exit code and stderr of one ``porecad`` process."""
    t = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "porecad", *argv], cwd=cwd, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE)
    err = p.stderr.read().decode()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    return time.perf_counter() - t, usage.ru_maxrss / 1024, p.returncode, err.strip()


def main() -> None:
    from test_untrusted import BILLION_LAUGHS, zip_bomb_3mf  # noqa: E402

    with tempfile.TemporaryDirectory() as tmp:
        where = Path(tmp)
        times = refusal_times(where)
        worst = max(times, key=lambda t: t[1])
        print(f"expression escapes: {len(times)} refusals, median {sorted(t for _, t in times)[len(times) // 2] * 1e3:.1f} "
              f"ms, slowest {worst[1] * 1e3:.1f} ms ({worst[0]})")
        bomb = zip_bomb_3mf(where / "bomb.3mf")
        laughs = where / "laughs.vtp"
        laughs.write_text(BILLION_LAUGHS)
        base = process_cost(["--version"], where)
        print(f"python + porecad start-up: {base[0]:.2f} s, {base[1]:.0f} MB")
        for name, argv in (("3MF zip bomb (11 GiB member, {:.1f} MB file)".format(bomb.stat().st_size / 2**20),
                            ["analyze", str(bomb)]),
                           ("billion-laughs VTP", ["vessel", str(laughs), "--voxel", "0.2", "-o", "o.stl"])):
            wall, rss, code, err = process_cost(argv, where)
            print(f"{name}: exit {code} in {wall:.2f} s, peak {rss:.0f} MB :: {err}")


if __name__ == "__main__":
    main()
