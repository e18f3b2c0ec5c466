"""Hex parameterisation in bounded time (issue 20): progress per stage, an estimate, a user-set limit."""

import pytest

from porecad import datasets
from porecad.errors import InputError
from porecad.param.hexcube import hex_parameterisation


def test_progress_reports_every_stage_and_the_limit_is_checked():
    v, f = datasets.star_blob(1200, seed=5)
    seen = []
    nodes, info = hex_parameterisation(v, f, (4, 4, 4), progress=lambda s, d, t: seen.append((s, d, t)))
    stages = {s.split(" ~")[0] for s, _, _ in seen}
    assert {"setup", "corners", "geodesics", "surface grid", "volume"} <= stages
    assert all(0 <= d <= t for _, d, t in seen)
    assert nodes.shape == (5, 5, 5, 3)
    assert info.untangle_stopped in (False, True)
    for s in info.estimates.values():
        assert s > 0
    for bad in (-1.0, float("nan"), "fast"):
        with pytest.raises(InputError, match="time limit"):
            hex_parameterisation(v, f, (4, 4, 4), untangle_limit=bad)
    with pytest.raises(InputError, match="nodes"):
        hex_parameterisation(v, f, (100, 100, 100))


def test_a_tiny_limit_stops_the_untangling_with_a_reason():
    v, f = datasets.star_blob(1200, seed=5)
    try:
        nodes, info = hex_parameterisation(v, f, (6, 6, 6), untangle_limit=1e-3)
    except InputError as err:  # no valid grid within the limit: the reason names it
        assert "time limit" in str(err) and "\n" not in str(err)
    else:
        assert info.min_scaled_jacobian > 0 or info.untangle_stopped
