"""A fast, deterministic subset of the fuzz suite (``tools/fuzz.py``; issue 19, Build 5).

The hostile cases of ``tools/fuzz_hostile.py`` (issue 41: recipe outputs
outside their folder, detached image data, special files, nested 3MF and
ivd parameters, odd names, bombs, signals at seeded times), three mutants
of every reader's seed file and one bad value (0, -1, nan,
inf, 1e308 or 2**62, in turn) for every numeric option of the commands
that need no torch, each run by the real command line in a forked child
under a memory limit (4 GiB address space) and a CPU-time limit (30 s;
a wall-clock limit several times longer catches a case that sleeps). Every case must end as a clean one-line refusal or a valid
success: no traceback, crash, hang, blow-up or leftover file. The limits
classify; nothing here asserts a duration. The full run (200 mutants per
format, every option with every value) is ``python tools/fuzz.py``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = "tpms,infill,build,analyze,tbss,hex,tis,arbf,vessel,phantom spine,seg classical"


@pytest.fixture(scope="module")
def fuzz_results(tmp_path_factory):
    pytest.importorskip("SimpleITK")
    out = tmp_path_factory.mktemp("fuzz") / "results.jsonl"
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "fuzz.py"), "--mutants", "3", "--seed", "19",
                           "--commands", COMMANDS, "--rotate-values", "--jobs", "2", "--timeout", "30",
                           "--memory-gb", "4", "--signals", "6", "--json", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert out.exists(), proc.stderr[-3000:]
    results = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    return results, proc


def test_fuzz_subset_has_no_bad_outcome(fuzz_results):
    results, proc = fuzz_results
    bad = [f"{r['class']}: {r['group']} {r['label']}: {' '.join(r['argv'])[:200]} :: {r['stderr'][-1:]}"
           for r in results if r["class"] not in ("refusal", "success")]
    assert not bad, "\n".join(bad)
    assert proc.returncode == 0, proc.stdout[-3000:]


def test_fuzz_subset_covers_every_reader_and_option(fuzz_results):
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import fuzz
    finally:
        sys.path.pop(0)
    results, _ = fuzz_results
    groups = {r["group"] for r in results}
    assert set(fuzz.READERS) <= groups
    assert set(fuzz.HOSTILE_GROUPS) <= groups  # issue 41: confinement, special files, nested 3MF, signals, ...
    wanted = {c for c in COMMANDS.split(",")}
    options = {(c, o) for c, o, _, _ in fuzz.numeric_options() if c in wanted}
    seen = {(r["group"], r["label"].rsplit(" ", 1)[0]) for r in results if r["group"] in wanted}
    assert options <= seen, sorted(options - seen)
    # the mutants do reach the parsers: most are refused, some still read as valid files
    assert sum(r["class"] == "refusal" for r in results) > len(fuzz.READERS)
