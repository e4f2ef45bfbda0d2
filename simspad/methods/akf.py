"""Asynchronous Kalman filter on log irradiance (Wang, Ng, Scheerlinck, Mahony, ICCV 2021; docs/methods.md).

State per pixel: log irradiance L (ln of ph s⁻¹ m⁻²) and its variance P. Between events the state relaxes to
the frame value L^F exactly (the solution of L̇ = −K(L − L^F), K = P/R, Ṗ = −P²/R over Δt):

    P(t)⁻¹ = P(tᵢ)⁻¹ + R⁻¹·Δt,   L(t) = L^F + (P(t)/P(tᵢ))·(L(tᵢ) − L^F),   then P += σ_p·Δt.

At an event, L += ±c and P += Q_thr + Q_iso + Q_ref with
- Q_thr = threshold_sigma²: the contrast-threshold mismatch (the paper's σ_θ), from the ``/events`` attrs;
- Q_iso = σ_iso·(time since the last event in the 3×3 neighbourhood, the pixel excluded): isolated events
  are likely noise (Wang et al.);
- Q_ref = σ_ref·Δt_pixel when the pixel's previous event is less than ``refractory_window_s`` ago (bursts);
- Q_bw = (c·τ/(τ + Δt_pixel))²: the illumination-dependent term of the reference paper ("noise dependence on
  illumination"). The event pixel's photoreceptor is a low-pass with cutoff f_c = f_max·I/(I + I_ref) in its
  photocurrent I = Φ·qe·fill·pitch² + dark (from the ``/events`` attrs, Φ from the filter state at the latest
  frame), τ = 1/(2πf_c);
  a change crossing the threshold Δt after the previous event is reported short by ≈ τ/(τ + Δt) of a step, so
  dim pixels (slow photoreceptors) make events unreliable and the filter leans on the SPAD frames. Left out when
  the attrs do not describe the photoreceptor.

Frames. A measurement (:class:`simspad.methods.windows.Measurement`: a NEDI-deblurred SPAD aggregate or an
EDI-deblurred conventional frame) gives ln Φ(f) with variance ``var_log`` from the sensor response. While it
is the latest measurement, L^F(t) = ln Φ(f) + ℓ(t) − ℓ(f): the frame advanced by the same events (the
"augmented frame" of Wang et al.), so L^F jumps by ±c with L at each event and the relaxation only removes the
disagreement between frames and integrated events. A measurement standing for a sampling period T is applied as
continuous measurement noise of density ``R = var_log·T``, i.e. it contributes exactly ``1/var_log`` of
information over its period.

The measurement variance is evaluated at the filter's *predicted* irradiance (``Measurement.var_log_predicted``):
weights computed from a measurement's own value favour high photon-count draws and bias the fused estimate up.

Dim pixels: an aggregate with fewer than ``LOW_COUNT`` (10) ones is fed as the equivalent Gaussian measurement of
its exact Bernoulli likelihood around the filter's prediction (:func:`simspad.methods.nedi.laplace_update`), not
as a floored ln Φ̂, which biases dark regions bright (docs/methods.md).

Covariance matching (:func:`inflate_by_innovation`): at each new frame, P is scaled up where the 3×3-pooled
innovations exceed P + R. Events that never fired (a photoreceptor too slow for the motion in dim light) add no Q,
so without this the filter keeps trusting a stale state and compresses contrast (docs/methods.md).

Defaults (Wang et al.'s published code): σ_p = 0.005 s⁻¹, σ_iso = 0.03 s⁻¹, σ_ref = 0.05 s⁻¹, refractory
window 10 ms. The initial state is the first measurement with P = its ``var_log``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Iterable, Iterator, NamedTuple

import numba
import numpy as np
from scipy.ndimage import uniform_filter

from simspad.methods.edi import frame_measurements
from simspad.methods.event_batches import event_thresholds
from simspad.methods.method import Method
from simspad.methods.nedi import aggregate_bins, spad_measurements
from simspad.methods.spad_response import attrs_detection_area_m2
from simspad.methods.windows import Measurement
from simspad.physics.photoreceptor import time_constant_s


@dataclass(frozen=True)
class AkfParams:
    """Filter noise parameters (units: log-irradiance² per s, or per event for ``q_threshold``)."""

    sigma_p: float = 0.005
    sigma_iso: float = 0.03
    sigma_ref: float = 0.05
    refractory_window_s: float = 10e-3
    q_threshold: float = 0.03 ** 2
    innovation_window_px: int = 3
    """Covariance matching at each frame over this square window (0 disables); see :func:`inflate_by_innovation`."""
    max_inflation: float = 1e3
    pr_area_m2: float = 0.0
    """Event pixel ``qe·fill_factor·pixel_pitch_m²``: photo-electrons per (ph m⁻²); 0 disables Q_bw."""
    pr_dark_e_s: float = 0.0
    pr_cutoff_hz_max: float = 0.0
    pr_cutoff_ref_e_s: float = 1.0


class FilterArrays(NamedTuple):
    """The per-pixel state arrays the event kernel updates in place (flattened ``[N]`` float64)."""

    L: np.ndarray
    """Log irradiance ln Φ (Φ in ph s⁻¹ m⁻²)."""
    P: np.ndarray
    """Variance of L."""
    LF: np.ndarray
    """Frame value L^F the state relaxes to."""
    Rinv: np.ndarray
    """Inverse measurement noise density 1/R (s⁻¹ per log-irradiance²)."""
    t_upd: np.ndarray
    """Time of the pixel's last update (s)."""
    t_last_ev: np.ndarray
    """Time of the pixel's last event (s)."""
    tau_pr: np.ndarray
    """Photoreceptor time constant τ (s), used when ``EventUpdateParams.use_bw``."""


class EventArrays(NamedTuple):
    """Time-sorted events: time (s), flat pixel index, signed log step (±c)."""

    t_s: np.ndarray
    pix: np.ndarray
    dl: np.ndarray


class EventUpdateParams(NamedTuple):
    """The event kernel's grid (width, height in pixels) and noise terms (as in :class:`AkfParams`)."""

    width: int
    height: int
    sigma_p: float
    sigma_iso: float
    sigma_ref: float
    refractory_window_s: float
    q_threshold: float
    use_bw: bool
    """Whether Q_bw (the photoreceptor-bandwidth term) is added."""


class AkfState:
    """Per-pixel filter state, flattened ``[N]`` float64 arrays, and the kernels that advance it."""

    def __init__(self, height: int, width: int, t0_s: float):
        n = height * width
        self.height, self.width = height, width
        self.L = np.zeros(n)
        self.P = np.ones(n)
        self.LF = np.zeros(n)
        self.Rinv = np.zeros(n)
        self.t_upd = np.full(n, t0_s)
        self.t_last_ev = np.full(n, t0_s)
        self.tau_pr = np.zeros(n)
        self.n_events = 0

    def update_photoreceptor(self, params: "AkfParams") -> None:
        """Photoreceptor time constant per pixel from the current state (refreshed at each frame: the
        photocurrent changes little within a frame interval, and the per-event loop then needs no exp)."""
        if params.pr_cutoff_hz_max > 0.0:
            cur = np.exp(self.L) * params.pr_area_m2 + params.pr_dark_e_s
            self.tau_pr[:] = time_constant_s(cur, params.pr_cutoff_hz_max, params.pr_cutoff_ref_e_s)

    def events(self, t_s, pix, dl, params: AkfParams) -> None:
        """Apply time-sorted events (numba kernel)."""
        if len(t_s):
            state = FilterArrays(self.L, self.P, self.LF, self.Rinv, self.t_upd, self.t_last_ev, self.tau_pr)
            update = EventUpdateParams(self.width, self.height, params.sigma_p, params.sigma_iso, params.sigma_ref,
                                       params.refractory_window_s, params.q_threshold, params.pr_cutoff_hz_max > 0.0)
            akf_events(state, EventArrays(t_s, pix, dl), update)
            self.n_events += len(t_s)

    def advance(self, t_s: float, sigma_p: float, mask: np.ndarray | None = None) -> None:
        """Relax every pixel (or those in ``mask``) to time ``t_s`` (closed form, vectorised)."""
        sel = slice(None) if mask is None else mask
        dt = t_s - self.t_upd[sel]
        P0 = self.P[sel]
        Pn = 1.0 / (1.0 / P0 + self.Rinv[sel] * dt)
        self.L[sel] = self.LF[sel] + (Pn / P0) * (self.L[sel] - self.LF[sel])
        self.P[sel] = Pn + sigma_p * dt
        self.t_upd[sel] = t_s

    def set_measurement(self, log_flux_now: np.ndarray, rinv: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Install a new frame value L^F (valid now) and its inverse noise density, for all pixels or ``mask``."""
        if mask is None:
            self.LF[:] = log_flux_now
            self.Rinv[:] = rinv
        else:
            self.LF[mask] = log_flux_now[mask]
            self.Rinv[mask] = rinv[mask]

    def image(self) -> np.ndarray:
        return np.exp(self.L).reshape(self.height, self.width).astype(np.float32)


@numba.njit(cache=True, boundscheck=False)
def akf_events(state: FilterArrays, events: EventArrays, params: EventUpdateParams) -> None:
    """Per-event AKF update: relax the pixel to the event time, then apply the event and its noise."""
    L, P, LF, Rinv, t_upd, t_last_ev, tau_pr = state
    ev_t, ev_pix, ev_dl = events
    width, height, sigma_p, sigma_iso, sigma_ref, refr_window, q_thr, use_bw = params
    for e in range(ev_t.size):
        i = ev_pix[e]
        t = ev_t[e]
        dt = t - t_upd[i]
        if dt > 0.0:
            p0 = P[i]
            pn = 1.0 / (1.0 / p0 + Rinv[i] * dt)
            L[i] = LF[i] + (pn / p0) * (L[i] - LF[i])
            P[i] = pn + sigma_p * dt
            t_upd[i] = t
        L[i] += ev_dl[e]
        LF[i] += ev_dl[e]
        y = i // width
        x = i - y * width
        t_nb = -1e300
        for dy in range(-1, 2):
            yy = y + dy
            if yy < 0 or yy >= height:
                continue
            for dx in range(-1, 2):
                xx = x + dx
                if xx < 0 or xx >= width or (dx == 0 and dy == 0):
                    continue
                tn = t_last_ev[yy * width + xx]
                if tn > t_nb:
                    t_nb = tn
        q = q_thr
        if t_nb > -1e300:
            q += sigma_iso * (t - t_nb)
        dtp = t - t_last_ev[i]
        if dtp < refr_window:
            q += sigma_ref * dtp
        if use_bw:
            # photoreceptor bandwidth: an event lags/attenuates the true change by ≈ τ/(τ + Δt) of its step
            frac = tau_pr[i] / (tau_pr[i] + dtp)
            q += (ev_dl[e] * frac) ** 2
        P[i] += q
        t_last_ev[i] = t


def inflate_by_innovation(st: AkfState, lf: np.ndarray, var: np.ndarray, mask, window_px: int,
                          max_inflation: float) -> None:
    """Covariance matching at a new frame: scale P up where the innovations exceed what P + R explains.

    The innovation ν = L^F(a) − L(a) has variance P + var under the filter's model. Events that never fired
    (a photoreceptor too slow for the motion, a change below threshold) leave no trace in Q, so the filter would
    keep trusting a stale state; pooled over a ``window_px`` square (to average out the χ² noise of single
    pixels), ``r = mean ν² / mean(P + var)`` > 1 reveals it and P is multiplied by r (never decreased). This is
    the classic covariance-matching adaptation (Mehra 1972) applied once per frame.
    """
    shape = (st.height, st.width)
    nu2 = (lf - st.L) ** 2
    ratio = uniform_filter(nu2.reshape(shape), window_px, mode="nearest") / uniform_filter(
        (st.P + var).reshape(shape), window_px, mode="nearest")
    ratio = np.clip(ratio.reshape(-1), 1.0, max_inflation)
    if mask is None:
        st.P *= ratio
    else:
        st.P[mask] *= ratio[mask]


def akf_frames(measurements: Iterable[Measurement], times_s: np.ndarray, shape: tuple[int, int],
               params: AkfParams, tally, adaptive=None) -> Iterator[np.ndarray]:
    """Run the filter over a measurement stream and yield exp(L) at each requested instant.

    ``adaptive`` (optional) is an object with ``select(state, m, first) -> (mask [N] bool, measurement)``
    deciding which pixels take a measurement (and possibly re-aggregating it) and ``after(state, m, mask)``; it
    charges the tally itself. Without it every measurement is used and charged in full.
    """
    H, W = shape
    it = iter(measurements)
    m = next(it, None)
    if m is None:
        return
    st = AkfState(H, W, m.a_s)
    lf0 = m.log_flux_at_start()
    st.L[:] = lf0
    st.P[:] = m.var_log
    k = 0
    n_t = times_s.size
    first = True
    while m is not None:
        mask = None
        if adaptive is not None:
            mask, m = adaptive.select(st, m, first)
        elif tally is not None:
            tally.add(1.0, m.readout_bits)
        var = m.var_log if first else m.var_log_predicted(np.exp(st.L + m.level_ref))
        lf = m.log_flux_at_start()
        if m.low_count_update is not None:  # also at the first frame: its prior is then the floor, P = its var
            low, u_eq, var_eq = m.low_count_update(st.L + m.level_ref, st.P)
            if low.any():
                var = var.copy()
                var[low] = var_eq
                lf[low] = u_eq - m.level_ref[low]
        rinv = 1.0 / (var * m.duration_s)
        if not first and params.innovation_window_px > 0:
            inflate_by_innovation(st, lf, var, mask, params.innovation_window_px, params.max_inflation)
        st.set_measurement(lf, rinv, mask)
        st.update_photoreceptor(params)
        if adaptive is not None:
            st.Rinv[~mask] = 0.0  # no new frame there: the state integrates events only
        first = False
        ev = m.events
        used = 0
        while k < n_t and times_s[k] < m.b_s:
            t = max(times_s[k], m.a_s)
            stop = ev.upto(t) if ev is not None else 0
            if stop > used:
                st.events(ev.t_s[used:stop], ev.pix[used:stop], ev.dl[used:stop], params)
                used = stop
            st.advance(t, params.sigma_p)
            yield st.image()
            k += 1
        if k >= n_t:
            return
        if ev is not None and len(ev) > used:
            st.events(ev.t_s[used:], ev.pix[used:], ev.dl[used:], params)
        st.advance(m.b_s, params.sigma_p)
        if adaptive is not None:
            adaptive.after(st, m, mask)
        m = next(it, None)
    # Instants past the data (cannot happen when the source extends its last window to the last instant).
    while k < n_t:
        yield st.image()
        k += 1


def akf_params_for(rec, **overrides) -> AkfParams:
    """Filter parameters with Q_thr from the recording's threshold mismatch (``threshold_sigma``)."""
    _, _, sigma = event_thresholds(rec)
    values = {"q_threshold": sigma ** 2}
    a = rec.events.attrs
    try:
        values.update(pr_area_m2=attrs_detection_area_m2(float(a["pixel_pitch_m"]), float(a.get("fill_factor", 1.0)),
                                                         float(a["qe"])),
                      pr_dark_e_s=float(a.get("dark_current_e_s", 0.0)),
                      pr_cutoff_hz_max=float(a["photoreceptor_cutoff_hz_max"]),
                      pr_cutoff_ref_e_s=float(a["photoreceptor_cutoff_ref_rate_e_s"]))
    except (KeyError, TypeError, ValueError):
        pass  # no photoreceptor description (e.g. a converted real capture): Q_bw is left out
    values.update(overrides)
    return AkfParams(**values)


#: The AKF's parameters as a method takes them (``**akf``): AkfParams' defaults, None where the recording decides
#: (the threshold mismatch and the photoreceptor description, :func:`akf_params_for`).
AKF_METHOD_PARAMETERS: dict[str, object] = {
    f.name: (None if f.name == "q_threshold" or f.name.startswith("pr_") else f.default) for f in fields(AkfParams)}


class NediAkf(Method):
    """NEDI+AKF (S+E): NEDI-deblurred SPAD aggregates fused with events by the AKF (the reference paper)."""

    name = "nedi_akf"
    label = "NEDI+AKF (S+E)"
    full_name = "Nonlinear event double integral of SPAD aggregates, fused with events by an asynchronous Kalman filter"
    citation = "NEDI: Muglikar et al., IEEE TPAMI 2025; AKF: Wang et al., ICCV 2021"
    sensors = "S+E"
    requires = ("spad", "events")
    absolute_scale = True
    forwarded_parameters = AKF_METHOD_PARAMETERS

    def __init__(self, aggregate_hz: float | None = None, n_bins: int | None = None, **akf):
        self.aggregate_hz = aggregate_hz
        self.n_bins = n_bins
        self.akf = akf

    def _measurements(self, rec, times_s, tally):
        n = aggregate_bins(rec, self.aggregate_hz, self.n_bins)
        until = float(times_s[-1]) + 1e-9 if times_s.size else 0.0
        return spad_measurements(rec, n, use_events=True, until_s=until, tally=tally)

    def _run(self, rec, times_s, tally):
        meas = self._measurements(rec, times_s, tally)
        yield from akf_frames(meas, times_s, (int(rec.height), int(rec.width)), akf_params_for(rec, **self.akf),
                              tally)


class AkfFrames(Method):
    """AKF (F+E): EDI-deblurred conventional frames fused with events by the same filter (Wang et al.)."""

    name = "akf_fe"
    label = "AKF (F+E)"
    full_name = "Asynchronous Kalman filter fusing EDI-deblurred conventional frames with events"
    citation = "Wang, Ng, Scheerlinck, Mahony, ICCV 2021"
    sensors = "F+E"
    requires = ("frames", "events")
    absolute_scale = True
    forwarded_parameters = AKF_METHOD_PARAMETERS

    def __init__(self, **akf):
        self.akf = akf

    def _run(self, rec, times_s, tally):
        until = float(times_s[-1]) + 1e-9 if times_s.size else 0.0
        meas = frame_measurements(rec, use_events=True, until_s=until, tally=tally)
        yield from akf_frames(meas, times_s, (int(rec.height), int(rec.width)), akf_params_for(rec, **self.akf),
                              tally)
