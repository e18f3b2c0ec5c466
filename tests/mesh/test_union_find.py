"""The union-find shared by the streamed mesh check and the banded printability checks."""

import numpy as np

from porecad.mesh.union_find import Forest


def test_batches_joined_across_seams_match_a_reference():
    rng = np.random.default_rng(3)
    f = Forest()
    assert f.grow(5) == 0 and f.grow(7) == 5 and len(f) == 12
    pairs = rng.integers(0, 12, size=(2, 9))
    f.join(pairs[0], pairs[1])
    # reference: repeated label propagation over the same pairs
    label = np.arange(12)
    for _ in range(12):
        for a, b in pairs.T:
            m = min(label[a], label[b])
            label[label == label[a]] = m
            label[label == label[b]] = m
    roots = f.roots()
    assert all((roots[i] == roots[j]) == (label[i] == label[j]) for i in range(12) for j in range(12))
    assert np.all(roots <= np.arange(12))  # the smallest id of a tree is its root
    f.join([], [])  # nothing to join: nothing changes
    assert np.array_equal(f.roots(), roots)
