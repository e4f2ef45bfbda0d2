"""Adaptive SPAD sampling: reads follow the filter's uncertainty (motion), not the clock."""

import numpy as np
import pytest

from simspad.io.recording import open_recording
from simspad.methods import get_method
from simspad.methods.adaptive import ReadoutRules, TilePolicy
from simspad.methods.akf import AkfState
from simspad.methods.method import BandwidthTally
from simspad.methods.nedi import spad_measurements
from simspad.methods.spad_response import SpadResponse, estimate_flux
from tests.helpers.synthetic_recordings import write_recording

SHAPE = (16, 64)


def _half_moving(t):
    """Left half: a static texture; right half: a grating moving at 2000 px/s."""
    x = np.arange(SHAPE[1])[None, :] + np.zeros((SHAPE[0], 1))
    y = np.arange(SHAPE[0])[:, None] + np.zeros((1, SHAPE[1]))
    static = 0.6 * np.sin(2 * np.pi * x / 11.0) * np.cos(2 * np.pi * y / 7.0)
    moving = 0.8 * np.sin(2 * np.pi * (x - 2000.0 * t) / 16.0)
    return 3e15 * np.exp(np.where(x < 32, static, moving))


@pytest.fixture(scope="module")
def rec_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("adaptive") / "half.h5"
    # threshold_sigma declares per-event uncertainty, so that moving regions (many events) grow P
    write_recording(path, _half_moving, shape=SHAPE, duration_s=0.03, frames=False,
                    event_attrs=dict(threshold_sigma=0.05))
    return path


def _rms_log(out, gt):
    return float(np.sqrt(np.mean((np.log(np.maximum(out, 1.0)) - np.log(gt)) ** 2)))


@pytest.mark.parametrize("integrate", [False, True])
def test_adaptive_reads_where_the_scene_moves(rec_path, integrate):
    with open_recording(rec_path) as rec:
        gt = rec.gt.flux().astype(np.float64)
        full = get_method("nedi_akf").reconstruct(rec, rec.gt.t)
        out_full = np.stack(list(full))
        m = get_method("adaptive_nedi_akf", tile_px=8, integrate=integrate)
        ad = m.reconstruct(rec, rec.gt.t)
        out_ad = np.stack(list(ad))
    pol = m.last_policy
    # fewer SPAD readouts than the full-rate filter (the static half is read once) ...
    assert pol.readout_fraction < 0.7
    assert ad.bandwidth.bits_per_pixel_s < full.bandwidth.bits_per_pixel_s
    # ... for a bounded loss: ≤ 3 dB in log-RMS terms (factor √2) over the frame, little on the moving half
    assert _rms_log(out_ad, gt) < np.sqrt(2) * _rms_log(out_full, gt)
    assert _rms_log(out_ad[:, :, 32:], gt[:, :, 32:]) < 1.2 * _rms_log(out_full[:, :, 32:], gt[:, :, 32:])


def test_adaptive_reads_static_regions_rarely(rec_path):
    with open_recording(rec_path) as rec:
        m = get_method("adaptive_nedi_akf", tile_px=8)
        for _ in m.reconstruct(rec, rec.gt.t):
            pass
    pol = m.last_policy
    # per-tile read counts: tiles are 8×8, the left 4 tile columns are static
    tiles_x = SHAPE[1] // 8
    per_tile = pol.tile_reads.reshape(SHAPE[0] // 8, tiles_x)
    assert per_tile[:, :4].mean() < 0.5 * per_tile[:, 4:].mean(), per_tile


def test_integration_since_last_readout_uses_all_pending_bins(tmp_path):
    """A tile read after skipping windows gets NEDI over every bin since its previous readout."""
    path = tmp_path / "flat.h5"
    write_recording(path, lambda t: np.full((8, 8), 2e15), shape=(8, 8), duration_s=0.012, frames=False,
                    dcr_cps=10.0)
    with open_recording(path) as rec:
        resp = SpadResponse.from_recording(rec)
        tally = BandwidthTally()
        meas = list(spad_measurements(rec, 100, use_events=True, until_s=0.011, tally=tally))
        pol = TilePolicy((8, 8), tally, resp, ReadoutRules(tile_px=8, threshold=0.5, integrate=True, max_windows=16))
        st = AkfState(8, 8, 0.0)
        st.P[:] = 1.0
        mask, _ = pol.select(st, meas[0], True)  # first window: read
        st.P[:] = 0.1
        for j in (1, 2):
            mask, _ = pol.select(st, meas[j], False)  # below threshold: keep counting
            assert not mask.any()
        st.P[:] = 1.0
        mask, m3 = pol.select(st, meas[3], False)
        assert mask.all()
        counts = sum(meas[j].raw_counts for j in (1, 2, 3))
        expected = estimate_flux(counts, 300, resp.q_m2, resp.gate_s, resp.dcr_cps.reshape(-1))
        assert np.allclose(m3.flux_ref, expected, rtol=1e-9)
        assert np.allclose(m3.var_log, m3.var_log_model(m3.flux_ref), rtol=1e-9)
    assert pol.tile_reads.tolist() == [2]
    # bits: one 7-bit aggregate (100 bins) and one 9-bit aggregate (300 bins) per pixel
    assert tally.bits == 7 + 9
