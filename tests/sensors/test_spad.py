"""SPAD model statistics against analytic values, with confidence bounds (docs/sensors.md).

Every statistical check uses a bound of ~4–5 standard errors (false-alarm rate ≲ 1e-4 per check) and, where it
matters, a companion check that a plausible *wrong* model is rejected by the same bound, so the test can fail.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from simspad.errors import SimSpadError
from simspad.io.recording import RecordingWriter, open_recording
from simspad.physics.radiometry import flux_scale
from simspad.physics.spad_statistics import (
    detection_probability,
    estimate_flux,
    log_flux_variance,
)
from simspad.radiance.timeline import Timeline
from simspad.sensors.presets import SpadParams
from simspad.sensors.spad import (
    SpadChunker,
    auto_gate,
    dcr_map,
    n_bins,
    pack_bits,
    resolve_gate,
    simulate_spad,
    unpack_bits,
)

H, W = 48, 64
BIN_S = 10.24e-6
QUIET = dict(afterpulsing_probability=0.0, crosstalk_probability=0.0)


def _flat_timeline(flux, t_end=1.0, shape=(H, W)):
    frames = np.full((2, *shape), flux, np.float32)
    return Timeline.from_arrays([0.0, t_end], frames)


def _counts(chunker: SpadChunker, n: int, width: int, chunk: int = 4096) -> np.ndarray:
    """Ones per pixel over n bins, unpacking only non-zero bytes (dark data stays cheap)."""
    total = None
    for k0 in range(0, n, chunk):
        packed = chunker.chunk(k0, min(chunk, n - k0))
        if total is None:
            total = np.zeros(packed.shape[1:2] + (packed.shape[2] * 8,), np.int64)
        flat = packed.reshape(packed.shape[0], -1)
        _, col = np.nonzero(flat)
        vals = flat[flat != 0]
        bits = np.unpackbits(vals[:, None], axis=1, bitorder="little").astype(np.int64)
        per_byte = np.zeros((flat.shape[1], 8), np.int64)
        np.add.at(per_byte, col, bits)
        total += per_byte.reshape(packed.shape[1], -1)
    return total[:, :width]


def _chi2_ok(observed, expected_p, n, dof_slack=5.0):
    """Pearson statistic of binomial counts; returns (statistic, dof, bound)."""
    var = n * expected_p * (1 - expected_p)
    stat = float(np.sum((observed - n * expected_p) ** 2 / var))
    dof = observed.size
    # Var of each term is 2 + (1 − 6p(1−p))/var: keep the exact spread so small counts do not false-alarm
    spread = math.sqrt(float(np.sum(2 + (1 - 6 * expected_p * (1 - expected_p)) / var)))
    return stat, dof, dof + dof_slack * spread


# ------------------------------------------------------------------------------------------------- pure functions
def test_pack_bits_little_order_round_trip():
    rng = np.random.default_rng(0)
    bits = (rng.random((5, 3, 13)) < 0.4).astype(np.uint8)
    packed = pack_bits(bits)
    assert packed.shape == (5, 3, 2)
    assert np.array_equal(unpack_bits(packed, 13), bits)
    one = np.zeros((1, 1, 13), np.uint8)
    one[0, 0, 9] = 1
    assert pack_bits(one)[0, 0].tolist() == [0, 0b10]  # x = 9 → byte 1, bit 1 (LSB first)


def test_kernel_places_bits_at_their_column():
    """Only column 11 is lit (no dark counts): every 1 of the packed output must decode to column 11."""
    frames = np.zeros((2, 4, 21), np.float32)
    frames[:, 2, 11] = 3e16  # Λ ≈ 3.9 per bin
    tl = Timeline.from_arrays([0.0, 1.0], frames)
    p = SpadParams(gate_s=BIN_S, **QUIET)
    out = SpadChunker(tl, 0.0, 500, p, np.zeros((4, 21), np.float32), np.random.default_rng(1)).chunk(0, 500)
    bits = unpack_bits(out, 21)
    assert bits[:, 2, 11].sum() > 400 and bits.sum() == bits[:, 2, 11].sum()


def test_estimate_flux_inverts_probability_and_clamps():
    q, gate, dcr = 1e-11, 1e-6, 50.0
    flux = np.array([1e14, 1e15, 1e16])
    p = detection_probability(flux, q, gate, dcr)
    n = 10_000
    assert np.allclose(estimate_flux(p * n, n, q, gate, dcr), flux, rtol=1e-9)
    full = estimate_flux(n, n, q, gate, dcr)
    assert np.isfinite(full) and np.isclose(full, (math.log(n) / gate - dcr) / q)
    assert np.isclose(log_flux_variance(1.0, 100, 1.0, 1.0), (math.e - 1) / 100)  # x = 1, no dark counts
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # far past saturation: +inf, and no overflow warning on the way
        assert log_flux_variance(1e3, 100, 1.0, 1.0) == math.inf


def test_auto_gate_solves_the_percentile_and_clips():
    rate = np.linspace(1e3, 1e6, 1001)
    g = auto_gate(rate, BIN_S, 5.75e-9, 0.9)
    assert np.isclose(np.percentile(-np.expm1(-rate * g), 99), 0.9, rtol=1e-9)
    assert auto_gate(np.full(10, 1.0), BIN_S, 5.75e-9) == BIN_S
    assert auto_gate(np.full(10, 1e12), BIN_S, 5.75e-9) == 5.75e-9
    with pytest.raises(SimSpadError, match="gate_s"):
        resolve_gate(SpadParams(gate_s=1e-9))


def test_dcr_map_is_lognormal_with_hot_pixels():
    p = SpadParams()
    dcr = dcr_map((400, 400), p, np.random.default_rng(3)).astype(np.float64)
    n = dcr.size
    hot = dcr > 150.0  # ln(150/7.5)/0.9 = 3.3σ above ordinary, ln(2000/150)/0.9 = 2.9σ below hot
    frac = hot.mean()
    assert abs(frac - p.hot_pixel_fraction) < 5 * math.sqrt(p.hot_pixel_fraction * (1 - p.hot_pixel_fraction) / n)
    ordinary = np.log(dcr[~hot])
    # median: SE ≈ 1.2533σ/√n; σ of ln: SE ≈ σ/√(2n); truncation at 3.3σ moves both by < 0.3 %
    assert abs(np.median(ordinary) - math.log(p.dcr_median_cps)) < 5 * 1.2533 * p.dcr_log_sigma / math.sqrt(n) + 0.01
    assert abs(ordinary.std() - p.dcr_log_sigma) < 5 * p.dcr_log_sigma / math.sqrt(2 * n) + 0.01 * p.dcr_log_sigma


# ------------------------------------------------------------------------------------------------- flat fields
LUX = [0.1, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5]


@pytest.mark.parametrize("lux", LUX)
def test_flat_field_bit_rate_matches_binomial(lux):
    """Per-pixel counts ~ Binomial(n, 1 − exp(−(λ + r_dark)·gate)) with the real DCR map, fixed gate."""
    flux = flux_scale(1.0, lux)  # flat relative luminance 1 = the mean: the whole frame is mid-grey
    base = SpadParams(**QUIET)
    q = base.detection_area_m2
    rate = flux * q
    # the full bin where it does not saturate, else a fixed gate giving p ≈ 0.5 (the sensor's own floor)
    gate = BIN_S if rate * BIN_S < 2.0 else max(math.log(2) / rate, base.min_gate_s)
    p = dataclasses.replace(base, gate_s=gate)
    rng = np.random.default_rng(int(lux * 10))
    dcr = dcr_map((H, W), p, rng)
    n = 6000
    counts = _counts(SpadChunker(_flat_timeline(flux), 0.0, n, p, dcr, rng), n, W)
    expected = detection_probability(flux, q, gate, dcr.astype(np.float64))
    assert 1e-4 < expected.mean() < 0.99
    total, mu = counts.sum(), n * expected.sum()
    assert abs(total - mu) < 4.5 * math.sqrt(float(np.sum(n * expected * (1 - expected))))
    stat, dof, bound = _chi2_ok(counts, expected, n)
    assert dof - (bound - dof) < stat < bound, (stat, dof, bound)
    # the same bound rejects a model 5 % off in flux
    wrong = detection_probability(1.05 * flux, q, gate, dcr.astype(np.float64))
    assert abs(total - n * wrong.sum()) > 4.5 * math.sqrt(float(np.sum(n * wrong * (1 - wrong))))


@pytest.mark.parametrize("lux", [1.0, 1e3, 1e5])
def test_auto_gate_flat_field(tmp_path, lux):
    """``auto``: the chosen gate puts the 99th percentile at P = 0.9; bits follow it; attrs record the gate."""
    flux = flux_scale(1.0, lux)
    p = SpadParams(**QUIET)
    tl = _flat_timeline(flux, t_end=0.03)
    path = tmp_path / "a.h5"
    with RecordingWriter(path, {"width": W, "height": H, "duration_s": 0.03, "lux": lux}) as w:
        attrs = simulate_spad(w, tl, 0.0, 0.03, p, np.random.default_rng(5))
    with open_recording(path) as rec:
        gate = rec.spad.attrs["gate_s"]
        dcr = rec.spad.dcr_cps.astype(np.float64)
        n = rec.spad.n_bins
        counts = rec.spad.counts(0, n)
        assert n == n_bins(0.03, BIN_S, gate) and np.allclose(rec.spad.t_start, np.arange(n) * BIN_S)
    rate = flux * p.detection_area_m2 + dcr
    assert attrs["gate_auto"] and gate == attrs["gate_s"]
    assert np.isclose(gate, auto_gate(rate, BIN_S, p.min_gate_s, 0.9))
    expected = -np.expm1(-rate * gate)
    if gate < BIN_S:
        assert np.isclose(np.percentile(expected, 99), 0.9, rtol=1e-6)
    stat, dof, bound = _chi2_ok(counts, expected, n)
    assert dof - (bound - dof) < stat < bound


def _gate_integral(knots_t, knots_y, a, b):
    """Exact ∫_a^b of the piecewise-linear (knots_t, knots_y), independent of the Timeline code."""
    inner = knots_t[(knots_t > a) & (knots_t < b)]
    t = np.concatenate([[a], inner, [b]])
    return np.trapezoid(np.interp(t, knots_t, knots_y), t)


def _uniform_scene_counts(knots_t, knots_y, shape, n, p, seed, chunk=500):
    """A uniform scene whose flux (photons s⁻¹ m⁻²) is ``knots_y`` at ``knots_t``, linear in between, simulated over
    ``n`` bins in calls of ``chunk`` bins: ones per bin (over the pixels), the exact Λ of each bin's gate, and the
    knots as the timeline stores them (float32, as float64)."""
    frames = np.broadcast_to(np.asarray(knots_y)[:, None, None], (knots_t.size, *shape)).astype(np.float32)
    tl = Timeline.from_arrays(knots_t, frames)
    knots_y32 = frames[:, 0, 0].astype(np.float64)
    chunker = SpadChunker(tl, 0.0, n, p, np.zeros(shape, np.float32), np.random.default_rng(seed))
    per_bin = np.concatenate([unpack_bits(chunker.chunk(k0, min(chunk, n - k0)), shape[1]).sum(axis=(1, 2))
                              for k0 in range(0, n, chunk)])
    starts = np.arange(n) * BIN_S
    lam = np.array([p.detection_area_m2 * _gate_integral(knots_t, knots_y32, s, s + p.gate_s) for s in starts])
    return per_bin, lam, knots_y32


@pytest.mark.parametrize("peak_lambda,shape", [(0.6, (16, 24)), (0.03, (96, 64))])  # dense; sparse + thinning
def test_time_varying_ramp_integrates_exactly(peak_lambda, shape):
    """Keyframes every 7.3 µs alternate dark and bright, gate 6 µs: most gates straddle knots.

    Per-bin counts over the pixels follow Binomial(N, 1 − exp(−q·∫_gate Φ)) for the exact integral; sampling the
    flux at the gate's midpoint instead is rejected by the same statistic. Λ peaks at 0.6 (dense sampler) or
    0.03 (sparse sampler: 8·0.03 expected candidates per byte and bin, below ``DENSE_MIN_CANDIDATES``; its
    thinning then carries the time variation).
    """
    from simspad.sensors.spad.kernel import DENSE_MIN_CANDIDATES

    assert (8 * peak_lambda < DENSE_MIN_CANDIDATES) == (peak_lambda < 0.1)  # each case reaches its sampler
    gate, n = 6e-6, 2500
    knots_t = np.arange(0, n * BIN_S + 20e-6, 7.3e-6)
    p = SpadParams(gate_s=gate, **QUIET)
    q = p.detection_area_m2
    peak = peak_lambda / (q * gate)
    knots_y = np.where(np.arange(knots_t.size) % 2 == 0, 0.05, 1.0) * peak * np.linspace(0.3, 1.0, knots_t.size)
    per_bin, lam, knots_y32 = _uniform_scene_counts(knots_t, knots_y, shape, n, p, seed=7)
    starts = np.arange(n) * BIN_S
    expected = -np.expm1(-lam)
    npx = shape[0] * shape[1]
    stat, dof, bound = _chi2_ok(per_bin, expected, npx)
    assert dof - (bound - dof) < stat < bound, (stat, dof, bound)
    mid = -np.expm1(-q * gate * np.interp(starts + gate / 2, knots_t, knots_y32))
    assert _chi2_ok(per_bin, mid, npx)[0] > 3 * bound


def test_tabulated_sparse_rows_follow_ramps_inside_long_runs():
    """Keyframes 1.7 ms apart (≈ 166 bins per run): Λ ramps 0.017 → 0.036 → 0.02, every byte sparse (8·0.036 below
    ``DENSE_MIN_CANDIDATES``) and every row tabulated (its candidates outnumber its runs × pixels), so thinning
    takes the exact Λ_k from the per-row table of each run's a + b·dk. Per-bin counts follow Binomial(N, p_k)
    (χ²); taking Λ constant over each call (the table's b ignored) is rejected by the same bound."""
    from simspad.sensors.spad.kernel import _TABLE_MIN_RUN_BINS, DENSE_MIN_CANDIDATES

    shape, n, chunk = (192, 64), 2500, 500
    p = SpadParams(gate_s=BIN_S, **QUIET)
    q = p.detection_area_m2
    knots_t = np.array([0.0, 1.7e-3, 3.4e-3, 5.1e-3, 6.8e-3, 8.5e-3, 10.2e-3, 30e-3])
    knots_lam = np.array([0.017, 0.036, 0.02, 0.033, 0.017, 0.036, 0.025, 0.025])
    assert 8 * knots_lam.max() < DENSE_MIN_CANDIDATES  # sparse everywhere
    runs_per_call = 2 * (chunk * BIN_S / 1.7e-3 + 1)  # a run per piece and one per straddling gate
    assert runs_per_call * _TABLE_MIN_RUN_BINS <= chunk  # the call's runs are long enough to tabulate
    # each row's candidates (at least 8·Λ_min per byte and bin) outnumber its table's entries
    assert chunk * 8 * knots_lam.min() * (shape[1] // 8) >= runs_per_call * shape[1]
    per_bin, lam, _ = _uniform_scene_counts(knots_t, knots_lam / (q * BIN_S), shape, n, p, seed=17, chunk=chunk)
    npx = shape[0] * shape[1]
    stat, dof, bound = _chi2_ok(per_bin, -np.expm1(-lam), npx)
    assert dof - (bound - dof) < stat < bound, (stat, dof, bound)
    per_call = np.repeat(lam.reshape(-1, chunk).mean(axis=1), chunk)
    assert _chi2_ok(per_bin, -np.expm1(-per_call), npx)[0] > 3 * bound


def test_dense_rows_follow_ramps_inside_long_runs():
    """Keyframes 1.7 ms apart (≈ 166 bins per run), gate 8 µs of a 10.24 µs bin (gates that straddle a keyframe
    are runs of one bin): Λ ramps 0.2 → 0.8 → 0.25 …, every byte dense, so z is advanced by its per-bin factor
    inside each run. Per-bin counts follow Binomial(N, p_k) (χ²); z held at each run's first bin (a factor of 1)
    is rejected by the same bound."""
    from simspad.sensors.spad.kernel import DENSE_MIN_CANDIDATES

    shape, n, chunk, gate = (32, 64), 2500, 500, 8e-6
    p = SpadParams(gate_s=gate, **QUIET)
    q = p.detection_area_m2
    knots_t = np.array([0.0, 1.7e-3, 3.4e-3, 5.1e-3, 6.8e-3, 8.5e-3, 10.2e-3, 30e-3])
    knots_lam = np.array([0.2, 0.8, 0.25, 0.6, 0.2, 0.8, 0.3, 0.3])
    assert 8 * knots_lam.min() >= DENSE_MIN_CANDIDATES  # dense everywhere
    starts = np.arange(n) * BIN_S
    straddling = [(starts < t) & (t < starts + gate) for t in knots_t[1:-1]]
    assert all(s.sum() == 1 for s in straddling)  # each keyframe inside the call has a run of one bin
    per_bin, lam, _ = _uniform_scene_counts(knots_t, knots_lam / (q * gate), shape, n, p, seed=19, chunk=chunk)
    npx = shape[0] * shape[1]
    stat, dof, bound = _chi2_ok(per_bin, -np.expm1(-lam), npx)
    assert dof - (bound - dof) < stat < bound, (stat, dof, bound)
    # runs: bins of one call inside one piece, and each straddling gate alone
    run_id = np.searchsorted(knots_t, starts, side="right") * 2 + np.any(straddling, axis=0)
    run_id = run_id * (n // chunk + 1) + np.arange(n) // chunk
    first = np.r_[0, np.flatnonzero(np.diff(run_id)) + 1]
    held = lam[first[np.searchsorted(first, np.arange(n), side="right") - 1]]
    assert _chi2_ok(per_bin, -np.expm1(-held), npx)[0] > 3 * bound


def test_dark_frames_reproduce_dcr_map():
    """No light: per-pixel counts over 2·10⁵ bins follow the DCR map; hot pixels are found at their rate."""
    p = SpadParams(gate_s=BIN_S, **QUIET)
    rng = np.random.default_rng(11)
    dcr = dcr_map((H, W), p, rng)
    n = 200_000
    counts = _counts(SpadChunker(_flat_timeline(0.0, t_end=3.0), 0.0, n, p, dcr, rng), n, W, chunk=8192)
    expected = -np.expm1(-dcr.astype(np.float64) * BIN_S)
    stat, dof, bound = _chi2_ok(counts, expected, n)
    assert dof - (bound - dof) < stat < bound, (stat, dof, bound)
    # a map with the same statistics but other pixels is rejected: the pattern itself is reproduced
    shuffled = np.random.default_rng(0).permutation(expected.ravel()).reshape(expected.shape)
    assert _chi2_ok(counts, shuffled, n)[0] > 3 * bound
    measured_dcr = -np.log1p(-counts / n) / BIN_S
    hot_frac = (measured_dcr > 150.0).mean()
    f = p.hot_pixel_fraction
    assert abs(hot_frac - f) < 5 * math.sqrt(f * (1 - f) / dcr.size) + 0.003


# ------------------------------------------------------------------------------------------------- secondaries
def _bits(p, flux, n, shape=(H, W), seed=0, chunk=1000):
    tl = _flat_timeline(flux, shape=shape)
    ch = SpadChunker(tl, 0.0, n, p, np.zeros(shape, np.float32), np.random.default_rng(seed))
    return np.concatenate([unpack_bits(ch.chunk(k0, min(chunk, n - k0)), shape[1]) for k0 in range(0, n, chunk)])


@pytest.mark.parametrize("p_primary,chunk", [(0.03, 1000), (0.3, 1000), (0.03, 3)])  # sparse, dense, carry-over
def test_afterpulsing_conditional_rate(p_primary, chunk):
    """Excess P(b[k+1] | b[k]=1) − P(b[k+1] | b[k]=0) = (1−p)a / (1 + (1−p)a) (only primaries afterpulse).

    With 3-bin chunks most pairs straddle a chunk boundary: afterpulses must carry over to the next chunk.
    """
    a = 0.05
    p = SpadParams(gate_s=BIN_S, afterpulsing_probability=a, crosstalk_probability=0.0)
    flux = -math.log1p(-p_primary) / (p.detection_area_m2 * BIN_S)
    b = _bits(p, flux, 4000 if chunk > 10 else 1200, chunk=chunk)
    prev, nxt = b[:-1].ravel(), b[1:].ravel()
    n1, n0 = prev.sum(), prev.size - prev.sum()
    r1, r0 = nxt[prev == 1].mean(), nxt[prev == 0].mean()
    se = math.sqrt(r1 * (1 - r1) / n1 + r0 * (1 - r0) / n0)
    expected = (1 - p_primary) * a / (1 + (1 - p_primary) * a)
    assert abs((r1 - r0) - expected) < 4.5 * se, (r1 - r0, expected, se)
    assert abs(r0 - p_primary) < 4.5 * math.sqrt(p_primary * (1 - p_primary) / n0)
    assert expected > 10 * se  # the effect is resolved, so a missing afterpulse model fails


def _crosstalk_table(p, c):
    """Exact joint law of two horizontal neighbours (interior) with crosstalk c from primaries of probability p."""
    o = 1 - (1 - p * c) ** 3  # at least one of a pixel's 3 other neighbours crosstalks into it
    table = np.zeros((2, 2))
    for pl in (0, 1):
        for pr in (0, 1):
            w = (p if pl else 1 - p) * (p if pr else 1 - p)
            p_l = 1.0 if pl else 1 - (1 - (c if pr else 0.0)) * (1 - o)
            p_r = 1.0 if pr else 1 - (1 - (c if pl else 0.0)) * (1 - o)
            for bl in (0, 1):
                for br in (0, 1):
                    table[bl, br] += w * (p_l if bl else 1 - p_l) * (p_r if br else 1 - p_r)
    return table


@pytest.mark.parametrize("p_primary", [0.03, 0.3])
def test_crosstalk_joint_law_of_neighbours(p_primary):
    """The 2×2 table of (left, right) bits of interior neighbours matches the exact law (χ², 3 dof)."""
    c = 0.03
    p = SpadParams(gate_s=BIN_S, afterpulsing_probability=0.0, crosstalk_probability=c)
    flux = -math.log1p(-p_primary) / (p.detection_area_m2 * BIN_S)
    b = _bits(p, flux, 3000, seed=2)
    left, right = b[:, 1:-1, 1:-2].ravel(), b[:, 1:-1, 2:-1].ravel()
    observed = np.bincount(left * 2 + right, minlength=4).reshape(2, 2)
    # use every 3rd column pair to keep cells nearly independent for the χ² (pairs share pixels otherwise)
    left3, right3 = b[:, 1:-1, 1:-2:3].ravel(), b[:, 1:-1, 2:-1:3].ravel()
    obs3 = np.bincount(left3 * 2 + right3, minlength=4)
    exp3 = _crosstalk_table(p_primary, c).ravel() * left3.size
    chi2 = float(np.sum((obs3 - exp3) ** 2 / exp3))
    assert chi2 < 25.0, (chi2, obs3, exp3)  # χ²(3): P(> 25) ≈ 1.6e-5
    no_ct = _crosstalk_table(p_primary, 0.0).ravel() * left3.size
    assert float(np.sum((obs3 - no_ct) ** 2 / no_ct)) > 100.0
    # marginal rate: p + (1 − p)(1 − (1 − pc)^4) for interior pixels
    marginal = observed[1].sum() / observed.sum()
    expected = p_primary + (1 - p_primary) * (1 - (1 - p_primary * c) ** 4)
    assert abs(marginal - expected) < 5 * math.sqrt(expected * (1 - expected) / (b.shape[0] * 46 * 10))


# ------------------------------------------------------------------------------------------------- estimator
@pytest.mark.parametrize("x", [0.05, 0.5, 2.0])
def test_ml_estimator_recovers_flux_within_predicted_std(x):
    """z = (ln Φ̂ − ln Φ)/sd has mean 0 and variance 1, sd from the docs/sensors.md formula (dark rate included)."""
    p = SpadParams(gate_s=1e-6, **QUIET)
    q = p.detection_area_m2
    flux = x / (q * p.gate_s)
    rng = np.random.default_rng(int(x * 100))
    dcr = dcr_map((H, W), p, rng)
    n = 3000
    counts = _counts(SpadChunker(_flat_timeline(flux), 0.0, n, p, dcr, rng), n, W)
    est = estimate_flux(counts, n, q, p.gate_s, dcr.astype(np.float64))
    # Var(ln Φ̂) = (e^{x_tot} − 1)/(n·x²), x_tot = x + r_dark·gate: dark counts add noise, not signal
    sd = np.sqrt(log_flux_variance(flux, n, q, p.gate_s, dcr.astype(np.float64)))
    z = (np.log(est) - math.log(flux)) / sd
    N = z.size
    assert abs(z.mean()) < 4.5 / math.sqrt(N) + 0.05  # + O(1/√n) bias of the ML estimator
    assert abs(z.var() - 1) < 4.5 * math.sqrt(2 / N) + 0.05
    assert np.all(np.abs(est / flux - 1) < 6 * sd)


def test_recording_holds_the_chunker_bins_when_chunks_do_not_align(tmp_path, monkeypatch):
    """Streamed chunks (1572 bins here) that are not a multiple of the HDF5 chunk (1048 bins) are stored intact.

    The appender keeps the rows short of a whole HDF5 chunk as a view until the next append; reusing the chunk
    buffer used to overwrite them with the next chunk's bins.
    """
    from simspad.sensors.spad import simulator

    monkeypatch.setattr(simulator, "CHUNK_BYTES", 3 << 19)
    h, w = 125, 64
    m, rows = simulator.chunk_bins(h, w), simulator.h5_chunk_bins(h, w)
    assert m % rows != 0
    p = SpadParams(gate_s=BIN_S, **QUIET)
    n = 2 * m + 300
    duration = (n - 1) * BIN_S + p.gate_s
    tl = _flat_timeline(flux_scale(1.0, 10.0), t_end=duration, shape=(h, w))
    with RecordingWriter(tmp_path / "r.h5", {"width": w, "height": h, "duration_s": duration, "lux": 10.0}) as wr:
        attrs = simulate_spad(wr, tl, 0.0, duration, p, np.random.default_rng(4))
    assert attrs["n_bins"] == n
    rng = np.random.default_rng(4)
    chunker = SpadChunker(tl, 0.0, n, p, dcr_map((h, w), p, rng), rng)
    expected = np.concatenate([chunker.chunk(k0, min(m, n - k0)) for k0 in range(0, n, m)])
    with open_recording(tmp_path / "r.h5") as rec:
        stored = rec.spad._dataset("bits")[()]
    assert expected.any() and np.array_equal(stored, expected)


def test_sparse_sampler_pixels_of_one_byte_keep_their_own_rates():
    """Sparse bytes draw candidates at the byte's largest rate and thin them per pixel: within every byte the
    columns' Λ span 0.0005–0.07 (all below the sparse threshold), yet each pixel's count follows its own
    Binomial (χ²); giving every pixel its byte's mean probability is rejected by the same bound."""
    h, w, n = 32, 64, 20_000
    p = SpadParams(gate_s=BIN_S, **QUIET)
    q = p.detection_area_m2
    lam = np.geomspace(5e-4, 0.07, 8)[np.arange(w) % 8]
    flux = np.broadcast_to(lam / (q * BIN_S), (h, w)).astype(np.float32)
    tl = Timeline.from_arrays([0.0, 1.0], np.stack([flux, flux]))
    counts = _counts(SpadChunker(tl, 0.0, n, p, np.zeros((h, w), np.float32), np.random.default_rng(9)), n, w)
    expected = np.broadcast_to(-np.expm1(-q * BIN_S * flux.astype(np.float64)), (h, w))
    stat, dof, bound = _chi2_ok(counts, expected, n)
    assert dof - (bound - dof) < stat < bound, (stat, dof, bound)
    byte_mean = np.repeat(expected.reshape(h, w // 8, 8).mean(axis=2), 8, axis=1)
    assert _chi2_ok(counts, byte_mean, n)[0] > 3 * bound


def test_chunk_layout_weights_give_the_exact_gate_mean():
    """Λ from the layout's keyframe weights equals q·(1/gate)·∫_gate Φ dt for every bin (inside a piece,
    straddling one or several keyframes), across consecutive calls that share the keyframe ring."""
    from simspad.sensors.spad.layout import KeyframeRing, chunk_layout

    rng = np.random.default_rng(3)
    knots_t = np.array([0.0, 13e-6, 20e-6, 23e-6, 61e-6, 200e-6])  # a gate (6 µs) can span three pieces
    frames = rng.uniform(0.0, 1e15, (knots_t.size, 3, 5)).astype(np.float32)
    tl = Timeline.from_arrays(knots_t, frames)
    q, gate, bin_s = 2e-11, 6e-6, 2.5e-6
    ring = KeyframeRing(tl, 3)  # fewer slots than one call needs: the ring grows
    for k0 in (0, 20, 40):
        starts = (k0 + np.arange(20)) * bin_s
        lay = chunk_layout(ring, starts, gate, bin_s, q)
        for j, s in enumerate(starts):
            r = lay.bin_run[j]
            terms = range(lay.term_ptr[r], lay.term_ptr[r + 1])
            dk = j - lay.run_k0[r]
            lam = sum((lay.term_c[t] + dk * lay.term_dc[t]) * lay.images[lay.term_img[t]].astype(np.float64)
                      for t in terms)
            exact = q * tl.integrate(float(s), float(s) + gate).astype(np.float64) / gate
            assert np.allclose(lam, exact, rtol=1e-5), (k0, j)
            assert set(lay.term_img[list(terms)]) <= set(lay.slots)  # the call's keyframes bound its gate means


def test_sampler_choice_per_row_keeps_every_pixel_binomial():
    """Wide rows (40 bytes) with a few bright bytes among dim ones: a row with fewer than ``DENSE_MIN_BYTES``
    bright bytes samples them with the sparse sampler at up to 8·0.9 expected candidates per bin, a row with more
    mixes both samplers. Every pixel's count follows its own Binomial (χ²) in both kinds of row; for the bright
    pixels alone, a flux 5 % off is rejected by the same bound."""
    from simspad.sensors.spad.kernel import DENSE_MIN_BYTES, DENSE_MIN_CANDIDATES

    h, w, n = 8, 320, 6000
    bright_lam = np.geomspace(0.1, 0.9, 8)  # per pixel of a bright byte: 8·Λ_max ≫ the dense threshold
    dim_lam = 0.02  # 8·0.02 < the dense threshold: always sparse
    assert 8 * dim_lam < DENSE_MIN_CANDIDATES < 8 * bright_lam[0]
    few, many = DENSE_MIN_BYTES // 4, DENSE_MIN_BYTES + 4
    assert 0 < few < DENSE_MIN_BYTES <= many <= w // 8 - 4  # each kind of row reaches its sampler choice
    lam = np.full((h, w), dim_lam)
    bright = np.zeros((h, w), bool)
    for y in range(h):
        n_bright = few if y % 2 == 0 else many
        for xb in np.random.default_rng(y).choice(w // 8, n_bright, replace=False):
            lam[y, 8 * xb : 8 * xb + 8] = bright_lam
            bright[y, 8 * xb : 8 * xb + 8] = True
    p = SpadParams(gate_s=BIN_S, **QUIET)
    q = p.detection_area_m2
    flux = (lam / (q * BIN_S)).astype(np.float32)
    tl = Timeline.from_arrays([0.0, 1.0], np.stack([flux, flux]))
    counts = _counts(SpadChunker(tl, 0.0, n, p, np.zeros((h, w), np.float32), np.random.default_rng(13)), n, w)
    expected = -np.expm1(-q * BIN_S * flux.astype(np.float64))
    for rows in (slice(0, h, 2), slice(1, h, 2)):
        stat, dof, bound = _chi2_ok(counts[rows], expected[rows], n)
        assert dof - (bound - dof) < stat < bound, (rows, stat, dof, bound)
        lit = bright[rows]
        stat, dof, bound = _chi2_ok(counts[rows][lit], expected[rows][lit], n)
        assert dof - (bound - dof) < stat < bound, (rows, stat, dof, bound)
        wrong = -np.expm1(-1.05 * q * BIN_S * flux[rows][lit].astype(np.float64))
        assert _chi2_ok(counts[rows][lit], wrong, n)[0] > bound


# ---------------------------------------------------------------------------------------------------- storage
#: HDF5 filter id of each storage choice on /spad/bits (None: stored unfiltered).
_FILTER_IDS = {"none": None, "gzip": 1, "zstd": 32015}


def _textured_timeline(mean_lambda=0.01, t_end=0.02):
    """Random per-pixel flux (log-normal, ~1 decade) with a mean of ``mean_lambda`` detections per bin, constant
    over ``t_end``."""
    p = SpadParams(gate_s=BIN_S)
    y = np.exp(np.random.default_rng(0).standard_normal((H, W)))
    flux = y / y.mean() * mean_lambda / (p.detection_area_m2 * BIN_S)
    return Timeline.from_arrays([0.0, t_end], np.stack([flux, flux]).astype(np.float32))


def test_every_storage_filter_stores_the_same_bits(tmp_path):
    """``compression`` changes how /spad/bits is stored, never the bits: same seed, same bits under every filter,
    each file carries the filter asked for, and at a low detection probability the compressed files are smaller."""
    tl = _textured_timeline()
    stored, sizes = {}, {}
    for name, filter_id in _FILTER_IDS.items():
        p = SpadParams(gate_s=BIN_S, compression=name)
        path = tmp_path / f"{name}.h5"
        with RecordingWriter(path, {"width": W, "height": H, "duration_s": 0.01, "lux": 1.0}) as wr:
            simulate_spad(wr, tl, 0.0, 0.01, p, np.random.default_rng(11))
        with open_recording(path) as rec:
            ds = rec.spad._dataset("bits")
            plist = ds.id.get_create_plist()
            ids = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
            assert ids == ([] if filter_id is None else [filter_id]), name
            assert rec.spad.attrs["compression"] == name
            stored[name] = ds[()]
        sizes[name] = path.stat().st_size
    assert 0.001 < np.bitwise_count(stored["none"]).mean() / 8 < 0.05  # sparse enough that compression must pay
    assert np.array_equal(stored["gzip"], stored["none"]) and np.array_equal(stored["zstd"], stored["none"])
    assert sizes["zstd"] < 0.5 * sizes["none"] and sizes["gzip"] < 0.5 * sizes["none"]


def test_zstd_recording_reads_with_h5py_and_hdf5plugin_alone(tmp_path):
    """An outside reader (h5py with hdf5plugin's filters, no SimSPAD) decodes the compressed bits, as
    docs/format.md tells users to read them."""
    import subprocess
    import sys

    tl = _textured_timeline()
    path = tmp_path / "r.h5"
    with RecordingWriter(path, {"width": W, "height": H, "duration_s": 0.005, "lux": 1.0}) as wr:
        simulate_spad(wr, tl, 0.0, 0.005, SpadParams(gate_s=BIN_S), np.random.default_rng(3))
    with open_recording(path) as rec:
        ones = int(np.bitwise_count(rec.spad._dataset("bits")[()]).sum(dtype=np.int64))
    code = ("import sys, h5py, hdf5plugin, numpy as np; f = h5py.File(sys.argv[1], 'r'); "
            "assert 'simspad' not in sys.modules; print(int(np.bitwise_count(f['spad/bits'][()]).sum(dtype=np.int64)))")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True)
    assert ones > 0 and int(out.stdout) == ones
