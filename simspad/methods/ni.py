"""NI (S): naive integration of SPAD bits (DESIGN §7).

Sum n consecutive binary frames and invert the response with the ML estimator of §4
(``Φ̂ = (−ln(1 − S/n)/gate_s − r_dark)/q``, S = n clamped to n − 1). Each output instant takes the aggregate
whose window holds it. Default n from the 0.4 kHz aggregate rate of the paper's Deblur(S) row.
"""

from __future__ import annotations

from simspad.methods.nedi import DEFAULT_AGGREGATE_HZ, aggregate_bins, spad_measurements
from simspad.methods.registry import Method
from simspad.methods.windows import open_loop_frames


class NI(Method):
    """NI (S): aggregate ``n_bins`` (default from ``aggregate_hz`` = 400 Hz) and invert the SPAD response."""

    name = "ni"
    label = "NI (S)"
    sensors = "S"
    requires = ("spad",)
    absolute_scale = True

    def __init__(self, aggregate_hz: float = DEFAULT_AGGREGATE_HZ, n_bins: int | None = None):
        self.aggregate_hz = aggregate_hz
        self.n_bins = n_bins

    def _run(self, rec, times_s, tally):
        n = aggregate_bins(rec, self.aggregate_hz, self.n_bins)
        until = float(times_s[-1]) + 1e-9 if times_s.size else 0.0
        meas = spad_measurements(rec, n, use_events=False, until_s=until, tally=tally)
        yield from open_loop_frames(meas, times_s, (int(rec.height), int(rec.width)), tally)
