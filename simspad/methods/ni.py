"""NI (S): naive integration of SPAD bits (docs/methods.md).

Sum n consecutive binary frames and invert the response with the ML estimator of docs/sensors.md
(``Φ̂ = (−ln(1 − S/n)/gate_s − r_dark)/q``, S = n clamped to n − 1). Each output instant takes the aggregate
whose window holds it. Default n from the 0.4 kHz aggregate rate of the paper's Deblur(S) row.
It is NEDI with the events left out: the same aggregation and inversion, no deblurring.
"""

from __future__ import annotations

from simspad.methods.nedi import NEDI


class NI(NEDI):
    """NI (S): aggregate ``n_bins`` (default from ``aggregate_hz`` = 400 Hz) and invert the SPAD response."""

    name = "ni"
    label = "NI (S)"
    full_name = "Naive integration: the maximum-likelihood irradiance of each SPAD aggregate, no deblurring"
    citation = "baseline of Muglikar et al., IEEE TPAMI 2025"
    sensors = "S"
    requires = ("spad",)
    use_events = False
