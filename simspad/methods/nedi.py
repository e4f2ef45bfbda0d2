"""NEDI: nonlinear event double integral deblurring of aggregated SPAD frames (docs/methods.md).

For an aggregate of n gated bins at times t_k (gate centres) with S ones, and the latent irradiance
``Φ(t) = Φ(f)·exp(ℓ(t) − ℓ(f))`` from events, the expected count is

    E[S] = Σ_k 1 − exp(−(q·Φ(f)·a_k + r_dark)·gate_s),   a_k = exp(ℓ(t_k) − ℓ(f)),

strictly increasing and concave in Φ(f). ℓ is piecewise constant, so the sum groups the bins by level
(one segment per event at the pixel). It is solved per pixel by Newton's method inside a bracket
``[Φ_ML/max a, Φ_ML/min a]`` (the roots with all a_k at their extremes), bisecting when a step leaves the
bracket, starting from linear EDI ``Φ_ML/mean a`` (Φ_ML the estimator of docs/sensors.md on S, n). Linear EDI is biased
when a varies in the window and the response is nonlinear (x = qΦ·gate ≳ 1): the test suite measures it.

The variance of ln Φ̂(f) is the Cramér–Rao bound of the n Bernoulli bins,
``1 / Σ_k x_k²/(e^{y_k} − 1)``, ``x_k = qΦ(f)a_k·gate``, ``y_k = x_k + r_dark·gate`` (docs/sensors.md's formula when a ≡ 1).

Default aggregation: 0.4 kHz (n = round(1/(0.4 kHz·bin_s)) = 244 bins at 97.7 kHz), the readout rate of the
reference paper's Deblur(S) and NEDI+AKF rows (docs/methods.md).
"""

from __future__ import annotations

from typing import Iterator, NamedTuple

import numba
import numpy as np

from simspad.errors import InputError
from simspad.methods.event_batches import (
    EventBatch,
    EventCursor,
    PixelEvents,
    group_by_pixel,
)
from simspad.methods.method import BandwidthTally, Method, aggregate_bits
from simspad.methods.spad_response import SpadResponse, floor_flux, log_flux_variance
from simspad.methods.windows import Measurement, open_loop_frames

DEFAULT_AGGREGATE_HZ = 400.0
"""Aggregate readout rate of the reference paper's Deblur(S) / NEDI+AKF (0.4 kHz per pixel)."""

GATE_AT_BIN_START = True
"""The gate opens at each bin's ``t_start`` (docs/format.md /spad/t_start): a bin samples at ``t_start + gate_s/2``."""


class AggregateWindow(NamedTuple):
    """One SPAD aggregate as the NEDI kernel reads it."""

    counts: np.ndarray
    """[N] float64 ones per pixel."""
    n_bins: int
    """Bins aggregated."""
    bin_t: np.ndarray
    """[n_bins] sorted sampling instants of the bins (s)."""
    t_ref: float
    """Reference instant f (s)."""


class NediResponse(NamedTuple):
    """The SPAD response the kernel inverts (:class:`simspad.methods.spad_response.SpadResponse`)."""

    q_m2: float
    """Detection area qe·fill·pitch² (m²)."""
    gate_s: float
    dcr_cps: np.ndarray
    """[N] dark count rate per pixel (counts s⁻¹)."""
    phi_floor: float
    """Flux floor (ph s⁻¹ m⁻²) at which the variance is evaluated for dark pixels."""
    linear: bool
    """Linear EDI on −ln(1 − S/n) instead of the exact response."""


class NediOutputs(NamedTuple):
    """[N] float64 arrays the kernel writes: Φ(f), Var(ln Φ̂) and ℓ(f)."""

    phi: np.ndarray
    var_log: np.ndarray
    level_ref: np.ndarray


@numba.njit(cache=True)
def _solve_pixel(m, a, nseg, s, n, q, g, r, linear):
    dark = n * (1.0 - np.exp(-r * g))
    if s <= dark:
        return 0.0
    phi_ml = (-np.log1p(-s / n) / g - r) / q
    amin = a[0]
    amax = a[0]
    wsum = 0.0
    for j in range(nseg):
        if a[j] < amin:
            amin = a[j]
        if a[j] > amax:
            amax = a[j]
        wsum += m[j] * a[j]
    phi = phi_ml * n / wsum
    if linear or amin == amax:
        return phi
    lo = phi_ml / amax
    hi = phi_ml / amin
    for _ in range(100):
        f = -s
        fp = 0.0
        for j in range(nseg):
            if m[j] > 0:
                e = np.exp(-(q * phi * a[j] + r) * g)
                f += m[j] * (1.0 - e)
                fp += m[j] * q * a[j] * g * e
        if f > 0:
            hi = phi
        else:
            lo = phi
        new = phi - f / fp if fp > 0 else 0.5 * (lo + hi)
        if not (lo < new < hi):
            new = 0.5 * (lo + hi)
        if abs(new - phi) <= 1e-12 * phi or hi - lo <= 1e-12 * hi:
            return new
        phi = new
    return phi


@numba.njit(cache=True)
def _fisher_var_log(m, a, nseg, phi, q, g, r):
    info = 0.0
    for j in range(nseg):
        x = q * phi * a[j] * g
        y = x + r * g
        info += m[j] * x * x / np.expm1(y)
    return 1.0 / info


@numba.njit(cache=True)
def nedi_kernel(window: AggregateWindow, events: PixelEvents, response: NediResponse, out: NediOutputs) -> None:
    """Solve NEDI (or linear EDI when ``response.linear``) for every pixel; see the module docstring.

    Events are grouped per pixel (time order within a pixel). Writes Φ(f), Var(ln Φ̂) and ℓ(f) (counted from the
    window start) per pixel into ``out``.
    """
    counts, n_bins, bin_t, t_ref = window
    order, offsets, ev_t, ev_dl = events
    q, g, dcr, phi_floor, linear = response
    out_phi, out_var, out_lref = out
    n_pix = counts.size
    n = float(n_bins)
    max_seg = 1
    for p in range(n_pix):
        k = offsets[p + 1] - offsets[p] + 1
        if k > max_seg:
            max_seg = k
    m = np.empty(max_seg)
    a = np.empty(max_seg)
    lev = np.empty(max_seg)
    for p in range(n_pix):
        s = min(float(counts[p]), n - 1.0)
        r = dcr[p]
        lo_e, hi_e = offsets[p], offsets[p + 1]
        nseg = hi_e - lo_e + 1
        level = 0.0
        lref = 0.0
        prev = 0
        for k in range(lo_e, hi_e):
            e = order[k]
            te = ev_t[e]
            idx = np.searchsorted(bin_t, te)
            m[k - lo_e] = idx - prev
            lev[k - lo_e] = level
            prev = idx
            level += ev_dl[e]
            if te <= t_ref:
                lref = level
        m[nseg - 1] = n_bins - prev
        lev[nseg - 1] = level
        for j in range(nseg):
            a[j] = np.exp(lev[j] - lref)
        phi = _solve_pixel(m, a, nseg, s, n, q, g, r, linear)
        out_phi[p] = phi
        out_var[p] = _fisher_var_log(m, a, nseg, max(phi, phi_floor), q, g, r)
        out_lref[p] = lref


def nedi_deblur(counts: np.ndarray, n_bins: int, bin_t_s: np.ndarray, events: EventBatch | None, t_ref_s: float,
                q_m2: float, gate_s: float, dcr_cps, linear: bool = False):
    """Deblur one SPAD aggregate with events.

    Parameters
    ----------
    counts : ndarray [H, W] int
        Ones per pixel in the aggregate.
    n_bins : int
        Bins aggregated.
    bin_t_s : ndarray [n_bins]
        Sampling instant of each bin (gate centre, s).
    events : EventBatch or None
        Events of the window (levels counted from its start); None means no motion information (NI).
    t_ref_s : float
        Reference instant f (s).
    q_m2, gate_s, dcr_cps
        SPAD response (:class:`SpadResponse`); ``dcr_cps`` scalar or [H, W].
    linear : bool
        Linear EDI on −ln(1 − S/n) instead of the exact response (for comparison).

    Returns
    -------
    flux_ref : ndarray [H, W] float64
        Φ(f), ph s⁻¹ m⁻².
    var_log : ndarray [H, W] float64
        Var(ln Φ̂(f)).
    level_ref : ndarray [H, W] float64
        ℓ(f), the event level at f from the window start.
    """
    shape = counts.shape
    n_pix = counts.size
    dcr = np.broadcast_to(np.asarray(dcr_cps, dtype=np.float64), shape).reshape(-1).copy()
    if events is None:
        events = EventBatch.empty(-np.inf, np.inf)
    order, offsets = group_by_pixel(events.pix, n_pix)
    phi = np.empty(n_pix)
    var = np.empty(n_pix)
    lref = np.empty(n_pix)
    window = AggregateWindow(np.ascontiguousarray(counts, dtype=np.float64).reshape(-1), int(n_bins),
                             np.ascontiguousarray(bin_t_s, dtype=np.float64), float(t_ref_s))
    response = NediResponse(float(q_m2), float(gate_s), dcr, floor_flux(n_bins, q_m2, gate_s), bool(linear))
    nedi_kernel(window, PixelEvents(order, offsets, events.t_s, events.dl), response, NediOutputs(phi, var, lref))
    return phi.reshape(shape), var.reshape(shape), lref.reshape(shape)


LOW_COUNT = 10
"""Below this many ones in an aggregate, ln Φ̂ is far from Gaussian (and undefined at 0): a filter uses
:func:`laplace_update` instead of (ln Φ̂, Var)."""


def laplace_update(counts, n_bins: int, q_m2: float, gate_s: float, dcr_cps, u_pred, P, low_count: int = LOW_COUNT):
    """Equivalent Gaussian measurement of u = ln Φ for low-count pixels, from the exact Bernoulli likelihood.

    With the filter's prior u ~ N(u_pred, P) and S ones in n bins (p = 1 − exp(−(q·e^u + r)·gate)), the posterior
    mode u* is found by Fisher scoring and its information I(u*) = n·λ²e^{−y}/p (λ = q·e^u·gate, y = λ + r·gate).
    The Gaussian measurement (u_eq, var_eq) that moves the prior to that posterior has ``var_eq = 1/I(u*)`` and
    ``u_eq = u* + (u* − u_pred)·var_eq/P``. Unlike ln Φ̂ with a floor, it is defined at S = 0 and its score has
    zero mean at the true flux, so averaging many sparse aggregates does not bias dim pixels upwards (a floored
    log average reported dark regions at 1 lx about 3× too bright).

    Returns ``(mask, u_eq, var_eq)`` for the pixels with ``counts < low_count`` (mask over all pixels).
    """
    counts = np.asarray(counts, dtype=np.float64)
    low = counts < low_count
    if not low.any():
        return low, np.zeros(0), np.zeros(0)
    S = counts[low]
    up = np.asarray(u_pred, dtype=np.float64)[low]
    Pl = np.asarray(P, dtype=np.float64)[low]
    rg = np.broadcast_to(np.asarray(dcr_cps, dtype=np.float64), counts.shape)[low] * gate_s
    n = float(n_bins)
    u = up.copy()
    for _ in range(30):
        lam = q_m2 * gate_s * np.exp(u)
        y = lam + rg
        p = -np.expm1(-y)
        ratio = np.exp(-y) / p
        score = S * lam * ratio - (n - S) * lam
        info = n * lam * lam * ratio
        step = np.clip((score - (u - up) / Pl) / (info + 1.0 / Pl), -2.0, 2.0)
        u += step
        if np.max(np.abs(step)) < 1e-7:
            break
    lam = q_m2 * gate_s * np.exp(u)
    y = lam + rg
    info = n * lam * lam * np.exp(-y) / -np.expm1(-y)
    var_eq = np.minimum(1.0 / np.maximum(info, 1e-12), 1e6)
    u_eq = u + (u - up) * var_eq / Pl
    return low, u_eq, var_eq


def aggregate_bins(rec, aggregate_hz: float | None = None, n_bins: int | None = None) -> int:
    """Bins per aggregate: ``n_bins`` if given, else ``round(1/(aggregate_hz·bin_s))`` (≥ 1)."""
    if n_bins is not None:
        return max(int(n_bins), 1)
    bin_s = float(rec.spad.attrs["bin_s"])
    return max(int(round(1.0 / ((aggregate_hz or DEFAULT_AGGREGATE_HZ) * bin_s))), 1)


def spad_measurements(rec, n_bins: int, *, use_events: bool, until_s: float, tally: BandwidthTally,
                      linear: bool = False) -> Iterator[Measurement]:
    """Aggregates of ``n_bins`` consecutive bins, in order, deblurred by NEDI (or NI without events).

    Window j covers bins [j·n, (j+1)·n) and the time from the first bin's start to the next window's start;
    f is its centre. The last window's interval (and its events) extends to ``until_s``. ``tally`` is charged
    the events read and the covered span; the aggregate readouts are charged by whoever uses them.
    """
    resp = SpadResponse.from_recording(rec)
    t_start = np.asarray(rec.spad.t_start, dtype=np.float64)
    n_total = int(t_start.size)
    n_win = n_total // n_bins
    if n_win == 0:
        raise InputError(f"recording has {n_total} SPAD bins, fewer than one aggregate of {n_bins}",
                         path=rec.path, field="/spad/bits")
    cursor = EventCursor(rec) if use_events else None
    n_pix = int(rec.width) * int(rec.height)
    bits = aggregate_bits(n_bins)
    offset = resp.gate_s / 2.0 if GATE_AT_BIN_START else resp.bin_s / 2.0
    dcr_flat = np.asarray(resp.dcr_cps, dtype=np.float64).reshape(-1)

    def var_model(flux):
        return log_flux_variance(flux, n_bins, resp.q_m2, resp.gate_s, dcr_flat)

    def low_count_update(counts):
        return lambda u_pred, P: laplace_update(counts, n_bins, resp.q_m2, resp.gate_s, dcr_flat, u_pred, P)

    for j in range(n_win):
        k0, k1 = j * n_bins, (j + 1) * n_bins
        a = t_start[k0]
        b_nominal = t_start[k1] if k1 < n_total else t_start[k1 - 1] + resp.bin_s
        b = max(b_nominal, until_s) if j == n_win - 1 else b_nominal
        bin_t = t_start[k0:k1] + offset
        f = 0.5 * (a + b_nominal)
        events = cursor.take(a, b) if cursor is not None else None
        counts = rec.spad.counts(k0, k1)
        phi, var, lref = nedi_deblur(counts, n_bins, bin_t, events, f, resp.q_m2, resp.gate_s, resp.dcr_cps,
                                     linear=linear)
        tally.cover(a, max(b_nominal, min(b, until_s)))
        if events is not None:
            tally.add(len(events) / n_pix, 32.0 * len(events) / n_pix)
        yield Measurement(a, b, f, phi.reshape(-1), floor_flux(n_bins, resp.q_m2, resp.gate_s), var.reshape(-1),
                          lref.reshape(-1), events, float(bits), b_nominal - a, var_model,
                          raw_counts=counts.reshape(-1), raw_bin_t=bin_t,
                          low_count_update=low_count_update(counts.reshape(-1)))


class NEDI(Method):
    """NEDI (S+E): each aggregate deblurred with events, then propagated by events to the output instants.

    Parameters
    ----------
    aggregate_hz : float
        Aggregate readout rate (default 400 Hz, the paper's); or ``n_bins`` directly.
    """

    name = "nedi"
    label = "NEDI (S+E)"
    full_name = "Nonlinear event double integral: SPAD aggregates deblurred by events, without a filter"
    citation = "Muglikar et al., IEEE TPAMI 2025"
    sensors = "S+E"
    requires = ("spad", "events")
    absolute_scale = True
    use_events = True

    def __init__(self, aggregate_hz: float = DEFAULT_AGGREGATE_HZ, n_bins: int | None = None):
        self.aggregate_hz = aggregate_hz
        self.n_bins = n_bins

    def _run(self, rec, times_s, tally):
        n = aggregate_bins(rec, self.aggregate_hz, self.n_bins)
        until = float(times_s[-1]) + 1e-9 if times_s.size else 0.0
        meas = spad_measurements(rec, n, use_events=self.use_events, until_s=until, tally=tally)
        yield from open_loop_frames(meas, times_s, (int(rec.height), int(rec.width)), tally)
