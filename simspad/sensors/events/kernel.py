"""Per-pixel event integrator (numba): photoreceptor, change detector, noise processes and readout of one chunk.

The photoreceptor low-pass of ``ln I`` is integrated *exactly* for an input whose log is linear in time over each
internal step (exponential integrator), so there is no ``τ/4`` stability limit; the step only has to keep ln of
the timeline's linear-in-time photocurrent close to linear: chord error ``(Δ ln I)²/8 ≤ substep_tolerance ×`` the
pixel's smaller threshold (which also bounds how much τ(I) varies inside a step). Static pixels and slowly
changing ones take one step per keyframe interval; cost follows what changes. Inside a step the detector is
``D(x) = A + B·x + c·exp(−x/τ)`` exactly and its crossings are solved by :mod:`.crossing`.

Randomness: one splitmix64 stream per pixel (:mod:`simspad.physics.rng`), seeded from the sensor's ``rng``, so the
result does not depend on chunking, on the pixel blocks or on the thread count; jitter draws are normal quantiles
of one uniform each (Acklam's approximation, relative error < 1.2·10⁻⁹). Draw order per pixel: at start the shot
and hot hazards and the leak phase; at a noise event its next hazard then its polarity; then at every event its
jitter.

Cost: an internal step costs one exp and no log (a step cut by the tolerance rule advances ln I by a per-pixel
constant; ln I at keyframes is taken once per pixel and keyframe, a tile of pixels at a time ahead of
the sequential loop, :mod:`.knot_table`); a crossing costs about two exp (Halley
iterations); noise processes cost a multiply per step until they fire.

The kernels take small NamedTuples (numba passes them as structs, at no cost) instead of long positional lists,
so that no two floats can be swapped at a call: :class:`Knots`, :class:`~.model.PixelMaps`,
:class:`ModelConstants`, :class:`PixelState`, :class:`EventBuffer` and :class:`Blocks`. Events are written with
their pixel, polarity and label packed in one int64 (:mod:`.codes`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from simspad.physics.photoreceptor import MIN_CURRENT_E_S, time_constant_pair
from simspad.physics.rng import exponential, normal, uniform_positive
from simspad.sensors.events.codes import pack_code
from simspad.sensors.events.crossing import Detector, first_crossing
from simspad.sensors.events.knot_table import TILE_PIXELS, fill_knot_table
from simspad.sensors.events.model import LABEL_HOT, LABEL_LEAK, LABEL_SHOT, LABEL_SIGNAL
from simspad.sensors.presets import EventParams

_MIN_STEP_S = 1e-10  # s: the internal step never shrinks below this (guards against round-off stalls)
#: Widening (log units) of the bounds that skip a step's exact crossing test: rounding is ~10⁻¹⁴ here.
_BOUND_MARGIN = 1e-9
#: Extra blind time after the refractory period, so µs-floored timestamps keep ≥ refractory_s spacing.
_REFRACTORY_GUARD_S = 1e-9


class Knots(NamedTuple):
    """Photocurrent knots of one chunk; between knots the photocurrent is linear in time."""

    t_s: np.ndarray
    """``[m+1]`` instants, s."""
    current_e_s: np.ndarray
    """``[m+1, H·W]`` photocurrent, e⁻ s⁻¹: knot-major, as the timeline gives it (the kernel copies a tile of
    pixels at a time into pixel-major tables, :mod:`.knot_table`)."""


class ModelConstants(NamedTuple):
    """Scalars of the sensor model the kernel needs (all float)."""

    shot_coef: float
    """``r₁·I₁^γ``: the shot-noise rate is ``shot_coef·I^(−γ)``, Hz."""
    shot_exponent: float
    """``γ``."""
    cutoff_hz_max: float
    """Photoreceptor bandwidth of a bright pixel, Hz."""
    cutoff_ref_rate_e_s: float
    """Photocurrent at half that bandwidth, e⁻ s⁻¹."""
    substep_tolerance: float
    """Chord error of ln I per internal step, as a fraction of the pixel's smaller threshold."""
    latency_s: float
    """Readout latency, s."""
    jitter_s: float
    """Readout jitter σ, s."""
    blind_s: float
    """Blind time after an event's readout (refractory period plus a guard), s."""


def model_constants(params: EventParams, current_1lux_e_s: float) -> ModelConstants:
    """The kernel's scalars from the sensor parameters and ``I₁`` (e⁻ s⁻¹, shot-noise normalisation)."""
    shot_coef = params.shot_noise_rate_hz_at_1lux * current_1lux_e_s ** params.shot_noise_current_exponent
    return ModelConstants(shot_coef=float(shot_coef), shot_exponent=float(params.shot_noise_current_exponent),
                          cutoff_hz_max=float(params.photoreceptor_cutoff_hz_max),
                          cutoff_ref_rate_e_s=float(params.photoreceptor_cutoff_ref_rate_e_s),
                          substep_tolerance=float(params.substep_tolerance), latency_s=float(params.latency_s),
                          jitter_s=float(params.jitter_s), blind_s=float(params.refractory_s) + _REFRACTORY_GUARD_S)


class PixelState(NamedTuple):
    """Per-pixel state carried from chunk to chunk, ``[H·W]`` each; updated in place by the kernels."""

    log_output: np.ndarray
    """Photoreceptor output ``L_p`` (ln of e⁻ s⁻¹)."""
    reference: np.ndarray
    """Change detector's reference level (ln of e⁻ s⁻¹)."""
    t_reference_s: np.ndarray
    """Instant of the last reset of the reference, s."""
    t_available_s: np.ndarray
    """End of the blind time after the last event, s."""
    shot_hazard: np.ndarray
    """Remaining unit-exponential hazard until the next shot-noise event."""
    hot_hazard: np.ndarray
    """Remaining unit-exponential hazard until the next hot-pixel event."""
    rng_state: np.ndarray
    """SplitMix64 state (uint64)."""

    @classmethod
    def empty(cls, seeds: np.ndarray) -> PixelState:
        """Uninitialised state for ``seeds.size`` pixels, their random streams starting at ``seeds`` (copied)."""
        n = seeds.size
        return cls(*(np.empty(n) for _ in range(6)), rng_state=seeds.copy())


class EventBuffer(NamedTuple):
    """Events as the kernel writes them, unsorted: readout time and packed pixel/polarity/label code."""

    t_s: np.ndarray
    """float64 readout time, s."""
    code: np.ndarray
    """int64 ``pixel·8 + polarity·4 + label``."""

    @classmethod
    def empty(cls, rows: int) -> EventBuffer:
        return cls(np.empty(rows, np.float64), np.empty(rows, np.int64))


class Blocks(NamedTuple):
    """Pixel blocks run in parallel: block i advances pixels ``pixel_lo[i] … pixel_hi[i]−1`` and writes its events
    into the buffer rows ``[start[i], limit[i])`` (int64 arrays)."""

    pixel_lo: np.ndarray
    pixel_hi: np.ndarray
    start: np.ndarray
    limit: np.ndarray


@numba.njit(cache=True)
def init_state(current0, t0, leak_rate_hz, state):
    """Settle every pixel at photocurrent ``current0`` (e⁻ s⁻¹) at instant ``t0`` (s) in its steady state:
    photoreceptor output and reference at ln I, no blind time, the first shot and hot hazards drawn, then the
    leak phase (in that order).

    A sensor that has been running is at a random point of each pixel's leak cycle, so the last reset is placed
    ``(1 − u)/leak_rate_hz[p]`` before ``t0`` (u uniform on (0, 1]): the drift already accumulated is
    ``(1 − u)·θ_on`` and the first leak event of a static pixel comes ``u/leak_rate_hz[p]`` after ``t0``,
    uniform over one leak period. A reference reset at ``t0`` would phase-lock every pixel's leak events to the
    recording's start (none before one leak period)."""
    for p in range(current0.size):
        state.log_output[p] = math.log(max(current0[p], MIN_CURRENT_E_S))
        state.reference[p] = state.log_output[p]
        state.t_available_s[p] = -np.inf
        s = state.rng_state[p]
        s, state.shot_hazard[p] = exponential(s)
        s, state.hot_hazard[p] = exponential(s)
        s, u = uniform_positive(s)
        state.t_reference_s[p] = t0 - (1.0 - u) / leak_rate_hz[p] if leak_rate_hz[p] > 0.0 else t0
        state.rng_state[p] = s


# One function for the whole per-pixel loop: the state lives in registers across steps, crossings and noise
# events; splitting it would pass a dozen values in and out per step and cost speed.
@numba.njit(cache=True, error_model="numpy")
def run_pixels(p0, p1, start, limit, knots, maps, model, state, buf):
    """Advance pixels ``p0 … p1−1`` over the keyframe pieces of one chunk, writing their events (unsorted) into
    ``buf`` (an :class:`EventBuffer`) from row ``start``. Returns ``(end, p_next, t_min, t_max)``: the row after
    the last event written, the first pixel not done (``p1`` when all are) and the earliest and latest readout time
    written (s; ``inf``, ``−inf`` when none), so the sort needs no pass to find its time range. When row ``limit``
    is reached inside pixel p, p's events are dropped and its state is left untouched (it is stored only once the
    pixel is done): ``(row of p's first event, p, …)``, so the caller can continue from p elsewhere and get exactly
    what one uninterrupted run gives.

    ``knots`` (:class:`Knots`) gives each pixel's photocurrent, linear in time between knots; ``maps`` the fixed
    pattern (:class:`~.model.PixelMaps`), ``model`` the scalars (:class:`ModelConstants`); ``state``
    (:class:`PixelState`) is updated in place.
    """
    knot_t = knots.t_s
    knot_current = knots.current_e_s
    th_on, th_off, leak_hz, hot_hz = maps.threshold_on, maps.threshold_off, maps.leak_rate_hz, maps.hot_rate_hz
    shot_coef, shot_exp = model.shot_coef, model.shot_exponent
    f_max, i_ref, step_tol = model.cutoff_hz_max, model.cutoff_ref_rate_e_s, model.substep_tolerance
    latency, jitter, blind = model.latency_s, model.jitter_s, model.blind_s
    lp_state, ref_state, tref_state = state.log_output, state.reference, state.t_reference_s
    tavail_state, hzs_state, hzh_state, rng_state = (state.t_available_s, state.shot_hazard, state.hot_hazard,
                                                     state.rng_state)
    buf_t, buf_code = buf.t_s, buf.code
    n_knots = knot_t.size
    n_ev = start
    t_min = np.inf  # readout time range of the pixels done
    t_max = -np.inf
    # I, ln I, I^(−γ/2) and the slopes at the knots, a tile of pixels at a time (:mod:`.knot_table`)
    tab_current = np.empty((TILE_PIXELS, n_knots))
    tab_log = np.empty((TILE_PIXELS, n_knots))
    tab_g = np.empty((TILE_PIXELS, n_knots))
    tab_slope = np.empty((TILE_PIXELS, max(n_knots - 1, 1)))
    tab_inv_slope = np.empty((TILE_PIXELS, max(n_knots - 1, 1)))
    for p in range(p0, p1):
        q = (p - p0) % TILE_PIXELS
        if q == 0:
            fill_knot_table(knot_t, knot_current, p, min(p + TILE_PIXELS, p1), shot_exp, tab_current, tab_log,
                            tab_g, tab_slope, tab_inv_slope)
        n_first = n_ev
        pixel_t_min = np.inf
        pixel_t_max = -np.inf
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
        ib = tab_current[q, 0]
        l_b = tab_log[q, 0]  # ln I at the next knot: one log per pixel and knot, none per internal step
        g_b = tab_g[q, 0]  # I^(−γ/2): the shot-noise rate of a step is r₁I₁^γ·g(start)·g(end)
        for j in range(n_knots - 1):
            ta = knot_t[j]
            tb = knot_t[j + 1]
            seg = tb - ta
            ia = ib
            l_a = l_b
            g_a = g_b
            ib = tab_current[q, j + 1]
            l_b = tab_log[q, j + 1]
            g_b = tab_g[q, j + 1]
            if seg <= 0.0:
                continue
            slope = tab_slope[q, j]
            inv_abs_slope = tab_inv_slope[q, j]
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
                tau, inv_tau = time_constant_pair(i_mid, f_max, i_ref)  # τ = (I + I_ref)/(2π f_max I) and 1/τ
                k = (l_e - l_t) / h
                decay = math.exp(-h * inv_tau)
                lp_e = l_e - k * tau + (lp - l_t + k * tau) * decay
                r_shot = shot_coef * g_t * g_e  # rate at the step's geometric-mean photocurrent
                # ---- events inside [t, s_b]. Exact path, x = s − t:  lp(x) = l_t + k·x − k·τ + c·exp(−x/τ);
                # detector D(x) = lp(x) − ref + ρ·(s − t_ref) = A + B·x + c·exp(−x/τ)
                c = lp - l_t + k * tau
                b_slope = k + rho
                # Fast path for the common quiet step (not blind, no crossing, no noise event): D(x) = lin(x) +
                # c·exp(−x/τ) with lin linear, so D ≤ max(lin(0) + max(c, c·decay), lin(h) + c·decay) and
                # D ≥ min(lin(0) + min(c, c·decay), lin(h) + c·decay) on [0, h] (exact extremes of a convex or
                # concave D; min/max instead of branches on the signs of c and B, which are data-dependent
                # and mispredicted). Where these bounds are inconclusive the exact path below decides.
                quiet = False
                if t >= t_avail:
                    a_off = l_t - k * tau - ref + rho * (t - t_ref)
                    trh = c * decay
                    d_end = a_off + b_slope * h + trh
                    quiet = (max(a_off + max(c, trh), d_end) < theta_on and min(a_off + min(c, trh), d_end) > -theta_off
                             and r_shot * h < hz_shot and r_hot * h < hz_hot)
                    if quiet:
                        hz_shot -= r_shot * h
                        hz_hot -= r_hot * h
                cur = t
                while not quiet:
                    if cur < t_avail:
                        s_end = min(t_avail, s_b)
                        dt = s_end - cur
                        hz_shot -= r_shot * dt
                        while hz_shot <= 0.0:
                            rs, e = exponential(rs)
                            hz_shot += e
                        hz_hot -= r_hot * dt
                        while hz_hot <= 0.0:
                            rs, e = exponential(rs)
                            hz_hot += e
                        cur = s_end
                        if cur >= s_b:
                            break
                    x0 = cur - t
                    a_off = l_t - k * tau - ref + rho * (t - t_ref)
                    trh = c * decay
                    d_end = a_off + b_slope * h + trh
                    lin0 = a_off + b_slope * x0
                    t_sig = np.inf
                    d_sig = 0.0  # detector value at the signal event: lp there = ref + d_sig − ρ·(t − t_ref)
                    pol = 0
                    # D at x0 needs the transient c·exp(−x0/τ), which lies between c and c·decay (0 < x0 < h).
                    # When even these bounds, widened by far more than any rounding, keep D(x0) strictly inside
                    # the thresholds, the decisions below are those of the exact value, so its exp waits until a
                    # search needs it (after most events the rest of the step is quiet and it never does).
                    if x0 == 0.0:
                        tr0 = c
                        d_cur_hi = d_cur_lo = lin0 + c
                    else:
                        tr0 = np.nan
                        d_cur_hi = lin0 + max(c, trh) + _BOUND_MARGIN
                        d_cur_lo = lin0 + min(c, trh) - _BOUND_MARGIN
                        if not (d_cur_hi < theta_on and d_cur_lo > -theta_off):
                            tr0 = c * math.exp(-x0 * inv_tau)
                            d_cur_hi = d_cur_lo = lin0 + tr0
                    if d_cur_lo >= theta_on:
                        t_sig = cur
                        d_sig = d_cur_lo
                        pol = 1
                    elif d_cur_hi <= -theta_off:
                        t_sig = cur
                        d_sig = d_cur_hi
                    else:
                        # cheap bounds of D on [x0, h] (convex if c > 0, concave if c < 0) before any search
                        lin_hi = a_off + b_slope * max(x0, h) if b_slope > 0 else lin0
                        lin_lo = lin0 if b_slope > 0 else a_off + b_slope * h
                        if c >= 0.0:
                            upper = max(d_cur_hi, d_end)
                            lower = lin_lo + c * decay
                        else:
                            upper = lin_hi + c * decay
                            lower = min(d_cur_lo, d_end)
                        if upper >= theta_on or lower <= -theta_off:
                            if np.isnan(tr0):
                                tr0 = c * math.exp(-x0 * inv_tau)
                            x_sig, pol = first_crossing(Detector(a_off, b_slope, c, tau), x0, h, lin0 + tr0, d_end,
                                                        theta_on, theta_off, tr0, trh)
                            if x_sig >= 0.0:
                                t_sig = t + x_sig
                                d_sig = theta_on if pol == 1 else -theta_off
                    kind = LABEL_SIGNAL  # which process fires first: signal, shot noise or hot pixel
                    t_next = t_sig
                    # a noise process fires in this step only if its remaining hazard runs out before the
                    # step's end or the signal event (a multiply, so the division is only paid when it does)
                    if r_shot * (min(t_next, s_b) - cur) >= hz_shot:
                        t_shot = cur + hz_shot / r_shot
                        if t_shot < t_next:
                            kind = LABEL_SHOT
                            t_next = t_shot
                    if r_hot * (min(t_next, s_b) - cur) >= hz_hot:
                        t_hot = cur + hz_hot / r_hot
                        if t_hot < t_next:
                            kind = LABEL_HOT
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
                    if kind == LABEL_SIGNAL:
                        lp_now = ref + d_sig - rho * (cur - t_ref)
                        label = LABEL_SIGNAL
                        if pol == 1 and rho * (cur - t_ref) > lp_now - ref:
                            label = LABEL_LEAK
                        ref = lp_now
                        t_ref = cur
                    elif kind == LABEL_SHOT:
                        rs, e = exponential(rs)
                        hz_shot = e
                        rs, u = uniform_positive(rs)
                        pol = 1 if u <= 0.5 else 0
                        label = LABEL_SHOT
                    else:
                        rs, e = exponential(rs)
                        hz_hot = e
                        rs, u = uniform_positive(rs)
                        pol = 1 if u <= 0.5 else 0
                        label = LABEL_HOT
                    delay = latency
                    if jitter > 0.0:
                        rs, z = normal(rs)
                        delay += jitter * z
                    t_out = cur + max(delay, 0.0)
                    t_avail = t_out + blind
                    if n_ev == limit:
                        return n_first, p, t_min, t_max
                    buf_t[n_ev] = t_out
                    pixel_t_min = min(pixel_t_min, t_out)
                    pixel_t_max = max(pixel_t_max, t_out)
                    buf_code[n_ev] = pack_code(p, pol, label)
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
        t_min = min(t_min, pixel_t_min)
        t_max = max(t_max, pixel_t_max)
    return n_ev, p1, t_min, t_max


@numba.njit(cache=True, parallel=True)
def simulate_blocks(blocks, knots, maps, model, state, buf):
    """Run the pixel :class:`Blocks` in parallel (arguments otherwise as :func:`run_pixels`).

    Returns each block's end row, first pixel not done (``blocks.pixel_hi[i]`` unless its rows filled up) and the
    earliest and latest readout time it wrote (s; ``inf``, ``−inf`` when none).
    """
    n_blocks = blocks.pixel_lo.size
    ends = np.empty(n_blocks, np.int64)
    p_next = np.empty(n_blocks, np.int64)
    t_min = np.empty(n_blocks)
    t_max = np.empty(n_blocks)
    for b in numba.prange(n_blocks):
        ends[b], p_next[b], t_min[b], t_max[b] = run_pixels(blocks.pixel_lo[b], blocks.pixel_hi[b], blocks.start[b],
                                                            blocks.limit[b], knots, maps, model, state, buf)
    return ends, p_next, t_min, t_max
