"""NI (S) inverts the SPAD response on a flat field within its predicted standard deviation."""

import numpy as np
import pytest

from simspad.io.recording import open_recording
from simspad.methods import get_method
from simspad.methods.spad_response import log_flux_variance
from tests.helpers.synthetic_recordings import SPAD_ATTRS, spad_q, write_recording


@pytest.mark.parametrize("x", [0.1, 1.5])
def test_ni_flat_field_within_predicted_std(tmp_path, x):
    shape = (32, 32)
    q, gate = spad_q(), SPAD_ATTRS["gate_s"]
    phi = x / (q * gate)
    path = tmp_path / "flat.h5"
    write_recording(path, lambda t: np.full(shape, phi), shape=shape, duration_s=0.01, frames=False, events=False,
                    dcr_cps=20.0, seed=int(x * 10))
    with open_recording(path) as rec:
        times = (np.arange(4) + 0.5) * 244 * SPAD_ATTRS["bin_s"]  # one instant per aggregate
        r = get_method("ni").reconstruct(rec, times)
        out = np.stack(list(r)).astype(np.float64)
        bw = r.bandwidth
    err = np.log(out / phi)
    sd = np.sqrt(log_flux_variance(phi, 244, q, gate, 20.0))
    assert abs(err.mean()) < 4 * sd / np.sqrt(err.size) + 0.01
    assert 0.88 < err.std() / sd < 1.12
    # one 8-bit aggregate (0..244) per 244 bins at 97.7 kHz: 0.4 kHz, 3.2 kbit/s per pixel
    rate = 1.0 / (244 * SPAD_ATTRS["bin_s"])
    assert bw.readout_khz_per_pixel == pytest.approx(rate / 1e3, rel=1e-9)
    assert bw.bits_per_pixel_s == pytest.approx(8 * rate, rel=1e-9)
