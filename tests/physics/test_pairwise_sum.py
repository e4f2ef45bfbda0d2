"""pairwise_sum adds in NumPy's order: equal to ``ndarray.sum`` to the last bit at every length."""

import numpy as np

from simspad.physics.pairwise_sum import pairwise_sum


def test_pairwise_sum_is_numpys_sum():
    rng = np.random.default_rng(0)
    for n in (0, 1, 5, 8, 15, 16, 127, 128, 129, 200, 256, 1003, 5000, 100_000):
        a = rng.normal(size=n) * 1e3
        padded = np.concatenate([[7.0, -3.0], a])
        assert pairwise_sum(a, 0, n) == a.sum()
        assert pairwise_sum(padded, 2, n) == a.sum()
    # a plain loop differs from NumPy's sum here: the test tells the orders apart
    a = rng.normal(size=1000) * 1e3
    assert sum(a.tolist()) != a.sum()
