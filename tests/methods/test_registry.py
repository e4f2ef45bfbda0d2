"""Registry, requirements and an end-to-end run of every method on a small synthetic recording."""

import numpy as np
import pytest

from simspad.errors import InputError, SimSpadError
from simspad.io.recording import open_recording
from simspad.methods import available_methods, get_method
from tests.helpers.synthetic_recordings import SPAD_ATTRS, write_recording

NAMES = ["nedi_akf", "adaptive_nedi_akf", "akf_fe", "cf", "edi", "ni", "nedi", "qbp"]
SHAPE = (16, 48)


def _grating(speed_px_s):
    def flux(t):
        x = np.arange(SHAPE[1])[None, :] + np.zeros((SHAPE[0], 1))
        return 2e15 * np.exp(0.8 * np.sin(2 * np.pi * (x - speed_px_s * t) / 24.0))
    return flux


@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "grating.h5"
    write_recording(path, _grating(6000.0), shape=SHAPE, duration_s=0.02, frame_rate_hz=500.0, exposure_s=1e-3)
    return path


def test_registry_lists_methods_and_requirements():
    assert available_methods() == NAMES
    expect = {"nedi_akf": ("S+E", {"spad", "events"}, True), "akf_fe": ("F+E", {"frames", "events"}, True),
              "cf": ("E", {"events"}, False), "qbp": ("S", {"spad"}, True), "ni": ("S", {"spad"}, True)}
    for name, (sensors, req, absolute) in expect.items():
        m = get_method(name)
        assert m.sensors == sensors and set(m.requires) == req and m.absolute_scale == absolute
        assert f"({sensors})" in m.label
    assert get_method("ni", n_bins=100).n_bins == 100
    with pytest.raises(SimSpadError, match="unknown method 'nope'"):
        get_method("nope")
    with pytest.raises(SimSpadError, match="bad parameters"):
        get_method("ni", no_such_parameter=1)


def test_missing_sensor_is_refused(tmp_path):
    path = tmp_path / "spad_only.h5"
    write_recording(path, lambda t: np.full(SHAPE, 1e15), shape=SHAPE, duration_s=0.006, frames=False,
                    events=False)
    with open_recording(path) as rec:
        assert available_methods(rec) == ["ni", "qbp"]
        with pytest.raises(InputError, match="events"):
            get_method("nedi_akf").reconstruct(rec, rec.gt.t)


def test_all_methods_end_to_end(moving):
    with open_recording(moving) as rec:
        times = rec.gt.t
        gt = rec.gt.flux().astype(np.float64)
        n_ev = rec.events.n_events
        errs, bws = {}, {}
        for name in available_methods(rec):
            r = get_method(name).reconstruct(rec, times)
            with pytest.raises(RuntimeError):
                r.bandwidth
            out = np.stack(list(r))
            assert out.shape == (times.size,) + SHAPE and out.dtype == np.float32 and np.isfinite(out).all()
            bws[name] = r.bandwidth
            if get_method(name).absolute_scale and name not in ("edi", "akf_fe"):
                errs[name] = np.sqrt(np.mean((np.log(np.maximum(out, 1.0)) - np.log(gt)) ** 2))
    # Quality on fast motion (≈ 15 px per aggregate): event deblurring beats naive integration by far.
    assert errs["nedi"] < 0.5 * errs["ni"], errs
    assert errs["nedi_akf"] < errs["nedi"], errs
    assert errs["qbp"] < errs["ni"], errs
    # Bandwidth (docs/methods.md).
    bin_s = SPAD_ATTRS["bin_s"]
    assert bws["qbp"].readout_khz_per_pixel == pytest.approx(1e-3 / bin_s, rel=1e-6)
    assert bws["qbp"].bits_per_pixel_s == pytest.approx(1.0 / bin_s, rel=1e-6)
    ni = bws["ni"]
    assert ni.readout_khz_per_pixel == pytest.approx(1e-3 / (244 * bin_s), rel=1e-6)
    ev_khz = n_ev / (SHAPE[0] * SHAPE[1]) / 0.02 / 1e3  # events per pixel per second over the recording
    assert bws["cf"].readout_khz_per_pixel == pytest.approx(ev_khz, rel=0.1)
    assert bws["cf"].bits_per_pixel_s == pytest.approx(32e3 * bws["cf"].readout_khz_per_pixel, rel=1e-9)
    assert bws["nedi"].readout_khz_per_pixel - ni.readout_khz_per_pixel == pytest.approx(ev_khz, rel=0.1)
    assert bws["nedi"].bits_per_pixel_s > ni.bits_per_pixel_s
    assert bws["adaptive_nedi_akf"].bits_per_pixel_s < bws["nedi_akf"].bits_per_pixel_s


def test_reconstruction_is_deterministic(moving):
    with open_recording(moving) as rec:
        a = np.stack(list(get_method("adaptive_nedi_akf").reconstruct(rec, rec.gt.t)))
        b = np.stack(list(get_method("adaptive_nedi_akf").reconstruct(rec, rec.gt.t)))
    assert np.array_equal(a, b)
