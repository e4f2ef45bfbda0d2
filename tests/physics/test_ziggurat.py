"""The ziggurat exponential follows Exp(1): tail probabilities e^(−t) from the body to the far tail, with binomial
bounds; a distribution 1 % off in scale is rejected by the same bounds."""

import math

import numba
import numpy as np

from simspad.physics.ziggurat import exponential_zig


@numba.njit
def _draws(n, seed):
    out = np.empty(n)
    state = np.uint64(seed)
    for i in range(n):
        state, out[i] = exponential_zig(state)
    return out


def test_ziggurat_tail_probabilities_match_exp1():
    n = 4_000_000
    x = _draws(n, 12345)
    assert x.min() >= 0.0
    for t in (0.01, 0.1, 0.5, 1.0, 2.0, 4.0, 7.0, 7.69711747, 9.0, 12.0):  # strips, wedges, base strip, tail
        p = math.exp(-t)
        bound = 5 * math.sqrt(n * p * (1 - p)) + 3
        assert abs(np.count_nonzero(x > t) - n * p) < bound, t
    # a 1 % scale error is visible to the same bounds
    p_wrong = math.exp(-1.0 / 1.01)
    assert abs(np.count_nonzero(x > 1.0) - n * p_wrong) > 5 * math.sqrt(n * p_wrong * (1 - p_wrong))
    assert abs(x.mean() - 1.0) < 5 / math.sqrt(n)
    assert abs(x.var() - 1.0) < 5 * math.sqrt(8 / n)
