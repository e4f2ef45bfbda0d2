"""Measurement windows: the unit in which SPAD aggregates and conventional frames reach the methods.

A :class:`Measurement` is one deblurred (or naively inverted) intensity image valid over a time interval
``[a_s, b_s)``: ``ln Φ(t) = ln Φ(f) + ℓ(t) − ℓ(f)`` for t in the interval, with ℓ the event level counted from
``a_s`` (:mod:`simspad.methods.event_batches`). Windows tile time contiguously and are produced lazily, in order,
so methods stream through long recordings holding one window's events at a time.

:func:`open_loop_frames` turns a measurement stream into output frames without any filter (NI, NEDI, EDI).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Iterator

import numpy as np

from simspad.methods.event_batches import EventBatch, levels_at


@dataclass
class Measurement:
    """One intensity image and its validity interval.

    Attributes
    ----------
    a_s, b_s : float
        The interval during which this is the latest measurement (s).
    t_ref_s : float
        The reference instant f the image refers to (s).
    flux_ref : ndarray [N] float64
        Φ(f), photon irradiance (ph s⁻¹ m⁻²), flattened; may be 0.
    floor_flux : float or ndarray [N]
        The log-domain floor of this measurement (irradiance of a half count / electron).
    var_log : ndarray [N] float64
        Var(ln Φ̂(f)) from the sensor response.
    level_ref : ndarray [N] float64
        ℓ(f): event level at f counted from ``a_s`` (zeros without events).
    events : EventBatch or None
        Events in ``[a_s, b_s)`` (None for methods without events).
    readout_bits : float
        Bits per pixel this measurement cost (ceil(log2(n+1)) for a SPAD aggregate, bit depth for a frame).
    duration_s : float
        The nominal sampling period the measurement stands for (window length / frame period), used to turn
        ``var_log`` into a continuous-time measurement noise density for the Kalman filter.
    var_log_model : callable or None
        ``flux [N] -> Var(ln Φ̂) [N]``: the response's variance at a given irradiance. A filter evaluates it at
        its *predicted* irradiance: weighting measurements by a variance computed from their own value favours
        high draws (weights ∝ Φ̂ for photon counts) and biases the fused estimate upwards.
    """

    a_s: float
    b_s: float
    t_ref_s: float
    flux_ref: np.ndarray
    floor_flux: float | np.ndarray
    var_log: np.ndarray
    level_ref: np.ndarray
    events: EventBatch | None
    readout_bits: float
    duration_s: float
    var_log_model: Callable[[np.ndarray], np.ndarray] | None = None
    raw_counts: np.ndarray | None = None
    """SPAD windows only: the ones per pixel [N] and the bins' sampling instants, for re-aggregation."""
    raw_bin_t: np.ndarray | None = None
    low_count_update: Callable | None = None
    """SPAD windows only: ``(u_pred, P) -> (mask, u_eq, var_eq)``, the equivalent Gaussian measurement of ln Φ(f)
    for pixels with few counts, where ln Φ̂ is not Gaussian (see :func:`simspad.methods.nedi.laplace_update`)."""

    def var_log_predicted(self, flux_pred: np.ndarray) -> np.ndarray:
        """Var(ln Φ̂) at the predicted irradiance, keeping the measurement's own structure (events in the window)
        through the ratio ``var_log · model(pred)/model(Φ̂)``."""
        if self.var_log_model is None:
            return self.var_log
        own = self.var_log_model(np.maximum(self.flux_ref, self.floor_flux))
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            ratio = self.var_log_model(flux_pred) / own
        # Within a factor 4 the prediction removes the bias of self-weighting; beyond that prediction and
        # measurement disagree (a change the events missed) and the innovation test deals with it.
        ratio = np.where(np.isfinite(ratio), np.clip(ratio, 0.25, 4.0), 1.0)
        return self.var_log * ratio

    def log_flux_at_start(self) -> np.ndarray:
        """ln Φ(a) = ln max(Φ(f), floor) − ℓ(f)."""
        return np.log(np.maximum(self.flux_ref, self.floor_flux)) - self.level_ref


def open_loop_frames(measurements: Iterable[Measurement], times_s: np.ndarray, shape: tuple[int, int],
                     tally=None) -> Iterator[np.ndarray]:
    """Output ``Φ(t) = Φ(f)·exp(ℓ(t) − ℓ(f))`` at each instant from the measurement whose interval holds it.

    Instants before the first interval use the first measurement at its start; the last measurement's interval
    must extend to the last instant (sources take ``until_s``). ``tally`` (optional) is charged the readout
    bits of every measurement used.
    """
    n_pix = shape[0] * shape[1]
    it = iter(measurements)
    m = next(it, None)
    if m is None:
        return
    _charge(tally, m)
    lev, used = np.zeros(n_pix), 0
    for t in times_s:
        while t >= m.b_s:
            nxt = next(it, None)
            if nxt is None:
                break
            m = nxt
            _charge(tally, m)
            lev, used = np.zeros(n_pix), 0
        if m.events is not None:
            lev, used = levels_at(m.events, t, n_pix, used, lev)
        img = m.flux_ref * np.exp(lev - m.level_ref)
        yield img.reshape(shape).astype(np.float32)


def _charge(tally, m: Measurement) -> None:
    if tally is not None:
        tally.add(1.0, m.readout_bits)
