"""SPAD sensor model (docs/sensors.md, preset ``swissspad2``): gated binary frames with calibrated noise.

Model
-----
Binary frame ``k`` starts at ``t_k = t0 + k·bin_s``; its gate is ``[t_k, t_k + gate_s]`` (gate at the start of
the bin). A pixel's bit is 1 when at least one photon or dark detection falls inside the gate:

    Λ_k = q·∫_gate Φ(t) dt + r_dark·gate_s,      P(bit = 1) = 1 − exp(−Λ_k),

with ``Φ`` the sensor-plane photon irradiance (photons s⁻¹ m⁻²), ``q = pixel_pitch_m²·fill_factor·qe``
(m², the detection area, :func:`simspad.physics.radiometry.detection_area_m2`) and ``r_dark`` the pixel's dark count
rate (a fixed log-normal map with a fraction of hot pixels). The timeline is piecewise linear in time, so the
integral is exact: inside one linear piece Λ_k is an affine function of ``k``; a gate that straddles a keyframe
is integrated piece by piece.

Secondary effects, drawn from each *primary* detection (second-order cascades, ∝ p², are neglected):

- afterpulsing: the detection triggers a spurious detection in the same pixel's next bin with probability
  ``afterpulsing_probability``;
- crosstalk: the detection triggers each of the 4 neighbours in the same bin with probability
  ``crosstalk_probability`` (a trial towards a neighbour outside the array is lost).

Dead time (``dead_time_s``, ≈ 100 ns) does not change the bit in gated 1-bit mode: the first detection in a
gate sets the bit, and detections the dead time hides would only have set it again. The one residual effect —
a detection in the last ``dead_time_s`` of gate k blinding the start of gate k+1 when ``bin_s − gate_s`` is
shorter than the dead time — removes at most ``dead_time_s/gate_s`` of that gate (≤ 1 % for the 10 µs gates
where it can happen) and is neglected. The value is recorded in the attrs for free-running analyses.

This module holds the model's pure functions (dark count map, gate, bin count, bit packing, attrs); the sampler
is in :mod:`~simspad.sensors.spad.kernel` and the streaming driver in :mod:`~simspad.sensors.spad.simulator`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from simspad.sensors.presets import SpadParams, params_to_attrs


def dcr_map(shape: tuple[int, int], params: SpadParams, rng: np.random.Generator) -> np.ndarray:
    """Dark count rate of every pixel, counts s⁻¹, float32 ``[H, W]``.

    Ordinary pixels are log-normal around ``dcr_median_cps`` (σ of ln DCR = ``dcr_log_sigma``); a fraction
    ``hot_pixel_fraction`` of pixels, chosen at random, are hot: log-normal around ``hot_pixel_dcr_cps`` with
    the same σ.
    """
    # Each pixel is hot independently with probability f: the same law as a binomial number of hot pixels at
    # uniformly chosen places, which costs ~0.1 ms per 512² instead of ~0.9 for a uniform draw per pixel.
    n_pixels = math.prod(shape)
    hot = rng.choice(n_pixels, size=rng.binomial(n_pixels, params.hot_pixel_fraction), replace=False, shuffle=False)
    # float32 throughout (the map's own precision): half the time of float64 draws and temporaries
    spread = rng.standard_normal(shape, dtype=np.float32)
    spread *= np.float32(params.dcr_log_sigma)
    np.exp(spread, out=spread)
    dcr = spread * np.float32(params.dcr_median_cps)
    dcr.ravel()[hot] = spread.ravel()[hot] * np.float32(params.hot_pixel_dcr_cps)
    return dcr


def auto_gate(rate_cps, bin_s: float, min_gate_s: float, max_probability: float = 0.9,
              percentile: float = 99.0) -> float:
    """Longest gate in ``[min_gate_s, bin_s]`` keeping the ``percentile`` detection probability ≤ ``max_probability``.

    P(1) = 1 − exp(−rate·gate) is monotone in rate, so the percentile of P is P at the rate's percentile and the
    gate solves ``rate_p·gate = −ln(1 − max_probability)``.

    Parameters
    ----------
    rate_cps : ndarray
        Detection rate per pixel (photon + dark), counts s⁻¹, from the first keyframe.
    bin_s, min_gate_s : float
        Bin period and shortest gate the sensor supports, s.
    """
    rate_p = float(np.percentile(np.asarray(rate_cps, dtype=np.float64), percentile))
    if rate_p <= 0:
        return float(bin_s)
    gate = -math.log1p(-max_probability) / rate_p
    return float(min(max(gate, min_gate_s), bin_s))


def resolve_gate(params: SpadParams, rate_cps=None) -> float:
    """The gate in seconds: ``params.gate_s`` (its range checked by the record,
    :class:`~simspad.sensors.presets.SpadParams`), or :func:`auto_gate` for ``"auto"``."""
    if params.gate_s == "auto":
        if rate_cps is None:
            raise ValueError("auto gate needs the detection rate of the first keyframe")
        return auto_gate(rate_cps, params.bin_s, params.min_gate_s, params.auto_max_probability,
                         params.auto_percentile)
    return min(float(params.gate_s), float(params.bin_s))  # within [min_gate_s, bin_s]: the record checked it


def n_bins(duration_s: float, bin_s: float, gate_s: float) -> int:
    """Number of whole binary frames whose gate lies inside an interval of ``duration_s``."""
    if duration_s < gate_s:
        return 0
    return int(math.floor((duration_s - gate_s) / bin_s * (1 + 1e-12) + 1e-9)) + 1


def pack_bits(bits: np.ndarray) -> np.ndarray:
    """Pack ``[..., W]`` 0/1 into ``[..., ceil(W/8)]`` uint8, little bit order along W (docs/format.md)."""
    return np.packbits(np.asarray(bits, dtype=np.uint8), axis=-1, bitorder="little")


def unpack_bits(packed: np.ndarray, width: int) -> np.ndarray:
    """Inverse of :func:`pack_bits`."""
    return np.unpackbits(packed, axis=-1, count=width, bitorder="little")


def spad_attrs(params: SpadParams, gate_s: float, n: int, t0: float) -> dict:
    """Group attrs: every parameter with the gate resolved, plus what inverting the data needs."""
    attrs = params_to_attrs(dataclasses.replace(params, gate_s=gate_s))
    area = float(params.pixel_pitch_m) ** 2
    attrs.update(gate_auto=params.gate_s == "auto", pixel_area_m2=area, detection_area_m2=params.detection_area_m2,
                 frame_rate_hz=1.0 / params.bin_s, n_bins=int(n), t0=float(t0), gate_position="start",
                 bit_order="little", dead_time_model="none in gated 1-bit mode (first detection sets the bit)",
                 secondary_model="afterpulse: next bin same pixel; crosstalk: 4-neighbours same bin; "
                                 "from primary detections only")
    return attrs
