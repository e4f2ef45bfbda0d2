"""An exponential that numba can vectorise: ``exp_fast`` inlines into a loop (no libm call), so a loop over an
array of arguments compiles to SIMD code.

``math.exp`` in a numba loop is a call per element (≈ 15–20 ns here), which kept the SPAD kernel's dense sampler
busier with setting up a run of bins than with drawing its bits. Method: Cody–Waite reduction
``x = n·ln 2 + r`` with ``|r| ≤ ln 2 / 2`` (ln 2 split in a high part exact in 32 bits and a low part, as fdlibm),
``e^r`` by its Taylor series to degree 13 (truncation < 5e-18) in Horner form, and ``2^n`` from a table. Error
≤ 2 ulp against ``math.exp`` for normal results (tests/physics/test_vector_exp.py); results below ~1e-308
(subnormal) lose precision, arguments below about −744.5 give 0 and above 709 give e^709.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # fdlibm: the high bits of ln 2, so n·_LN2_HI is exact for |n| < 2²⁰
_LN2_LO = 1.90821492927058770002e-10
_X_MIN, _X_MAX = -745.2, 709.0  # 2^n stays finite (n ≤ 1023)
_N_MIN = -1080
_ROUND = 6755399441055744.0  # 1.5·2⁵²: adding and subtracting it rounds a |v| < 2⁵¹ to an integer
#: 2^n for n in [_N_MIN, 1024): exact powers of two (those below 2⁻¹⁰⁷⁴ are 0).
_POW2 = np.ldexp(1.0, np.arange(_N_MIN, 1024))
_INV_FACT = tuple(1.0 / math.factorial(k) for k in range(14))


@numba.njit(cache=True, inline="always")
def exp_fast(x):
    """e^x (float64) within 2 ulp, with no call: vectorises inside numba loops."""
    x = min(max(x, _X_MIN), _X_MAX)
    n = (x * _LOG2E + _ROUND) - _ROUND  # round to nearest (no floor call: llvm.floor became a libm call)
    r = (x - n * _LN2_HI) - n * _LN2_LO
    c = _INV_FACT
    # Estrin's scheme (pairs, then powers of r²): a dependency chain of 5 multiply-adds instead of Horner's 13
    r2 = r * r
    r4 = r2 * r2
    r8 = r4 * r4
    q0 = c[0] + c[1] * r
    q1 = c[2] + c[3] * r
    q2 = c[4] + c[5] * r
    q3 = c[6] + c[7] * r
    q4 = c[8] + c[9] * r
    q5 = c[10] + c[11] * r
    q6 = c[12] + c[13] * r
    s0 = q0 + q1 * r2
    s1 = q2 + q3 * r2
    s2 = q4 + q5 * r2
    p = (s0 + s1 * r4) + (s2 + q6 * r4) * r8
    return p * _POW2[np.int64(n) - _N_MIN]
