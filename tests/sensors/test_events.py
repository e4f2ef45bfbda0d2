"""Event camera: threshold counts, noise statistics vs lux, refractory period, unclumped timestamps, lag."""

import dataclasses
import math

import h5py
import numba
import numpy as np
import pytest
from scipy import stats

from simspad.errors import SimSpadError
from simspad.io.recording import RecordingWriter, open_recording
from simspad.physics.photoreceptor import cutoff_hz
from simspad.physics.radiometry import flux_scale
from simspad.physics.rng import normal, normal_quantile
from simspad.radiance.timeline import Timeline
from simspad.sensors import events
from simspad.sensors.presets import EventParams

QUIET = dict(leak_rate_hz=0.0, shot_noise_rate_hz_at_1lux=0.0, hot_pixel_fraction=0.0, latency_s=0.0, jitter_s=0.0)
#: Photocurrent per unit photon irradiance of the preset pixel (e⁻ s⁻¹ per photon s⁻¹ m⁻²).
E_PER_FLUX = EventParams().pixel_pitch_m ** 2 * EventParams().fill_factor * EventParams().qe


def _run(tmp_path, times, frames, params, seed=0, lux=1000.0, t0=None, t1=None, name="e.h5", **kw):
    tl = Timeline.from_arrays(np.asarray(times, np.float64), np.asarray(frames, np.float32))
    t0 = tl.t_start if t0 is None else t0
    t1 = tl.t_end if t1 is None else t1
    path = tmp_path / name
    with RecordingWriter(path, {"width": tl.width, "height": tl.height, "duration_s": t1 - t0, "lux": lux}) as w:
        attrs = events.simulate_events(w, tl, t0, t1, params, np.random.default_rng(seed), lux, **kw)
    with open_recording(path) as rec:
        ev = rec.events.window(t0, t1 + 1.0)
        ev["ms_to_idx"] = rec.events.ms_to_idx.copy()
        assert rec.events.n_events == ev["t"].size
    maps = events.draw_pixel_maps(params, (tl.height, tl.width), np.random.default_rng(seed))
    return ev, attrs, maps


def _cutoff_hz(current, params):
    return cutoff_hz(current, params.photoreceptor_cutoff_hz_max, params.photoreceptor_cutoff_ref_rate_e_s)


def _per_pixel(ev, shape, mask=None):
    idx = ev["y"].astype(np.int64) * shape[1] + ev["x"]
    if mask is not None:
        idx = idx[mask]
    return np.bincount(idx, minlength=shape[0] * shape[1])


def test_log_ramp_gives_floor_of_contrast_over_each_pixels_threshold(tmp_path):
    """A ramp of Δ log units then a hold: each pixel emits floor(Δ/θ_i) events of the ramp's sign."""
    H, W = 16, 40
    params = EventParams(**QUIET)
    times = np.linspace(0.0, 0.2, 101)
    ramp = np.clip(times / 0.1, 0, 1)
    delta = np.linspace(0.4, 3.0, W)
    sign = np.where(np.arange(H) < H // 2, 1.0, -1.0)
    log_y = ramp[:, None, None] * sign[None, :, None] * delta[None, None, :]
    ev, attrs, maps = _run(tmp_path, times, 1e18 * np.exp(log_y), params)
    assert attrs["threshold_sigma"] == 0.03 and attrs["n_events_by_label"].startswith('{"signal"')
    d = np.abs(sign[:, None] * delta[None, :]).ravel()
    theta = np.where(np.repeat(sign, W) > 0, maps.threshold_on, maps.threshold_off)
    expected = np.floor(d / theta)
    on = _per_pixel(ev, (H, W), ev["p"] == 1).reshape(H, W)
    off = _per_pixel(ev, (H, W), ev["p"] == 0).reshape(H, W)
    assert off[: H // 2].sum() == 0 and on[H // 2:].sum() == 0
    counts = (on + off).ravel()
    assert np.mean(counts == expected) >= 0.99
    assert np.max(np.abs(counts - expected)) <= 1
    # the mismatch shows: pixels of one column disagree, as floor(Δ/θ_i) predicts
    assert np.std(counts.reshape(H, W)[:, -1]) > 0
    assert np.all(ev["label"] == events.LABEL_SIGNAL)


def test_static_scene_gives_only_noise_whose_rate_rises_as_light_falls(tmp_path):
    H, W, T = 32, 48, 1.0
    params = EventParams(shot_noise_rate_hz_at_1lux=1.0, leak_rate_hz=2.0, hot_pixel_fraction=0.02,
                         hot_pixel_rate_hz=200.0)
    dead_s = params.latency_s + params.refractory_s
    shot_counts = []
    for lux in (1.0, 10.0, 100.0):
        flux = flux_scale(1.0, lux)  # a grey flat field at the lux level's mean luminance
        ev, attrs, maps = _run(tmp_path, [0.0, T], np.full((2, H, W), flux), params, seed=7, lux=lux,
                               name=f"s{lux:g}.h5")
        assert not np.any(ev["label"] == events.LABEL_SIGNAL), "a static scene has no signal events"
        current = flux * E_PER_FLUX + params.dark_current_e_s
        current_1lux = attrs["shot_noise_current_1lux_e_s"]
        assert current_1lux == pytest.approx(flux / lux * E_PER_FLUX + params.dark_current_e_s, rel=1e-6)
        rate = params.shot_noise_rate_hz_at_1lux * np.sqrt(current_1lux / current)
        n_shot = int(np.sum(ev["label"] == events.LABEL_SHOT))
        expected = rate * T * H * W
        assert abs(n_shot - expected) < 5 * np.sqrt(expected) + 0.02 * expected, (lux, n_shot, expected)
        shot_counts.append(n_shot)
        # leak: ON events at each pixel's own rate (reference drift leak·θ_on per second)
        leak = _per_pixel(ev, (H, W), ev["label"] == events.LABEL_LEAK)
        assert np.all(ev["p"][ev["label"] == events.LABEL_LEAK] == 1)
        # steady state: a uniform leak phase gives floor(T·r) or that + 1 events, T·r on average
        n_leak = T * maps.leak_rate_hz
        assert np.mean((leak == np.floor(n_leak)) | (leak == np.floor(n_leak) + 1)) > 0.97
        frac = n_leak % 1
        assert abs(leak.sum() - n_leak.sum()) < 5 * np.sqrt(np.sum(frac * (1 - frac))) + 0.01 * n_leak.sum()
        # hot pixels: Poisson at the hot rate thinned by the dead time after each event
        hot = _per_pixel(ev, (H, W), ev["label"] == events.LABEL_HOT)
        is_hot = maps.hot_rate_hz > 0
        assert hot[~is_hot].sum() == 0 and is_hot.sum() > 10
        r_hot = params.hot_pixel_rate_hz / (1 + params.hot_pixel_rate_hz * dead_s)
        expected_hot = r_hot * T * is_hot.sum()
        assert abs(hot.sum() - expected_hot) < 5 * np.sqrt(expected_hot)
    assert shot_counts[0] > shot_counts[1] > shot_counts[2]
    assert shot_counts[0] > 5 * shot_counts[2]


def test_short_static_recording_has_leak_events_at_the_steady_state_rate(tmp_path):
    """20 ms of a static scene with the preset's leak rate (a period of ≈ 10 s): each pixel fires with probability
    T·r, so the recording holds Σ T·r leak events, not none (a reference reset at the start would give none)."""
    H, W, T = 256, 256, 0.02
    params = EventParams(**{**QUIET, "leak_rate_hz": EventParams().leak_rate_hz})
    ev, _, maps = _run(tmp_path, [0.0, T], np.full((2, H, W), 1e17), params, seed=11)
    p_fire = T * maps.leak_rate_hz
    expected = p_fire.sum()
    assert expected > 100
    n_leak = int(np.sum(ev["label"] == events.LABEL_LEAK))
    assert n_leak == ev["t"].size, "a quiet static scene gives leak events only"
    # each pixel fires at most once (Bernoulli T·r): 5 σ of the sum
    assert abs(n_leak - expected) < 5 * np.sqrt(np.sum(p_fire * (1 - p_fire))), (n_leak, expected)


def test_leak_phase_is_uniform_not_locked_to_the_recording_start(tmp_path):
    """Each pixel's first leak event comes at u/r after the start, u uniform on (0, 1] (KS test), and later ones
    every 1/r: the sensor starts in its steady state."""
    H, W, T = 32, 32, 1.0
    params = EventParams(**{**QUIET, "leak_rate_hz": 5.0})
    ev, _, maps = _run(tmp_path, [0.0, T], np.full((2, H, W), 1e17), params, seed=12)
    assert np.all(ev["label"] == events.LABEL_LEAK) and np.all(ev["p"] == 1)
    idx = ev["y"].astype(np.int64) * W + ev["x"]
    order = np.lexsort((ev["t"], idx))
    idx, t_s = idx[order], ev["t"][order] * 1e-6
    first = np.r_[True, np.diff(idx) != 0]
    full = np.flatnonzero(maps.leak_rate_hz * T >= 1.0)  # pixels whose first event must fall inside [0, T)
    assert full.size > 0.9 * H * W and np.all(np.isin(full, idx[first]))
    keep = np.isin(idx[first], full)
    phase = t_s[first][keep] * maps.leak_rate_hz[idx[first][keep]]
    assert stats.kstest(phase, "uniform").pvalue > 1e-3
    # later events follow at the pixel's period (to the µs floor of the timestamps)
    gaps = np.diff(t_s)[~first[1:]]
    period = 1.0 / maps.leak_rate_hz[idx[1:][~first[1:]]]
    assert gaps.size > 1000 and np.all(np.abs(gaps - period) <= 1.0001e-6)


def test_refractory_period_is_respected_and_throttles_fast_changes(tmp_path):
    H, W = 8, 16
    params = EventParams(shot_noise_rate_hz_at_1lux=5.0, hot_pixel_fraction=0.1, hot_pixel_rate_hz=5000.0)
    times = np.array([0.0, 0.002, 0.004, 0.006])
    log_y = np.array([0.0, 4.0, 0.0, 4.0])[:, None, None] * np.ones((1, H, W))  # 200 contrast units per s
    ev, attrs, maps = _run(tmp_path, times, 1e18 * np.exp(log_y), params)
    refractory_us = round(params.refractory_s * 1e6)
    idx = ev["y"].astype(np.int64) * W + ev["x"]
    order = np.lexsort((ev["t"], idx))
    same = np.diff(idx[order]) == 0
    gaps = np.diff(ev["t"][order])[same]
    assert gaps.size > 100
    assert gaps.min() >= refractory_us
    # crossings every 0.3/2000 s = 150 µs can't all be emitted with a 100 µs refractory + 50 µs latency
    signal = _per_pixel(ev, (H, W), ev["label"] == events.LABEL_SIGNAL)
    ideal = np.floor(4.0 / maps.threshold_on) * 2 + np.floor(4.0 / maps.threshold_off)
    assert np.all(signal <= ideal) and signal.sum() < 0.95 * ideal.sum()


def test_timestamps_sorted_indexed_and_not_clumped_at_keyframes(tmp_path):
    H, W = 32, 32
    params = EventParams(**QUIET)
    dt_key = 1e-3
    times = np.arange(0.0, 0.5 + dt_key / 2, dt_key)
    rng = np.random.default_rng(3)
    # linear brightening at a different rate per pixel; ≤ 3 % per keyframe interval, so the crossing density
    # inside an interval (∝ 1/I for linear I) is uniform to ~1 %
    rates = rng.uniform(5.0, 30.0, (H, W))
    frames = 1e17 * (1.0 + rates[None] * times[:, None, None])
    ev, attrs, maps = _run(tmp_path, times, frames, params)
    t = ev["t"]
    assert t.size > 3000
    assert np.all(np.diff(t) >= 0)
    np.testing.assert_array_equal(ev["ms_to_idx"], np.searchsorted(t, np.arange(ev["ms_to_idx"].size) * 1000))
    assert ev["ms_to_idx"].size == int(np.ceil(0.5 * 1e3)) + 1
    fraction = ((t % 1000) + 0.5) / 1000.0  # position inside the keyframe interval (µs resolution)
    assert stats.kstest(fraction, "uniform").pvalue > 1e-3
    near_keyframe = np.mean((fraction < 0.02) | (fraction > 0.98))
    assert near_keyframe < 0.04 + 4 * np.sqrt(0.04 / t.size)


def test_dim_pixels_lag_as_the_photoreceptor_cutoff_predicts(tmp_path):
    """A step ×2 in light: first ON event after −τ·ln(1 − θ/ln 2), τ = 1/(2π f_c(I)) — slow when dim."""
    params = EventParams(**QUIET)
    currents = np.array([2e3, 2e4, 2e7])  # e⁻/s before the step (dim, moderate, bright)
    H, W = 3, 16
    step_t = 0.01
    times = np.array([0.0, step_t, step_t + 1e-7, 0.2])
    level = (currents[:, None] - params.dark_current_e_s) / E_PER_FLUX * np.ones((1, W))
    frames = np.stack([level, level, 2 * level + params.dark_current_e_s / E_PER_FLUX, 2 * level + params.dark_current_e_s / E_PER_FLUX])
    ev, attrs, maps = _run(tmp_path, times, frames, params)
    first = np.full(H * W, np.nan)
    idx = ev["y"].astype(np.int64) * W + ev["x"]
    for p in range(H * W):
        ts = ev["t"][idx == p]
        first[p] = ts.min() * 1e-6 - step_t if ts.size else np.nan
    after = np.repeat(2 * currents, W)
    tau = 1.0 / (2 * np.pi * _cutoff_hz(after, params))
    expected = -tau * np.log(1.0 - maps.threshold_on / np.log(2.0))
    np.testing.assert_allclose(first, expected, rtol=0.03, atol=2e-6)
    assert np.nanmean(first[:W]) > 100 * np.nanmean(first[-W:])


def test_thresholds_never_reach_zero(tmp_path):
    params = EventParams(threshold_sigma=5.0, **QUIET)
    maps = events.draw_pixel_maps(params, (64, 64), np.random.default_rng(0))
    assert maps.threshold_on.min() >= params.threshold_min > 0
    assert maps.threshold_off.min() >= params.threshold_min
    times = np.array([0.0, 0.01])
    ev, attrs, _ = _run(tmp_path, times, 1e17 * np.stack([np.ones((4, 4)), 1.5 * np.ones((4, 4))]), params)
    assert np.all(np.isfinite(ev["t"]))
    with pytest.raises(SimSpadError, match="threshold_min"):
        dataclasses.replace(params, threshold_min=0.0)


def test_same_seed_same_events_whatever_the_chunking_and_threads(tmp_path):
    params = EventParams(shot_noise_rate_hz_at_1lux=20.0, hot_pixel_fraction=0.05)
    rng = np.random.default_rng(1)
    times = np.linspace(0.0, 0.05, 26)
    frames = 1e16 * np.exp(rng.normal(0, 0.5, (26, 12, 10)))
    a, _, _ = _run(tmp_path, times, frames, params, seed=4, name="a.h5")
    b, _, _ = _run(tmp_path, times, frames, params, seed=4, name="b.h5", chunk_bytes=1)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        d, _, _ = _run(tmp_path, times, frames, params, seed=4, name="d.h5")
    finally:
        numba.set_num_threads(threads)
    c, _, _ = _run(tmp_path, times, frames, params, seed=5, name="c.h5")
    assert a["t"].size > 500
    for key in ("t", "x", "y", "p", "label", "ms_to_idx"):
        np.testing.assert_array_equal(a[key], b[key])
        np.testing.assert_array_equal(a[key], d[key])
    assert a["t"].size != c["t"].size or not np.array_equal(a["t"], c["t"])


@pytest.mark.parametrize("chunk_rows", [None, 64])
def test_event_columns_take_their_size_on_disk(tmp_path, monkeypatch, chunk_rows):
    """Fewer events than a chunk: each column is stored in one chunk exactly as long as the events (a chunk of
    65 536 rows held ≈ 0.9 MiB of zeros for a few hundred events). More (chunks of 64 rows here): whole chunks, and
    the events are those of the same run with the default chunk, row for row."""
    params = EventParams(shot_noise_rate_hz_at_1lux=20.0, hot_pixel_fraction=0.05)
    rng = np.random.default_rng(1)
    times = np.linspace(0.0, 0.05, 26)
    frames = 1e16 * np.exp(rng.normal(0, 0.5, (26, 12, 10)))
    if chunk_rows is not None:
        monkeypatch.setattr(events.simulator, "EVENT_CHUNK_ROWS", chunk_rows)
    ev, _, _ = _run(tmp_path, times, frames, params, seed=4)
    n = ev["t"].size
    assert 500 < n < events.EVENT_CHUNK_ROWS  # the package constant: unpatched
    with h5py.File(tmp_path / "e.h5", "r") as f:
        for name, dtype in (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.uint8),
                            ("label", np.uint8)):
            ds = f[f"events/{name}"]
            rows = ds.chunks[0]
            assert rows == (n if chunk_rows is None else chunk_rows)
            assert ds.id.get_storage_size() == -(-n // rows) * rows * np.dtype(dtype).itemsize
    if chunk_rows is not None:
        monkeypatch.undo()
        ref, _, _ = _run(tmp_path, times, frames, params, seed=4, name="ref.h5")
        for key in ("t", "x", "y", "p", "label", "ms_to_idx"):
            np.testing.assert_array_equal(ev[key], ref[key])


def test_jitter_draws_are_standard_normal():
    """The one-uniform normal quantile used for readout jitter: accurate, and its draws pass a KS test."""
    u = np.concatenate([np.linspace(1e-12, 1 - 1e-12, 20001), [0.02425, 0.97575, 0.5]])
    z = np.array([normal_quantile(v) for v in u])
    exact = stats.norm.ppf(u)
    assert np.max(np.abs(z - exact) / np.maximum(1.0, np.abs(exact))) < 2e-9

    @numba.njit
    def draws(seed, n):
        out = np.empty(n)
        s = np.uint64(seed)
        for i in range(n):
            s, out[i] = normal(s)
        return out

    x = draws(12345, 200_000)
    assert stats.kstest(x, "norm").pvalue > 1e-3
    assert abs(x.mean()) < 5 / np.sqrt(x.size) and abs(x.std() - 1) < 5 / np.sqrt(2 * x.size)


def test_overflowing_pixel_block_is_rerun_alone_with_identical_events():
    """Force the per-block event buffers to overflow in one block only: its rerun gives the same events."""
    H, W = 32, 32
    params = EventParams(shot_noise_rate_hz_at_1lux=5.0, hot_pixel_fraction=0.05)
    times = np.array([0.0, 0.002, 0.004, 0.006])
    log_y = np.zeros((4, H, W))
    log_y[:, :8] = np.array([0.0, 4.0, 0.0, 4.0])[:, None, None]  # only the first pixel block is busy
    current = events.sensor_photocurrent_e_s(1e18 * np.exp(log_y), params).reshape(4, H * W)
    maps = events.draw_pixel_maps(params, (H, W), np.random.default_rng(2))
    runs = []
    for cap in (None, 1):
        sim = events.EventSimulator(params, (H, W), current[0], 0.0, 1e6, maps)
        if cap is not None:
            sim._cap = cap  # smallest room: the busy block overflows, the quiet ones do not
        out = [sim.advance(times, current), sim.finish()]
        runs.append([np.concatenate([o[i] for o in out]) for i in range(5)])
    busy = np.count_nonzero(runs[0][2] < H * W // 4)
    assert busy > 4 * 1024 and runs[0][0].size - busy > 0
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
    assert np.all(np.diff(runs[0][1]) >= 0)


def test_sparse_events_over_a_long_piece_are_sorted_by_time_then_pixel(tmp_path):
    """Few events spread over a long keyframe piece take the comparison-sort path: same canonical order."""
    H, W, T = 8, 8, 3.0
    params = EventParams(shot_noise_rate_hz_at_1lux=2.0, hot_pixel_fraction=0.1, hot_pixel_rate_hz=50.0)
    ev, attrs, maps = _run(tmp_path, [0.0, T], np.full((2, H, W), flux_scale(1.0, 1.0)), params, lux=1.0)
    n = ev["t"].size
    span_us = int(ev["t"].max() - ev["t"].min()) + 1
    assert 50 < n and span_us > 4 * n + (1 << 20)  # the bucket sort would need a sparse µs table: fallback used
    idx = ev["y"].astype(np.int64) * W + ev["x"]
    np.testing.assert_array_equal(np.lexsort((idx, ev["t"])), np.arange(n))
    np.testing.assert_array_equal(ev["ms_to_idx"], np.searchsorted(ev["t"], np.arange(ev["ms_to_idx"].size) * 1000))


def _panning_texture(shape, n_keyframes, rate_hz, flow_px, seed):
    """Keyframes of a smooth log-normal texture panning ``flow_px`` pixels per keyframe (periodic)."""
    rng = np.random.default_rng(seed)
    fy, fx = np.fft.fftfreq(shape[0])[:, None], np.fft.fftfreq(shape[1])[None, :]
    spectrum = (rng.normal(size=shape) + 1j * rng.normal(size=shape)) / (0.01 + fx**2 + fy**2)
    spectrum[0, 0] = 0.0
    tex = np.stack([np.real(np.fft.ifft2(spectrum * np.exp(-2j * np.pi * fx * flow_px * i)))
                    for i in range(n_keyframes)])
    return np.arange(n_keyframes) / rate_hz, 1e17 * np.exp(1.2 * tex / tex.std())


def _per_frame_reference(times, frames, params, maps, frames_per_interval):
    """Brute-force signal events: frames interpolated linearly in time, the exact low-pass update for an input held
    over each frame, floor(Δ/θ) crossings per frame with linearly interpolated times. Returns (t_s, pixel, pol)."""
    shape = frames.shape[1:]
    th = {1: maps.threshold_on.reshape(shape), 0: maps.threshold_off.reshape(shape)}
    frame_t = np.concatenate([np.linspace(a, b, frames_per_interval, endpoint=False)
                              for a, b in zip(times[:-1], times[1:])] + [times[-1:]])

    def current(t):
        i = min(np.searchsorted(times, t, side="right") - 1, times.size - 2)
        w = (t - times[i]) / (times[i + 1] - times[i])
        return events.sensor_photocurrent_e_s((1 - w) * frames[i] + w * frames[i + 1], params)

    lp = np.log(current(frame_t[0]))
    ref = lp.copy()
    out = []
    for t0, t1 in zip(frame_t[:-1], frame_t[1:]):
        cur = current(t1)
        new = lp - np.expm1(-(t1 - t0) * 2 * np.pi * _cutoff_hz(cur, params)) * (np.log(cur) - lp)
        for sign, pol in ((1, 1), (-1, 0)):
            n = np.floor(np.maximum(sign * (new - ref), 0) / th[pol]).astype(np.int64)
            for k in range(1, n.max(initial=0) + 1):
                y, x = np.nonzero(n >= k)
                frac = (ref[y, x] + sign * k * th[pol][y, x] - lp[y, x]) / (new[y, x] - lp[y, x])
                out.append((t0 + (t1 - t0) * frac, y * shape[1] + x, np.full(x.size, pol)))
            ref = ref + sign * n * th[pol]
        lp = new
    return tuple(np.concatenate(column) for column in zip(*out))


def _count_error(ev, ev_ref, n_pix, window_s):
    """Σ|N − N_ref| / ΣN_ref over per-pixel, per-polarity counts in time windows (missing, extra and moved events)."""
    n_win = 1000

    def counts(e):
        key = (np.asarray(e[1], np.int64) * 2 + e[2]) * n_win + np.floor(e[0] / window_s).astype(np.int64)
        return np.bincount(key, minlength=2 * n_pix * n_win)

    ref = counts(ev_ref)
    return np.abs(counts(ev) - ref).sum() / ref.sum()


def test_exact_integrator_is_the_limit_of_a_brute_force_per_frame_simulation(tmp_path):
    """An independent brute-force simulator of the same model (noise off) converges to SimSPAD's events as its
    frame interval shrinks, at about first order, and SimSPAD's default step tolerance stays close to that limit:
    the closed-form crossings, the adaptive steps and the intensity-dependent low-pass are the model's, not an
    artefact of the solver."""
    params = EventParams(**QUIET, refractory_s=0.0)
    shape = (16, 16)
    times, frames = _panning_texture(shape, 9, 1000.0, 0.5, seed=3)
    sims = {}
    for tol in (1e-4, params.substep_tolerance):
        ev, _, maps = _run(tmp_path, times, frames, dataclasses.replace(params, substep_tolerance=tol),
                           name=f"{tol}.h5")
        sims[tol] = ((ev["t"] + 0.5) * 1e-6, ev["y"].astype(np.int64) * shape[1] + ev["x"], ev["p"])
    converged, default = sims[1e-4], sims[params.substep_tolerance]
    assert converged[0].size > 1500
    window = 100e-6
    errors = {n: _count_error(_per_frame_reference(times, frames, params, maps, n), converged, shape[0] * shape[1],
                              window) for n in (16, 64, 256)}
    assert errors[16] / errors[64] > 2.5 and errors[64] / errors[256] > 2.5  # converging, not levelling off
    assert errors[256] < 0.1
    assert _count_error(default, converged, shape[0] * shape[1], window) < 0.15


def test_knot_table_matches_the_kernels_own_expressions_bit_for_bit():
    """The per-tile knot table (clamped I, ln I, I^(−γ/2), slope, 1/|slope|) equals what the kernel computed in
    place, bit for bit, including a repeated knot (empty piece), a flat piece and a current below the floor; the
    photocurrent is read knot-major ([knots, pixels])."""
    from simspad.physics.photoreceptor import MIN_CURRENT_E_S
    from simspad.sensors.events.knot_table import fill_knot_table

    rng = np.random.default_rng(5)
    knot_t = np.array([0.0, 1e-3, 1e-3, 2.5e-3, 4e-3])
    current = rng.lognormal(10.0, 2.0, size=(7, knot_t.size))
    current[1, 3:] = current[1, 2]  # flat pieces
    current[2, 0] = 0.0  # below the floor
    gamma = 0.5
    n_tile = 4
    tabs = [np.full((n_tile, knot_t.size), np.nan), np.full((n_tile, knot_t.size), np.nan),
            np.full((n_tile, knot_t.size), np.nan), np.full((n_tile, knot_t.size - 1), np.nan),
            np.full((n_tile, knot_t.size - 1), np.nan)]
    fill_knot_table(knot_t, np.ascontiguousarray(current.T), 1, 4, gamma, *tabs)
    clamped = np.maximum(current[1:4], MIN_CURRENT_E_S)
    np.testing.assert_array_equal(tabs.pop(0)[:3], clamped)
    log_i = np.array([[math.log(v) for v in row] for row in clamped])
    np.testing.assert_array_equal(tabs[0][:3], log_i)
    np.testing.assert_array_equal(tabs[1][:3], np.array([[math.exp(-0.5 * gamma * v) for v in row] for row in log_i]))
    seg = np.diff(knot_t)
    slope = np.where(seg > 0, np.diff(clamped, axis=1) / np.where(seg > 0, seg, 1.0), 0.0)
    np.testing.assert_array_equal(tabs[2][:3], slope)
    np.testing.assert_array_equal(tabs[3][:3], np.where(slope != 0, 1.0 / np.abs(np.where(slope != 0, slope, 1.0)), 0))
    assert (tabs[2][:3, 1] == 0).all() and (tabs[2][0, 2:] == 0).all() and (tabs[3][0, 2:] == 0).all()
    assert np.isnan(tabs[0][3]).all()  # rows past the tile untouched
