"""Event camera (DESIGN §4, preset ``prophesee_gen4``): a per-pixel DVS model with exact crossing times.

Per pixel (flattened index ``y·W + x``):

- **photocurrent** ``I(t) = qe·fill·pitch²·Φ(t) + dark_current`` (e⁻ s⁻¹), linear in time between keyframes;
- **photoreceptor**: first-order low-pass of ``ln I`` with cutoff ``f_c = f_max·I/(I + I_ref)``, so dim pixels
  lag (``τ = 1/(2π f_c)``). It is integrated *exactly* for an input whose log is linear in time over each internal
  step (exponential integrator), so there is no ``τ/4`` stability limit; the step only has to keep ln of the
  timeline's linear-in-time photocurrent close to linear: chord error ``(Δ ln I)²/8 ≤ substep_tolerance ×`` the
  pixel's smaller threshold (which also bounds how much τ(I) varies inside a step). Static pixels and slowly
  changing ones take one step per keyframe interval; cost follows what changes;
- **change detector**: ON when ``D = L_p − ref + leak·(t − t_ref) ≥ θ_on``, OFF when ``D ≤ −θ_off``; at an event
  the reference resets to the current ``L_p``. Inside a step ``D(x) = A + B·x + c·exp(−x/τ)`` exactly, with at
  most one stationary point, so each crossing — several per step included — is solved on its monotone piece
  (closed form once the transient has decayed, Newton otherwise) to 1 ns: nothing snaps to keyframes;
- **thresholds** ``θ ~ N(nominal, threshold_sigma)`` per pixel and polarity, fixed for the recording, clamped to
  ``≥ threshold_min`` (> 0);
- **leak**: the reference drifts down at ``leak_rate·θ_on`` per second (log-normal per-pixel rate, median
  ``leak_rate_hz``): a static pixel emits ON events at that rate. An ON event whose change since the last reset
  owes more to the drift than to the light is labelled leak (2);
- **shot noise** (label 1): a Poisson process of random polarity with rate ``r(I) = r₁·(I₁/I)^γ``, where ``I₁`` is
  the photocurrent of a pixel seeing the scene's mean luminance at 1 lx (plus dark current) and
  ``r₁ = shot_noise_rate_hz_at_1lux``. Graça & Delbruck (2021) explain why DVS noise rises as light falls: the
  photocurrent's relative shot-noise amplitude grows as ``1/sqrt(I)``, and in dim light it is no longer offset by a
  shrinking photoreceptor bandwidth alone. We model the result, not the first-passage process: a power law in the
  photocurrent, ``γ = shot_noise_current_exponent`` (default 0.5, the amplitude's scaling), calibrated at 1 lx.
  The rate saturates in the dark because ``I ≥ I_dark``, and the refractory period caps it. Noise events do not
  move the reference (they are transient excursions), so a static scene yields only noise-labelled events;
- **hot pixels** (label 3): a fraction of pixels fire an extra Poisson process at ``hot_pixel_rate_hz``;
- **readout**: timestamp = detection + ``max(0, latency + jitter·z)``; the pixel is blind from detection until
  ``refractory_s`` after its event is read out, so events of one pixel are ≥ ``refractory_s`` apart; a signal
  crossing that falls in that window fires when the window ends (if the change still exceeds the threshold).

Randomness: one splitmix64 stream per pixel, seeded from the sensor's ``rng``, so the result does not depend on
chunking, on the pixel blocks or on the thread count; jitter draws are normal quantiles of one uniform each
(Acklam's approximation, relative error < 1.2·10⁻⁹). Events stream out in time chunks, sorted by (µs timestamp,
pixel index): the kernel emits them in pixel order (time and a packed pixel/polarity/label code), so one stable
counting sort over µs buckets orders a chunk. It runs in parallel on equal slices of that sequence, one histogram
each, with the bucket rows handed out in (bucket, slice) order: the rows a serial pass gives, whatever the thread
count. The events held back from the previous chunk (read out after its end, so few) are merged into rows left
free in front of the new ones, touching only the new events that sort before the last of them; events read out
after the recording's end are dropped. A pixel block whose buffer slice fills up continues from the pixel that
did not fit in a larger slice, so no finished work is redone.

Cost: an internal step costs one exp and no log (a step cut by the tolerance rule advances ln I by a per-pixel
constant; ln I at keyframes is taken once per pixel and keyframe); a crossing costs about two exp (Halley
iterations); noise processes cost a multiply per step until they fire.

File layout (DESIGN §5): ``/events/t`` int64 µs since the timeline's t = 0 (``time_origin_s = 0``; the same
base as ``/gt/t``), ``x``, ``y`` uint16, ``p`` uint8 (1 ON, 0 OFF), ``label`` uint8, and ``ms_to_idx[k]`` = index
of the first event with ``t ≥ 1000·k`` µs, for k = 0 … ceil(t_end_ms) (= ceil(duration_ms) + 1 entries when the
recording starts at 0).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numba
import numpy as np

from simspad.errors import SimSpadError
from simspad.physics.radiometry import detection_rate
from simspad.sensors.presets import EventParams, params_to_attrs

LABEL_SIGNAL, LABEL_SHOT, LABEL_LEAK, LABEL_HOT = 0, 1, 2, 3
LABEL_NAMES = {LABEL_SIGNAL: "signal", LABEL_SHOT: "shot_noise", LABEL_LEAK: "leak", LABEL_HOT: "hot_pixel"}
_FIELD = "sensors.events"
#: Bytes of keyframe photocurrent held per time chunk (bounds memory whatever the sequence length).
CHUNK_BYTES = 64 << 20
#: Keyframe pieces per time chunk at most (keeps each chunk's event buffers small and cache-friendly).
CHUNK_PIECES = 16
#: Events written per HDF5 chunk.
EVENT_CHUNK_ROWS = 1 << 16
#: Histogram entries (µs buckets × parts) the parallel bucket sort may hold; it uses fewer parts beyond this.
_BUCKET_MAX_ENTRIES = 8 << 20
#: Extra blind time after the refractory period, so µs-floored timestamps keep ≥ refractory_s spacing.
_REFRACTORY_GUARD_S = 1e-9


# ----------------------------------------------------------------------------------------------- pixel maps
@dataclass(frozen=True)
class PixelMaps:
    """Fixed per-pixel properties of one sensor, flattened to ``[H·W]``.

    Attributes
    ----------
    threshold_on, threshold_off : ndarray float64
        Contrast thresholds (log units), ≥ ``threshold_min``.
    leak_rate_hz : ndarray float64
        Leak event rate (reference drift ``leak_rate_hz·threshold_on`` per second).
    hot_rate_hz : ndarray float64
        Extra event rate of hot pixels (0 elsewhere).
    rng_state : ndarray uint64
        Seeds of the per-pixel random streams.
    """

    threshold_on: np.ndarray
    threshold_off: np.ndarray
    leak_rate_hz: np.ndarray
    hot_rate_hz: np.ndarray
    rng_state: np.ndarray


def draw_pixel_maps(params: EventParams, shape: tuple[int, int], rng: np.random.Generator) -> PixelMaps:
    """Draw the fixed pattern (in this order: ON, OFF thresholds, leak rates, hot pixels, stream seeds)."""
    n = int(shape[0]) * int(shape[1])
    theta_on = params.threshold_on + params.threshold_sigma * rng.standard_normal(n)
    theta_off = params.threshold_off + params.threshold_sigma * rng.standard_normal(n)
    leak = params.leak_rate_hz * np.exp(params.leak_rate_log_sigma * rng.standard_normal(n))
    hot = np.where(rng.random(n) < params.hot_pixel_fraction, params.hot_pixel_rate_hz, 0.0)
    seeds = rng.integers(0, np.iinfo(np.uint64).max, size=n, dtype=np.uint64, endpoint=True)
    return PixelMaps(threshold_on=np.maximum(theta_on, params.threshold_min),
                     threshold_off=np.maximum(theta_off, params.threshold_min),
                     leak_rate_hz=leak, hot_rate_hz=hot, rng_state=seeds)


# ----------------------------------------------------------------------------------------------- physics helpers
def photocurrent_e_s(flux_ph_s_m2, params: EventParams) -> np.ndarray:
    """Photo-electron rate plus dark current, e⁻ s⁻¹ (float64)."""
    signal = detection_rate(np.asarray(flux_ph_s_m2, dtype=np.float64), params.pixel_pitch_m, params.fill_factor,
                            params.qe)
    return signal + params.dark_current_e_s


def cutoff_hz(photocurrent: np.ndarray, params: EventParams) -> np.ndarray:
    """Photoreceptor cutoff frequency, Hz: ``f_max·I/(I + I_ref)``."""
    current = np.asarray(photocurrent, dtype=np.float64)
    return params.photoreceptor_cutoff_hz_max * current / (current + params.photoreceptor_cutoff_ref_rate_e_s)


def reference_current_1lux(mean_flux_ph_s_m2: float, lux: float, params: EventParams) -> float:
    """``I₁``: photocurrent of a pixel at the scene's mean luminance scaled to 1 lx, plus dark current (e⁻ s⁻¹)."""
    signal = float(detection_rate(mean_flux_ph_s_m2, params.pixel_pitch_m, params.fill_factor, params.qe))
    per_lux = signal / lux if lux and lux > 0 else 0.0
    return per_lux + params.dark_current_e_s


def shot_noise_rate_hz(photocurrent, current_1lux: float, params: EventParams) -> np.ndarray:
    """Shot-noise event rate, Hz: ``r₁·(I₁/I)^γ``."""
    current = np.maximum(np.asarray(photocurrent, dtype=np.float64), _MIN_CURRENT)
    return params.shot_noise_rate_hz_at_1lux * (current_1lux / current) ** params.shot_noise_current_exponent


_MIN_CURRENT = 1e-6  # e⁻/s: keeps ln I finite if a user sets the dark current to 0
_MIN_STEP_S = 1e-10  # s: the internal step never shrinks below this (guards against round-off stalls)
_ROOT_TOL_S = 1e-9  # s: crossing instants are solved to this (timestamps are whole µs) ...
_ROOT_TOL_LOG = 1e-9  # ... or until the detector is this close to the threshold (log units)


def validate_params(params: EventParams) -> None:
    """Raise :class:`SimSpadError` naming the field for values the model cannot use."""
    checks = [
        ("threshold_on", params.threshold_on > 0, "must be > 0"),
        ("threshold_off", params.threshold_off > 0, "must be > 0"),
        ("threshold_min", params.threshold_min > 0, "must be > 0 (thresholds may never reach 0)"),
        ("qe", 0 < params.qe <= 1, "must be in (0, 1]"),
        ("fill_factor", 0 < params.fill_factor <= 1, "must be in (0, 1]"),
        ("pixel_pitch_m", params.pixel_pitch_m > 0, "must be > 0"),
        ("photoreceptor_cutoff_hz_max", params.photoreceptor_cutoff_hz_max > 0, "must be > 0"),
        ("hot_pixel_fraction", params.hot_pixel_fraction <= 1, "must be in [0, 1]"),
        ("substep_tolerance", 0 < params.substep_tolerance <= 0.1, "must be in (0, 0.1]"),
    ]
    for name, ok, message in checks:
        if not ok:
            raise SimSpadError(f"{message}, got {getattr(params, name)!r}", field=f"{_FIELD}.{name}")


# ----------------------------------------------------------------------------------------------- numba kernel
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always")
def _next_u64(state):
    state = state + _GOLDEN
    z = state
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return state, z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def _uniform(state):
    """(new state, u) with u uniform in (0, 1]."""
    state, z = _next_u64(state)
    return state, ((z >> np.uint64(11)) + np.uint64(1)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, inline="always")
def _exponential(state):
    state, u = _uniform(state)
    return state, -math.log(u)


# Acklam's rational approximation of the normal quantile (relative error < 1.2e-9): one uniform per draw and no
# transcendental call in the central 95 %, where Box-Muller needs a log, a sqrt and a cos for every jitter draw.
_ACK_A = (-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02, 1.383577518672690e+02,
          -3.066479806614716e+01, 2.506628277459239e+00)
_ACK_B = (-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02, 6.680131188771972e+01,
          -1.328068155288572e+01)
_ACK_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00, -2.549732539343734e+00,
          4.374664141464968e+00, 2.938163982698783e+00)
_ACK_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00)
_ACK_LOW = 0.02425


@numba.njit(cache=True, inline="always")
def _normal_quantile(u):
    """Standard normal quantile of u in (0, 1) (Acklam)."""
    a, b, c, d = _ACK_A, _ACK_B, _ACK_C, _ACK_D
    if u < _ACK_LOW or u > 1.0 - _ACK_LOW:
        q = math.sqrt(-2.0 * math.log(min(u, 1.0 - u)))
        z = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
        return z if u < _ACK_LOW else -z
    q = u - 0.5
    r = q * q
    return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q / \
        (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)


@numba.njit(cache=True, inline="always")
def _normal(state):
    """(new state, z) with z standard normal, from one uniform in the open interval (0, 1)."""
    state, z = _next_u64(state)
    return state, _normal_quantile(((z >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0))


@numba.njit(cache=True, error_model="numpy")
def _solve_monotone(a_off, b_slope, c, tau, lo, hi, f_lo, f_hi, level, tr_lo):
    """Root of D(x) = level on [lo, hi] where D = a_off + b_slope·x + c·exp(−x/τ) is monotone.

    ``f_lo``, ``f_hi`` are D − level at the ends (opposite signs, or zero); ``tr_lo`` = c·exp(−lo/τ), the
    photoreceptor transient at ``lo`` (the caller has it already). Once the transient has decayed below the
    tolerance D is linear and the root is closed-form; otherwise Halley steps from the secant point, kept inside
    the shrinking bracket (bisection when a step leaves it). One exp gives D, D' and D'' (cubic convergence);
    a step is taken without a further evaluation when it, or its predicted error K·step³ (×10 margin), is
    below the tolerance.
    """
    if f_lo == 0.0:
        return lo
    if f_hi == 0.0:
        return hi
    if abs(tr_lo) <= _ROOT_TOL_LOG:
        return min(max(lo - f_lo / b_slope, lo), hi)
    inv_tau = 1.0 / tau
    x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
    for _ in range(100):
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        e = c * math.exp(-x * inv_tau)
        f_x = a_off + b_slope * x + e - level
        if abs(f_x) <= _ROOT_TOL_LOG or hi - lo < _ROOT_TOL_S:
            return x
        if (f_x > 0.0) == (f_lo > 0.0):
            lo, f_lo = x, f_x
        else:
            hi = x
        d1 = b_slope - e * inv_tau
        if d1 == 0.0:
            x = 0.5 * (lo + hi)
            continue
        d2 = e * inv_tau * inv_tau
        if abs(f_x * d2) <= d1 * d1:  # near the root: Halley, error after the step ≈ K·step³
            step = 2.0 * f_x * d1 / (2.0 * d1 * d1 - f_x * d2)
            r2 = d2 / d1  # K = (D2/D1)²/4 − D3/(6·D1), and D3 = −D2/τ here
            err = (0.25 * r2 * r2 + abs(r2 * inv_tau) / 6.0) * abs(step) ** 3
        else:  # far out on the flat tail Halley creeps by ~2τ a step; Newton overshoots into a bisection
            step = f_x / d1
            err = np.inf
        x = x - step
        if (abs(step) <= _ROOT_TOL_S or 10.0 * err <= _ROOT_TOL_S) and lo <= x <= hi:
            return x
    return x


@numba.njit(cache=True, error_model="numpy")
def _first_crossing(a_off, b_slope, c, tau, x0, h, d0, dh, theta_on, theta_off, tr0, trh):
    """First x in (x0, h] where D(x) = a_off + b_slope·x + c·exp(−x/τ) reaches θ_on or −θ_off.

    D has at most one stationary point (D' = b_slope − (c/τ)·exp(−x/τ) is monotone), so [x0, h] splits into at
    most two monotone pieces; the first piece whose far end is beyond a threshold holds the crossing.
    ``tr0``, ``trh`` are the transient c·exp(−x/τ) at x0 and h: D' has a root inside only if its end values
    differ in sign, so the log that locates it is taken only then.
    Returns ``(x, polarity)`` or ``(-1, 0)``; requires −θ_off < D(x0) < θ_on.
    """
    xs = -1.0
    if c != 0.0 and b_slope != 0.0 and (b_slope - tr0 / tau > 0.0) != (b_slope - trh / tau > 0.0):
        r = b_slope * tau / c
        if r > 0.0:
            x_stat = -tau * math.log(r)
            if x0 < x_stat < h:
                xs = x_stat
    lo, f_lo, tr_lo = x0, d0, tr0
    for piece in range(2):
        if piece == 0 and xs > 0.0:
            hi = xs
            f_hi = a_off + b_slope * xs + b_slope * tau  # c·exp(−xs/τ) = b_slope·τ there
        elif piece == 0:
            hi, f_hi = h, dh
        elif xs > 0.0:
            hi, f_hi = h, dh
        else:
            break
        if f_hi >= theta_on:
            return _solve_monotone(a_off, b_slope, c, tau, lo, hi, f_lo - theta_on, f_hi - theta_on,
                                   theta_on, tr_lo), 1
        if f_hi <= -theta_off:
            return _solve_monotone(a_off, b_slope, c, tau, lo, hi, f_lo + theta_off, f_hi + theta_off,
                                   -theta_off, tr_lo), 0
        lo, f_lo, tr_lo = hi, f_hi, b_slope * tau
    return -1.0, 0


# An event's pixel, polarity and label travel packed in one int64 (``pixel·8 + polarity·4 + label``) from the
# kernel through the bucket sort: two scattered stores per event instead of four.
@numba.njit(cache=True, inline="always")
def _pack(pixel, polarity, label):
    return (np.int64(pixel) << 3) | (np.int64(polarity) << 2) | np.int64(label)


@numba.njit(cache=True, parallel=True)
def _unpack(t_s, pix, lo):
    """Unpack rows ``lo …`` of events given as time (s) and packed code, in parallel; ``pix`` holds the codes on
    entry and the pixel indices on return (no separate code array to allocate and fault in).

    Returns
    -------
    t_us, pol, lab : ndarray
        µs timestamps (floor of t·10⁶, as :func:`timestamps_us`), polarity and label. Rows before ``lo`` are left
        uninitialised: they are the room :meth:`EventSimulator.advance` merges the held-back events into.
    """
    n = pix.size
    t_us = np.empty(n, np.int64)
    pol = np.empty(n, np.uint8)
    lab = np.empty(n, np.uint8)
    for j in numba.prange(n - lo):
        k = lo + j
        t_us[k] = np.int64(math.floor(t_s[k] * 1e6))
        c = pix[k]
        pix[k] = c >> 3
        pol[k] = np.uint8((c >> 2) & 1)
        lab[k] = np.uint8(c & 3)
    return t_us, pol, lab


@numba.njit(cache=True)
def _init_state(current0, rng_state, lp, ref, t_ref, t_avail, hz_shot, hz_hot, t0):
    for p in range(current0.size):
        lp[p] = math.log(max(current0[p], _MIN_CURRENT))
        ref[p] = lp[p]
        t_ref[p] = t0
        t_avail[p] = -np.inf
        s = rng_state[p]
        s, hz_shot[p] = _exponential(s)
        s, hz_hot[p] = _exponential(s)
        rng_state[p] = s


@numba.njit(cache=True, error_model="numpy")
def _run_pixels(p0, p1, knot_t, knot_current, th_on, th_off, leak_hz, hot_hz, shot_coef, shot_exp,
                f_max, i_ref, step_tol, latency, jitter, refractory,
                lp_state, ref_state, tref_state, tavail_state, hzs_state, hzh_state, rng_state,
                buf_t, buf_code, start, limit):
    """Advance pixels ``p0 … p1−1`` over the keyframe pieces of one chunk, writing their events (unsorted) into
    the buffers from index ``start``. Returns ``(end, p_next)``: the index after the last event written and the
    first pixel not done (``p1`` when all are). When ``limit`` is reached inside pixel p, p's events are dropped
    and its state is left untouched (it is stored only once the pixel is done): ``(index of p's first event, p)``,
    so the caller can continue from p elsewhere and get exactly what one uninterrupted run gives.

    ``knot_current[p, j]`` is pixel p's photocurrent at ``knot_t[j]`` (pixel-major, so each pixel's knots are
    contiguous in memory); between knots it is linear in time. The state arrays are updated in place.
    """
    n_knots = knot_t.size
    n_ev = start
    inv_two_pi_fmax = 1.0 / (_TWO_PI * f_max)
    two_pi_fmax = _TWO_PI * f_max
    for p in range(p0, p1):
        n_first = n_ev
        theta_on = th_on[p]
        theta_off = th_off[p]
        rho = leak_hz[p] * theta_on
        r_hot = hot_hz[p]
        tol = step_tol * min(theta_on, theta_off)
        max_dlog = min(math.sqrt(8.0 * tol), 0.5)
        # a step cut by the rule ends at I·(1 ± max_dlog) exactly, so its ln I advances by a per-pixel constant
        dlog_up = math.log1p(max_dlog)
        dlog_down = math.log1p(-max_dlog)
        # ... and the shot-noise factor I^(−γ/2) by a per-pixel constant factor
        g_up = math.exp(-0.5 * shot_exp * dlog_up)
        g_down = math.exp(-0.5 * shot_exp * dlog_down)
        lp = lp_state[p]
        ref = ref_state[p]
        t_ref = tref_state[p]
        t_avail = tavail_state[p]
        hz_shot = hzs_state[p]
        hz_hot = hzh_state[p]
        rs = rng_state[p]
        ib = max(knot_current[p, 0], _MIN_CURRENT)
        l_b = math.log(ib)  # ln I at the next knot: one log per pixel and knot, none per internal step
        g_b = math.exp(-0.5 * shot_exp * l_b)  # I^(−γ/2): the shot-noise rate of a step is r₁I₁^γ·g(start)·g(end)
        for j in range(n_knots - 1):
            ta = knot_t[j]
            tb = knot_t[j + 1]
            seg = tb - ta
            ia = ib
            l_a = l_b
            g_a = g_b
            ib = max(knot_current[p, j + 1], _MIN_CURRENT)
            if ib != ia:
                l_b = math.log(ib)
                g_b = math.exp(-0.5 * shot_exp * l_b)
            if seg <= 0.0:
                continue
            slope = (ib - ia) / seg
            inv_abs_slope = 1.0 / abs(slope) if slope != 0.0 else 0.0
            t = ta
            i_t = ia
            l_t = l_a
            g_t = g_a
            while t < tb:
                # internal step: inside a step ln I is taken as linear in time; the chord error of ln of the
                # linear input, (Δ ln I)²/8, must stay within tol (this also bounds how much τ(I) varies)
                h = tb - t
                by_rule = False
                if slope != 0.0:
                    h_rule = max_dlog * i_t * inv_abs_slope
                    if h_rule < h:
                        h = h_rule
                        by_rule = True
                if h < _MIN_STEP_S:
                    h = _MIN_STEP_S
                    by_rule = False
                s_b = t + h
                if s_b >= tb or tb - s_b < 1e-12 * seg:
                    s_b = tb
                    i_e = ib
                    l_e = l_b
                    g_e = g_b
                else:
                    i_e = ia + slope * (s_b - ta)
                    if by_rule and slope > 0.0:
                        l_e = l_t + dlog_up
                        g_e = g_t * g_up
                    elif by_rule:
                        l_e = l_t + dlog_down
                        g_e = g_t * g_down
                    else:
                        l_e = math.log(i_e)
                        g_e = math.exp(-0.5 * shot_exp * l_e)
                h = s_b - t
                i_mid = 0.5 * (i_t + i_e)
                # τ = (I + I_ref)/(2π f_max I) and 1/τ from one division
                q = 1.0 / (i_mid * (i_mid + i_ref))
                tau = (i_mid + i_ref) * (i_mid + i_ref) * q * inv_two_pi_fmax
                inv_tau = i_mid * i_mid * q * two_pi_fmax
                k = (l_e - l_t) / h
                decay = math.exp(-h * inv_tau)
                lp_e = l_e - k * tau + (lp - l_t + k * tau) * decay
                r_shot = shot_coef * g_t * g_e  # rate at the step's geometric-mean photocurrent
                # ---- events inside [t, s_b]. Exact path, x = s − t:  lp(x) = l_t + k·x − k·τ + c·exp(−x/τ);
                # detector D(x) = lp(x) − ref + ρ·(s − t_ref) = A + B·x + c·exp(−x/τ)
                c = lp - l_t + k * tau
                b_slope = k + rho
                cur = t
                while True:
                    if cur < t_avail:
                        s_end = min(t_avail, s_b)
                        dt = s_end - cur
                        hz_shot -= r_shot * dt
                        while hz_shot <= 0.0:
                            rs, e = _exponential(rs)
                            hz_shot += e
                        hz_hot -= r_hot * dt
                        while hz_hot <= 0.0:
                            rs, e = _exponential(rs)
                            hz_hot += e
                        cur = s_end
                        if cur >= s_b:
                            break
                    x0 = cur - t
                    a_off = l_t - k * tau - ref + rho * (t - t_ref)
                    tr0 = c if x0 == 0.0 else c * math.exp(-x0 * inv_tau)
                    trh = c * decay
                    d_cur = a_off + b_slope * x0 + tr0
                    d_end = a_off + b_slope * h + trh
                    t_sig = np.inf
                    d_sig = d_cur  # detector value at the signal event: lp there = ref + d_sig − ρ·(t − t_ref)
                    pol = 0
                    if d_cur >= theta_on:
                        t_sig = cur
                        pol = 1
                    elif d_cur <= -theta_off:
                        t_sig = cur
                    else:
                        # cheap bounds of D on [x0, h] (convex if c > 0, concave if c < 0) before any search
                        lin_hi = a_off + b_slope * max(x0, h) if b_slope > 0 else a_off + b_slope * x0
                        lin_lo = a_off + b_slope * x0 if b_slope > 0 else a_off + b_slope * h
                        if c >= 0.0:
                            upper = max(d_cur, d_end)
                            lower = lin_lo + c * decay
                        else:
                            upper = lin_hi + c * decay
                            lower = min(d_cur, d_end)
                        if upper >= theta_on or lower <= -theta_off:
                            x_sig, pol = _first_crossing(a_off, b_slope, c, tau, x0, h, d_cur, d_end,
                                                         theta_on, theta_off, tr0, trh)
                            if x_sig >= 0.0:
                                t_sig = t + x_sig
                                d_sig = theta_on if pol == 1 else -theta_off
                    kind = 0  # which process fires first: 0 signal, 1 shot noise, 3 hot pixel
                    t_next = t_sig
                    # a noise process fires in this step only if its remaining hazard runs out before the
                    # step's end or the signal event (a multiply, so the division is only paid when it does)
                    if r_shot * (min(t_next, s_b) - cur) >= hz_shot:
                        t_shot = cur + hz_shot / r_shot
                        if t_shot < t_next:
                            kind = 1
                            t_next = t_shot
                    if r_hot * (min(t_next, s_b) - cur) >= hz_hot:
                        t_hot = cur + hz_hot / r_hot
                        if t_hot < t_next:
                            kind = 3
                            t_next = t_hot
                    if t_next > s_b:
                        dt = s_b - cur
                        hz_shot -= r_shot * dt
                        hz_hot -= r_hot * dt
                        break
                    t_next = max(t_next, cur)
                    dt = t_next - cur
                    hz_shot -= r_shot * dt
                    hz_hot -= r_hot * dt
                    cur = t_next
                    if kind == 0:
                        lp_now = ref + d_sig - rho * (cur - t_ref)
                        label = 0
                        if pol == 1 and rho * (cur - t_ref) > lp_now - ref:
                            label = 2
                        ref = lp_now
                        t_ref = cur
                    elif kind == 1:
                        rs, e = _exponential(rs)
                        hz_shot = e
                        rs, u = _uniform(rs)
                        pol = 1 if u <= 0.5 else 0
                        label = 1
                    else:
                        rs, e = _exponential(rs)
                        hz_hot = e
                        rs, u = _uniform(rs)
                        pol = 1 if u <= 0.5 else 0
                        label = 3
                    delay = latency
                    if jitter > 0.0:
                        rs, z = _normal(rs)
                        delay += jitter * z
                    t_out = cur + max(delay, 0.0)
                    t_avail = t_out + refractory
                    if n_ev == limit:
                        return n_first, p
                    buf_t[n_ev] = t_out
                    buf_code[n_ev] = _pack(p, pol, label)
                    n_ev += 1
                lp = lp_e
                t = s_b
                i_t = i_e
                l_t = l_e
                g_t = g_e
        lp_state[p] = lp
        ref_state[p] = ref
        tref_state[p] = t_ref
        tavail_state[p] = t_avail
        hzs_state[p] = hz_shot
        hzh_state[p] = hz_hot
        rng_state[p] = rs
    return n_ev, p1


@numba.njit(cache=True, parallel=True)
def _simulate_blocks(pix_lo, pix_hi, starts, limits, knot_t, knot_current, th_on, th_off, leak_hz, hot_hz,
                     shot_coef, shot_exp, f_max, i_ref, step_tol, latency, jitter, refractory,
                     lp_state, ref_state, tref_state, tavail_state, hzs_state, hzh_state, rng_state,
                     buf_t, buf_code):
    """Run pixel blocks in parallel: block i advances pixels ``pix_lo[i] … pix_hi[i]−1`` and writes its events
    into the buffers' slice ``[starts[i], limits[i])``.

    Returns each block's end index and first pixel not done (``pix_hi[i]`` unless the slice filled up).
    """
    n_blocks = pix_lo.size
    ends = np.empty(n_blocks, np.int64)
    p_next = np.empty(n_blocks, np.int64)
    for b in numba.prange(n_blocks):
        ends[b], p_next[b] = _run_pixels(pix_lo[b], pix_hi[b], knot_t, knot_current, th_on, th_off, leak_hz,
                                         hot_hz, shot_coef, shot_exp, f_max, i_ref, step_tol, latency, jitter,
                                         refractory, lp_state, ref_state, tref_state, tavail_state, hzs_state,
                                         hzh_state, rng_state, buf_t, buf_code, starts[b], limits[b])
    return ends, p_next


# Post-processing runs on "parts": the blocks' events read in block (= pixel) order form one virtual sequence
# (row v of the sequence lies in segment s with offsets[s] ≤ v < offsets[s+1]), cut into n_parts equal slices,
# one per thread (fewer if their histograms would be large). The slices balance the work whatever the blocks'
# sizes, and the result does not depend on how the sequence is cut, so it does not depend on the thread count.
@numba.njit(cache=True)
def _offsets(starts, ends):
    """Exclusive prefix sum of the segments' event counts (``n_seg + 1`` entries, the last = all events)."""
    offsets = np.empty(starts.size + 1, np.int64)
    offsets[0] = 0
    for s in range(starts.size):
        offsets[s + 1] = offsets[s] + ends[s] - starts[s]
    return offsets


@numba.njit(cache=True, inline="always")
def _part(offsets, n_parts, p):
    """Virtual rows ``[v0, v1)`` of part ``p`` and the segment to start reading at (the last one whose first
    row is ≤ ``v0``; segments are read on while they start before ``v1``)."""
    n = offsets[-1]
    v0 = n * p // n_parts
    v1 = n * (p + 1) // n_parts
    return v0, v1, np.searchsorted(offsets, v0, side="right") - 1


@numba.njit(cache=True)
def _part_range(starts, offsets, buf_t, v0, v1, s):
    """(smallest, largest) µs timestamp of virtual rows ``[v0, v1)``, ``s`` as from :func:`_part`."""
    lo = np.iinfo(np.int64).max
    hi = np.iinfo(np.int64).min
    while s < starts.size and offsets[s] < v1:
        base = starts[s] - offsets[s]
        for v in range(max(v0, offsets[s]), min(v1, offsets[s + 1])):
            u = np.int64(math.floor(buf_t[base + v] * 1e6))
            lo = min(lo, u)
            hi = max(hi, u)
        s += 1
    return lo, hi


@numba.njit(cache=True, parallel=True)
def _us_range(starts, ends, buf_t, n_parts):
    """(smallest, largest) µs timestamp of the blocks' events (floor of t·10⁶, as :func:`timestamps_us`)."""
    offsets = _offsets(starts, ends)
    lo = np.empty(n_parts, np.int64)
    hi = np.empty(n_parts, np.int64)
    for p in numba.prange(n_parts):
        v0, v1, s = _part(offsets, n_parts, p)
        lo[p], hi[p] = _part_range(starts, offsets, buf_t, v0, v1, s)
    return lo.min(), hi.max()


@numba.njit(cache=True)
def _part_histogram(starts, offsets, buf_t, v0, v1, s, t_lo, count):
    """Add the events of virtual rows ``[v0, v1)`` to ``count`` (one entry per µs from ``t_lo``)."""
    while s < starts.size and offsets[s] < v1:
        base = starts[s] - offsets[s]
        for v in range(max(v0, offsets[s]), min(v1, offsets[s + 1])):
            count[np.int64(math.floor(buf_t[base + v] * 1e6)) - t_lo] += 1
        s += 1


@numba.njit(cache=True)
def _part_scatter(starts, offsets, buf_t, buf_code, v0, v1, s, t_lo, next_row, t_out, code_out):
    """Move the events of virtual rows ``[v0, v1)`` to their sorted rows; ``next_row[u]`` is the next free row
    of µs bucket ``u`` reserved for this part (advanced as rows are taken)."""
    while s < starts.size and offsets[s] < v1:
        base = starts[s] - offsets[s]
        for v in range(max(v0, offsets[s]), min(v1, offsets[s + 1])):
            i = base + v
            u = np.int64(math.floor(buf_t[i] * 1e6)) - t_lo
            k = next_row[u]
            next_row[u] = k + 1
            t_out[k] = buf_t[i]
            code_out[k] = buf_code[i]
        s += 1


@numba.njit(cache=True, parallel=True)
def _bucket_blocks(starts, ends, buf_t, buf_code, t_lo, span, n_parts, lead):
    """The blocks' events sorted by (µs timestamp, pixel) with one stable counting sort over µs buckets.

    Blocks cover increasing pixel ranges and each pixel's events are in time order, so reading the blocks in
    order already gives pixel order inside every µs bucket: a stable sort by µs alone suffices. It runs in
    parallel over ``n_parts`` parts of that sequence (one histogram of ``span`` buckets each): the bucket rows are
    handed out in (bucket, part) order, so each part fills its share of a bucket after the earlier parts and in
    its own order, the same rows a serial pass gives. Only the time and the packed code are scattered; the other
    columns are unpacked afterwards in one parallel pass over the sorted rows.

    Returns
    -------
    t_s, t_us, pixel, polarity, label : ndarray
        ``lead`` + number of events rows; the sorted events fill rows ``lead …``, the first ``lead`` rows are
        left uninitialised (room for the held-back events, see :meth:`EventSimulator.advance`).
    """
    offsets = _offsets(starts, ends)
    n = offsets[-1]
    count = np.zeros((n_parts, span), np.int64)
    for p in numba.prange(n_parts):
        v0, v1, s = _part(offsets, n_parts, p)
        _part_histogram(starts, offsets, buf_t, v0, v1, s, t_lo, count[p])
    k = lead
    for u in range(span):  # exclusive prefix sum in (bucket, part) order: each part's first row per bucket
        for p in range(n_parts):
            c = count[p, u]
            count[p, u] = k
            k += c
    t_s = np.empty(lead + n, np.float64)
    pix = np.empty(lead + n, np.int64)  # packed codes until unpacked in place
    for p in numba.prange(n_parts):
        v0, v1, s = _part(offsets, n_parts, p)
        _part_scatter(starts, offsets, buf_t, buf_code, v0, v1, s, t_lo, count[p], t_s, pix)
    t_us, pol, lab = _unpack(t_s, pix, lead)
    return t_s, t_us, pix, pol, lab


@numba.njit(cache=True)
def _merge_front(a_t, a_us, a_pix, a_pol, a_lab, t_s, t_us, pix, pol, lab):
    """Merge the events ``a`` into the front of ``t_s …``, in place; both sorted by (µs, pixel), on a full tie
    ``a`` (the earlier chunk) comes first.

    The first ``a_t.size`` rows of ``t_s …`` are free, the rest hold the new events. Rows are written from the
    front and the write row never passes the next unread new event, so no copy is needed; once ``a`` is used up
    the remaining new events are already in place. Cost: ``a`` plus the new events that sort before its last.
    """
    na = a_t.size
    n = t_s.size
    i = 0
    j = na
    k = 0
    while i < na:
        if j < n and (t_us[j] < a_us[i] or (t_us[j] == a_us[i] and pix[j] < a_pix[i])):
            t_s[k], t_us[k], pix[k], pol[k], lab[k] = t_s[j], t_us[j], pix[j], pol[j], lab[j]
            j += 1
        else:
            t_s[k], t_us[k], pix[k], pol[k], lab[k] = a_t[i], a_us[i], a_pix[i], a_pol[i], a_lab[i]
            i += 1
        k += 1


@numba.njit(cache=True)
def _gather(starts, ends, buf_t, buf_code):
    """Concatenate the blocks' events in block (= pixel) order: ``(t_s, t_us, pixel, polarity, label)``."""
    n = 0
    for b in range(starts.size):
        n += ends[b] - starts[b]
    t = np.empty(n, np.float64)
    pix = np.empty(n, np.int64)
    k = 0
    for b in range(starts.size):
        for i in range(starts[b], ends[b]):
            t[k] = buf_t[i]
            pix[k] = buf_code[i]
            k += 1
    t_us, pol, lab = _unpack(t, pix, 0)
    return t, t_us, pix, pol, lab


def sort_events(t_us: np.ndarray, pixel: np.ndarray, n_pix: int) -> np.ndarray:
    """Permutation that orders events by (µs timestamp, pixel index): the file's canonical order."""
    return np.lexsort((np.asarray(pixel), np.asarray(t_us)))


def timestamps_us(t_s: np.ndarray) -> np.ndarray:
    """Integer µs timestamps (floor: the µs during which the event was read out)."""
    return np.floor(np.asarray(t_s) * 1e6).astype(np.int64)


# ----------------------------------------------------------------------------------------------- simulator
class EventSimulator:
    """Streaming event generation: feed photocurrent knots chunk by chunk, get time-sorted event batches.

    Parameters
    ----------
    params : EventParams
    shape : (H, W)
    current0 : ndarray [H·W]
        Photocurrent at ``t0`` (e⁻ s⁻¹); the photoreceptor starts settled there, the reference equal to it.
    t0 : float
        Start instant, s.
    current_1lux : float
        ``I₁`` of :func:`reference_current_1lux` (shot-noise normalisation).
    maps : PixelMaps
    """

    def __init__(self, params: EventParams, shape, current0, t0: float, current_1lux: float, maps: PixelMaps):
        validate_params(params)
        self.params = params
        self.shape = (int(shape[0]), int(shape[1]))
        n = self.shape[0] * self.shape[1]
        self.maps = maps
        self.shot_coef = params.shot_noise_rate_hz_at_1lux * current_1lux ** params.shot_noise_current_exponent
        self.lp = np.empty(n)
        self.ref = np.empty(n)
        self.t_ref = np.empty(n)
        self.t_avail = np.empty(n)
        self.hz_shot = np.empty(n)
        self.hz_hot = np.empty(n)
        self.rng_state = maps.rng_state.copy()
        _init_state(np.ascontiguousarray(current0, dtype=np.float64).ravel(), self.rng_state, self.lp, self.ref,
                    self.t_ref, self.t_avail, self.hz_shot, self.hz_hot, float(t0))
        self._pending = (np.empty(0), np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0, np.uint8),
                         np.empty(0, np.uint8))
        self._cap = max(1 << 16, 4 * n)  # events expected per chunk (adapts; an overflowing block is rerun)
        self._buf = (np.empty(0), np.empty(0, np.int64))  # event time (s), packed pixel/polarity/label

    def advance(self, knot_t: np.ndarray, knot_current: np.ndarray):
        """Run the pieces between ``knot_t`` (m+1 instants) on photocurrents ``[m+1, H·W]``.

        Returns
        -------
        t_s, t_us, pixel, polarity, label : ndarray
            Events whose µs timestamp lies before the µs holding ``knot_t[-1]``, sorted by (t_us, pixel);
            later ones are held back and merged with the next chunk, so the order does not depend on chunking.
        """
        pending = self._pending
        merged = self._run_chunk(np.ascontiguousarray(knot_t, dtype=np.float64),
                                 np.ascontiguousarray(np.asarray(knot_current, np.float64).T), pending[0].size)
        # The held-back events are few (read out after the previous chunk's end): they are merged into the rows
        # left free in front of the new ones, touching only the new events that sort before the last of them.
        _merge_front(*pending, *merged)
        cut = int(np.searchsorted(merged[1], timestamps_us(knot_t[-1]), side="left"))
        self._pending = tuple(a[cut:].copy() for a in merged)
        return tuple(a[:cut] for a in merged)

    def _buffers(self, size: int):
        """Event buffers of at least ``size`` rows, kept between chunks (no fresh pages to fault in each time)."""
        if self._buf[0].size < size:
            self._buf = (np.empty(size, np.float64), np.empty(size, np.int64))
        return self._buf

    def _run_chunk(self, knot_t, knot_current, lead: int = 0):
        """All pixels over one chunk, in parallel pixel blocks, sorted by (µs, pixel), after ``lead`` rows left
        uninitialised (room for :func:`_merge_front`).

        A block that fills its buffer slice stops at the pixel that did not fit (that pixel's state untouched);
        the rest of the block continues in a fresh, larger slice (per-pixel random streams make the result the
        same as one uninterrupted run), so no finished work is redone.
        """
        p = self.params
        m = self.maps
        n_pix = knot_current.shape[0]
        n_blocks = max(1, min(n_pix, 16 * numba.get_num_threads(), -(-n_pix // 256)))
        bounds = np.arange(n_blocks + 1, dtype=np.int64) * n_pix // n_blocks
        pix_lo, pix_hi = bounds[:-1].copy(), bounds[1:].copy()
        block = np.arange(n_blocks, dtype=np.int64)
        room = max(1024, -(-2 * self._cap // n_blocks))
        starts = np.arange(n_blocks, dtype=np.int64) * room
        state = (self.lp, self.ref, self.t_ref, self.t_avail, self.hz_shot, self.hz_hot, self.rng_state)
        args = (knot_t, knot_current, m.threshold_on, m.threshold_off, m.leak_rate_hz, m.hot_rate_hz,
                float(self.shot_coef), float(p.shot_noise_current_exponent), float(p.photoreceptor_cutoff_hz_max),
                float(p.photoreceptor_cutoff_ref_rate_e_s), float(p.substep_tolerance), float(p.latency_s),
                float(p.jitter_s), float(p.refractory_s) + _REFRACTORY_GUARD_S, *state)
        used_rows = n_blocks * room
        self._buffers(used_rows)
        seg_pix, seg_start, seg_end, seg_block = [], [], [], []  # finished buffer segments, each a pixel range
        while True:
            ends, p_next = _simulate_blocks(pix_lo, pix_hi, starts, starts + room, *args, *self._buf)
            seg_pix.append(pix_lo)
            seg_start.append(starts)
            seg_end.append(ends)
            seg_block.append(block)
            left = np.flatnonzero(p_next < pix_hi)
            if left.size == 0:
                break
            room *= 4
            pix_lo, pix_hi, block = p_next[left], pix_hi[left], block[left]
            starts = used_rows + np.arange(left.size, dtype=np.int64) * room
            used_rows += left.size * room
            if self._buf[0].size < used_rows:  # grow, keeping the segments already written
                old = self._buf
                self._buf = tuple(np.empty(used_rows, a.dtype) for a in old)
                for a, b in zip(self._buf, old):
                    a[:b.size] = b
        seg_pix = np.concatenate(seg_pix)
        order = np.argsort(seg_pix, kind="stable")  # pixel order (a segment left empty sorts harmlessly)
        starts = np.concatenate(seg_start)[order]
        ends = np.concatenate(seg_end)[order]
        counts = ends - starts
        per_block = np.bincount(np.concatenate(seg_block)[order], weights=counts, minlength=n_blocks)
        self._cap = max(1024, int(per_block.max()) * n_blocks)
        buf = self._buf
        n_threads = numba.get_num_threads()
        if counts.sum() == 0:
            return tuple(np.empty(lead, a.dtype) for a in self._pending)
        t_lo, t_hi = _us_range(starts, ends, buf[0], n_threads)
        span = t_hi - t_lo + 1
        if span <= 4 * int(counts.sum()) + (1 << 20):
            # One histogram of span buckets per part: fewer parts (down to one, a serial pass) when that is large.
            n_parts = max(1, min(n_threads, _BUCKET_MAX_ENTRIES // span))
            return _bucket_blocks(starts, ends, *buf, t_lo, span, n_parts, lead)
        sparse = _gather(starts, ends, *buf)  # sparse events over a long chunk: comparison sort
        order = sort_events(sparse[1], sparse[2], n_pix)
        out = tuple(np.empty(lead + order.size, a.dtype) for a in sparse)
        for a, b in zip(out, sparse):
            a[lead:] = b[order]
        return out

    def finish(self):
        """The events still held back (sorted)."""
        pending = self._pending
        self._pending = tuple(a[:0] for a in pending)
        return pending


def iter_knot_chunks(flux_tl, t0: float, t1: float, params: EventParams, max_bytes: int = CHUNK_BYTES,
                     max_pieces: int = CHUNK_PIECES):
    """Yield ``(knot_t [m+1], photocurrent [m+1, H·W])`` covering [t0, t1] in chunks of whole keyframe pieces."""
    n_pix = flux_tl.width * flux_tl.height
    per_chunk = max(1, min(max_pieces, max_bytes // (8 * n_pix) - 1))
    times, values = [], []
    for ta, tb, ya, yb in flux_tl.segments(t0, t1):
        if not times:
            times.append(ta)
            values.append(photocurrent_e_s(ya, params).ravel())
        times.append(tb)
        values.append(photocurrent_e_s(yb, params).ravel())
        if len(times) > per_chunk:
            yield np.array(times), np.stack(values)
            times, values = times[-1:], values[-1:]
    if len(times) > 1:
        yield np.array(times), np.stack(values)


def simulate_events(writer, flux_tl, t0: float, t1: float, params: EventParams, rng: np.random.Generator,
                    lux: float, progress: bool = False, chunk_bytes: int = CHUNK_BYTES) -> dict:
    """Simulate the event camera over [t0, t1] and write ``/events`` (DESIGN §5).

    Parameters
    ----------
    writer : RecordingWriter
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Recording interval, s (timeline time base; timestamps are µs since the timeline's t = 0).
    params : EventParams
    rng : numpy.random.Generator
        The sensor's own stream (fixed pattern, then per-pixel stream seeds).
    lux : float
        Scene illuminance of the recording (normalises the shot-noise rate, see module doc).
    progress : bool
        Show a progress bar.
    chunk_bytes : int
        Keyframe photocurrent held per time chunk.

    Returns
    -------
    dict
        The attrs written on ``/events``.
    """
    validate_params(params)
    height, width = flux_tl.height, flux_tl.width
    maps = draw_pixel_maps(params, (height, width), rng)
    mean_flux = float(np.mean(flux_tl.keyframe(0), dtype=np.float64))
    current_1lux = reference_current_1lux(mean_flux, lux, params)
    sim = EventSimulator(params, (height, width), photocurrent_e_s(flux_tl.sample(t0), params).ravel(), t0,
                         current_1lux, maps)
    columns = {name: writer.append_dataset(f"events/{name}", (), dtype, chunk_rows=EVENT_CHUNK_ROWS)
               for name, dtype in (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.uint8),
                                   ("label", np.uint8))}
    n_ms = int(math.ceil(round(t1 * 1e3, 9))) + 1
    boundaries_us = np.arange(n_ms, dtype=np.int64) * 1000
    ms_to_idx = np.zeros(n_ms, dtype=np.uint64)
    counts = np.zeros(4, dtype=np.int64)

    def write(batch):
        t_s, t_us, pixel, pol, label = batch
        keep = t_s < t1
        if not keep.all():
            t_us, pixel, pol, label = t_us[keep], pixel[keep], pol[keep], label[keep]
        if t_us.size == 0:
            return
        ms_to_idx[:] += np.searchsorted(t_us, boundaries_us, side="left").astype(np.uint64)
        columns["t"].append(t_us)
        columns["x"].append((pixel % width).astype(np.uint16))
        columns["y"].append((pixel // width).astype(np.uint16))
        columns["p"].append(pol)
        columns["label"].append(label)
        counts[:] += np.bincount(label, minlength=4)[:4]

    chunks = iter_knot_chunks(flux_tl, t0, t1, params, chunk_bytes)
    if progress:
        from tqdm import tqdm

        chunks = tqdm(chunks, desc="events", unit="chunk")
    for knot_t, knot_current in chunks:
        write(sim.advance(knot_t, knot_current))
    write(sim.finish())
    writer.write_dataset("events/ms_to_idx", ms_to_idx)

    attrs = params_to_attrs(params)
    attrs.update(
        time_origin_s=0.0, timestamp_unit="us", t_start_s=float(t0), t_end_s=float(t1),
        ms_to_idx_origin_us=0, lux=float(lux), pixel_area_m2=params.pixel_pitch_m ** 2,
        shot_noise_current_1lux_e_s=current_1lux,
        threshold_on_mean=float(maps.threshold_on.mean()), threshold_on_std=float(maps.threshold_on.std()),
        threshold_off_mean=float(maps.threshold_off.mean()), threshold_off_std=float(maps.threshold_off.std()),
        n_hot_pixels=int(np.count_nonzero(maps.hot_rate_hz)), n_events=int(counts.sum()),
        n_events_by_label=json.dumps({LABEL_NAMES[i]: int(c) for i, c in enumerate(counts)}),
        labels=json.dumps({str(k): v for k, v in LABEL_NAMES.items()}), polarity="1 ON, 0 OFF",
        model="log photocurrent, low-pass f_c=f_max*I/(I+I_ref), per-crossing interpolated timestamps; "
              "shot-noise rate r1*(I1/I)^exponent; leak drift leak_rate*threshold_on; refractory after readout")
    writer.set_attrs("events", **attrs)
    return attrs
