"""Frame camera: EMVA 1288 photon transfer recovers the configured parameters; exposure integrates the scene."""

import dataclasses

import numpy as np
import pytest

from simspad.analysis import emva
from simspad.errors import SimSpadError
from simspad.io.recording import RecordingWriter, open_recording
from simspad.radiance.timeline import Timeline
from simspad.sensors import frames
from simspad.sensors.presets import FrameParams, sensor_params

SHAPE = (96, 96)


def _ptc_measurement(params, seed=1, n_levels=60, n_bright=4, n_dark=100, exposure_s=1e-3):
    """Flat fields at fixed exposure and increasing irradiance, denser near saturation (EMVA 1288 practice)."""
    rng = np.random.default_rng(seed)
    pattern = frames.draw_fixed_pattern(params, SHAPE, rng)
    full_p = params.full_well_e / params.qe
    mu_p = np.concatenate([np.linspace(0.0, 0.9 * full_p, n_levels // 2, endpoint=False),
                           np.linspace(0.9 * full_p, 1.15 * full_p, n_levels - n_levels // 2)])
    bright = [np.stack([frames.expose(np.full(SHAPE, m), exposure_s, pattern, params, rng) for _ in range(n_bright)])
              for m in mu_p]
    dark = np.stack([frames.expose(np.zeros(SHAPE), exposure_s, pattern, params, rng) for _ in range(n_dark)])
    return emva.photon_transfer(bright, dark, mu_p)


@pytest.mark.parametrize("overrides", [{}, {"gain_dn_per_e": 0.25, "read_noise_e": 6.0, "dsnu_e": 3.0,
                                             "prnu": 0.02, "full_well_e": 12000.0}])
def test_photon_transfer_recovers_emva_parameters(overrides):
    params = sensor_params("frames", "blackfly_s", overrides)
    r = _ptc_measurement(params)
    # the temporal dark noise includes the dark current's shot noise over the exposure (1 ms: 0.003 e⁻)
    read_e = np.sqrt(params.read_noise_e ** 2 + params.dark_current_e_s * 1e-3)
    assert r.gain_dn_per_e == pytest.approx(params.gain_dn_per_e, rel=0.03)
    assert r.read_noise_e == pytest.approx(read_e, rel=0.05)
    # EMVA's saturation point (maximum temporal variance) sits a few % below the physical full well: pixels
    # with a high PRNU gain clip first, and the ADC range may end just before the full well
    assert r.saturation_e == pytest.approx(params.full_well_e, rel=0.10)
    assert r.dsnu_e == pytest.approx(params.dsnu_e, rel=0.10)
    assert r.prnu == pytest.approx(params.prnu, rel=0.10)
    assert r.qe == pytest.approx(params.qe, rel=0.03)


def test_quantisation_rounds_to_the_nearest_dn_and_clips_exactly():
    """With no photons, no read noise and no dark current the electrons are the DSNU map itself, so every DN is
    known: round(K·e⁻ + black) to the nearest integer, then clipped to [0, 2^bits − 1]. Each fraction below
    is 1/64 off a half, so truncation or a half-DN offset changes half the pixels."""
    params = dataclasses.replace(FrameParams(), read_noise_e=0.0, dark_current_e_s=0.0, gain_dn_per_e=0.25,
                                 black_level_dn=40.0)
    k = np.arange(64)
    analog = 40.0 + k / 8 + 1 / 64  # fractions 1/64, 9/64, ... never a tie
    dsnu = ((analog - 40.0) / 0.25).reshape(8, 8)
    pattern = frames.FixedPattern(prnu_gain=np.ones((8, 8)), dsnu_e=dsnu)
    dn = frames.expose(np.zeros((8, 8)), 1e-3, pattern, params, np.random.default_rng(0))
    expected = 40 + (k + 4) // 8  # k/8 + 1/64 rounds up exactly when k mod 8 ≥ 4
    np.testing.assert_array_equal(dn.reshape(-1), expected)
    assert dn.dtype == np.uint16
    assert dn.mean() - analog.mean() == pytest.approx(0.5 - 1 / 64 - 7 / 16)  # the mean rounding error: 3/64
    # the clip at both ends of the ADC range: far below 0 and far above 2^12 − 1
    edges = frames.FixedPattern(prnu_gain=np.ones((1, 2)), dsnu_e=np.array([[-1000.0, 1e5]]))
    out = frames.expose(np.zeros((1, 2)), 1e-3, edges, dataclasses.replace(params, full_well_e=1e9),
                        np.random.default_rng(0))
    np.testing.assert_array_equal(out, [[0, frames.dn_max(params)]])


def test_photon_transfer_detects_a_wrong_gain():
    """The analysis is sensitive: a camera with 10 % more gain is measured as such (not the preset)."""
    params = dataclasses.replace(FrameParams(), gain_dn_per_e=0.39 * 1.1)
    r = _ptc_measurement(params, seed=2, n_levels=20, n_dark=20)
    assert abs(r.gain_dn_per_e / 0.39 - 1.1) < 0.03


def _flat_timeline(flux, times=(0.0, 0.1), shape=(24, 32)):
    keyframes = np.full((len(times), *shape), flux, np.float32)
    return Timeline.from_arrays(np.asarray(times), keyframes)


def test_simulate_frames_flat_field_statistics_and_attrs(tmp_path):
    params = FrameParams(frame_rate_hz=200.0)
    flux = 3e17  # photons s⁻¹ m⁻²: 2.3e6 e⁻/s, so auto exposure (3.6 ms) is set by the full well
    tl = _flat_timeline(flux)
    with RecordingWriter(tmp_path / "r.h5", {"width": 32, "height": 24, "duration_s": 0.1, "lux": 1.0}) as w:
        attrs = frames.simulate_frames(w, tl, 0.0, 0.1, params, np.random.default_rng(5))
    rate_e = params.qe * flux * params.pixel_pitch_m ** 2 * params.fill_factor + params.dark_current_e_s
    expected_exposure = min(params.max_exposure_s, 1 / params.frame_rate_hz,
                            params.auto_max_fill * params.full_well_e / rate_e)
    assert expected_exposure < 1 / params.frame_rate_hz  # the full-well criterion binds, not the frame period
    assert attrs["exposure_s"] == pytest.approx(expected_exposure)
    with open_recording(tmp_path / "r.h5") as rec:
        dn = rec.frames.dn().astype(np.float64)
        t_start, t_end = rec.frames.t_start, rec.frames.t_end
        fa = rec.frames.attrs
    assert dn.shape == (20, 24, 32)
    np.testing.assert_allclose(np.diff(t_start), 1 / params.frame_rate_hz)
    np.testing.assert_allclose(t_end - t_start, expected_exposure)
    for key in ("gain_dn_per_e", "read_noise_e", "full_well_e", "bit_depth", "black_level_dn", "qe",
                "pixel_pitch_m", "fill_factor", "pixel_area_m2", "exposure_s", "dsnu_e", "prnu"):
        assert key in fa
    mean_e = rate_e * expected_exposure
    expected_dn = params.gain_dn_per_e * mean_e + params.black_level_dn
    # per-frame mean over 768 pixels: σ ≈ K·sqrt(mean_e + (PRNU·mean_e)²)/sqrt(768)
    sigma = params.gain_dn_per_e * np.sqrt(mean_e + (params.prnu * mean_e) ** 2 + params.read_noise_e ** 2)
    assert abs(dn.mean() - expected_dn) < 5 * sigma / np.sqrt(dn.size)  # no slack: rounding is unbiased
    assert dn.var(axis=0).mean() == pytest.approx(params.gain_dn_per_e ** 2 * (mean_e + params.read_noise_e ** 2)
                                                   + 1 / 12, rel=0.1)


def test_window_fluence_is_exact_for_motion_and_rolling_shutter():
    rng = np.random.default_rng(0)
    times = np.array([0.0, 0.003, 0.004, 0.01])
    keyframes = rng.uniform(0, 1e15, (4, 8, 5)).astype(np.float32)
    tl = Timeline.from_arrays(times, keyframes)
    line_s = 4e-4
    starts = 0.001 + np.arange(8) * line_s
    got = frames.window_fluence(tl, starts, 0.005)
    fine = np.linspace(0, 1, 20001)
    for r in (0, 3, 7):
        ts = starts[r] + 0.005 * fine
        values = np.stack([tl.sample(t)[r] for t in ts[::50]])  # piecewise linear: trapezoid on a fine grid
        ref = np.trapezoid(values, ts[::50], axis=0)
        np.testing.assert_allclose(got[r], ref, rtol=2e-4)
    # a rolling shutter sees later instants in lower rows: on a brightening flat field lower rows collect more
    ramp = Timeline.from_arrays([0.0, 0.02], np.stack([np.full((8, 5), 1e15), np.full((8, 5), 3e15)]).astype(np.float32))
    f = frames.window_fluence(ramp, 0.001 + np.arange(8) * line_s, 0.004)
    expected = (1e15 + 2e15 * (0.001 + np.arange(8) * line_s + 0.002) / 0.02) * 0.004
    np.testing.assert_allclose(f[:, 0], expected, rtol=1e-6)


def test_rolling_shutter_recording_skews_rows_and_fits_the_readout(tmp_path):
    """A brightening flat field seen through a rolling shutter: lower rows integrate later, brighter light."""
    H, W, line_s = 24, 32, 1e-4
    ramp = Timeline.from_arrays([0.0, 0.1], np.stack([np.full((H, W), 1e16), np.full((H, W), 1e17)]).astype(np.float32))
    params = FrameParams(exposure_s=8e-3, frame_rate_hz=100.0, rolling_shutter_line_s=line_s)
    with RecordingWriter(tmp_path / "rs.h5", {"width": W, "height": H, "duration_s": 0.1, "lux": 1.0}) as w:
        attrs = frames.simulate_frames(w, ramp, 0.0, 0.1, params, np.random.default_rng(2))
    with open_recording(tmp_path / "rs.h5") as rec:
        dn = rec.frames.dn().astype(np.float64)
        t_start = rec.frames.t_start
    assert attrs["shutter"] == "rolling" and attrs["readout_s"] == pytest.approx((H - 1) * line_s)
    assert t_start[-1] + 8e-3 + (H - 1) * line_s <= 0.1 + 1e-12  # every row of every frame inside the interval
    assert dn.shape[0] == 9  # a global shutter fits 10; the 10th frame's last rows would end after 0.1 s
    k = dn.shape[0] - 1
    row_means = dn[k].mean(axis=1) - params.black_level_dn
    starts = t_start[k] + np.arange(H) * line_s
    fluence = (1e16 + 9e17 * (starts + 4e-3)) * 8e-3
    expected = params.gain_dn_per_e * params.qe * fluence * params.pixel_pitch_m ** 2
    np.testing.assert_allclose(row_means, expected, rtol=0.02)
    assert np.polyfit(np.arange(H), row_means, 1)[0] > 0


def test_bayer_mosaic_follows_the_colour_of_the_scene(tmp_path):
    red = np.zeros((2, 6, 8, 3), np.float32)
    red[..., 0] = 3e17
    tl = Timeline.from_arrays([0.0, 0.05], red)
    params = FrameParams(rgb=True, exposure_s=2e-3, frame_rate_hz=100.0)
    with RecordingWriter(tmp_path / "c.h5", {"width": 8, "height": 6, "duration_s": 0.05, "lux": 1.0}) as w:
        attrs = frames.simulate_frames(w, tl, 0.0, 0.05, params, np.random.default_rng(1))
    with open_recording(tmp_path / "c.h5") as rec:
        dn = rec.frames.dn().astype(np.float64).mean(axis=0)
    channel = frames.bayer_channel_map(6, 8)
    assert attrs["bayer_pattern"] == "RGGB" and attrs["rgb_source"] == "rgb"
    assert dn[channel == 0].mean() > params.black_level_dn + 100
    assert abs(dn[channel != 0].mean() - params.black_level_dn) < 2


def test_bad_exposure_is_refused_with_the_field_named():
    # the parameter record refuses it when built, so no simulator (and no file) ever sees it
    with pytest.raises(SimSpadError, match="longer than the frame period") as info:
        FrameParams(exposure_s=0.02, frame_rate_hz=100.0)
    assert info.value.field == "sensors.frames.exposure_s"


def test_saturation_clips_at_full_well_and_adc():
    params = FrameParams()
    rng = np.random.default_rng(3)
    pattern = frames.draw_fixed_pattern(params, (32, 32), rng)
    dn = frames.expose(np.full((32, 32), 1e6), 1e-3, pattern, params, rng)
    assert dn.dtype == np.uint16
    assert dn.max() <= frames.dn_max(params)
    assert dn.min() >= min(frames.dn_max(params),
                           params.gain_dn_per_e * params.full_well_e + params.black_level_dn - 10)
