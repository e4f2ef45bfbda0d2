"""exp_fast agrees with math.exp to 2 ulp over the range the SPAD kernel uses (and beyond), and is a tenth-of-ulp
away on average; a polynomial one degree too short is caught by the same bound."""

import math

import numba
import numpy as np

from simspad.physics.vector_exp import exp_fast


@numba.njit
def _exp_all(x):
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = exp_fast(x[i])
    return out


def _ulp_error(got, x):
    want = np.array([math.exp(v) for v in x])
    return np.abs(got - want) / np.spacing(want)


def test_exp_fast_within_two_ulp():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-700, 700, 200_000), rng.uniform(-1, 1, 200_000), rng.uniform(-30, 0, 200_000),
                        [0.0, -0.0, 1e-300, -1e-17, 0.34657359, -0.34657359, 700.0, -700.0]])
    err = _ulp_error(_exp_all(x), x)
    assert err.max() <= 2.0, err.max()
    assert err.mean() < 0.5
    # truncating the series after r^11 (error ≈ r^12/12! ≈ 6e-15) breaks the bound: it is tight enough to matter
    r = rng.uniform(-0.3466, 0.3466, 10_000)
    short = sum(r**k / math.factorial(k) for k in range(12))
    assert _ulp_error(short, r).max() > 2.0


def test_exp_fast_limits():
    x = np.array([-746.0, -1e6, -744.0, 709.0])
    got = _exp_all(x)
    assert got[0] == 0.0 and got[1] == 0.0
    assert 0 < got[2] < 1e-320
    assert np.isfinite(got[3])
