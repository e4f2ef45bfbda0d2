"""Independent, vectorised NumPy/SciPy references for the methods' compiled kernels (issue 36, goal 6).

Written from the equations in docs/methods.md and the modules' docstrings, not from the kernels' code: they
organise the work differently (whole arrays at a time instead of one event or one pixel at a time), so a formula
changed in a kernel shows up as a disagreement. Used by ``tests/methods`` and by ``benchmarks/bench_akf.py`` and
``benchmarks/bench_nedi.py`` (which time the kernels against them).

- :func:`akf_events_reference`: the AKF's per-event update (simspad.methods.akf.akf_events). Every event's noise
  Q = Q_thr + Q_iso + Q_ref + Q_bw depends only on the event stream (its own pixel's previous event, the latest
  event among its eight neighbours), so all of them are computed at once with sorts and searches; the state
  recursion is sequential only within a pixel, so it runs over the k-th events of every pixel together.
- :func:`nedi_reference`: the NEDI aggregate solve (simspad.methods.nedi.nedi_deblur): the expected number of
  ones E[S](Φ) = Σ_k 1 − exp(−(q·Φ·e^{ℓ(t_k) − ℓ(f)} + r_dark)·gate) equals the count S, solved for every pixel at
  once with SciPy's vectorised bracketing root finder.
"""

from __future__ import annotations

import numpy as np

#: The eight neighbours (dy, dx) of a pixel.
NEIGHBOURS = tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0))


def event_noise_reference(ev_t, ev_pix, ev_dl, t_last_ev0, tau_pr, width, height, p):
    """Process noise Q added by each event, for a time-sorted stream starting from ``t_last_ev0`` ([N] s).

    ``p`` holds ``sigma_iso``, ``sigma_ref``, ``refractory_window_s``, ``q_threshold`` and ``use_bw`` (the
    fields of :class:`simspad.methods.akf.EventUpdateParams`). Returns ``(q [n], rank [n])``: the noise and each
    event's position among its pixel's events (0 for the first).
    """
    ev_t = np.asarray(ev_t, np.float64)
    ev_pix = np.asarray(ev_pix, np.int64)
    n = ev_t.size
    pos = np.arange(n, dtype=np.int64)
    order = np.lexsort((pos, ev_pix))  # by pixel, then by position in the stream
    key = ev_pix[order] * n + pos[order]  # increasing
    first = np.r_[True, ev_pix[order][1:] != ev_pix[order][:-1]]
    group_start = np.maximum.accumulate(np.where(first, np.arange(n), 0))
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n) - group_start
    prev_t = np.empty(n)
    prev_t[order] = np.where(first, t_last_ev0[ev_pix[order]], np.r_[0.0, ev_t[order][:-1]])
    dtp = ev_t - prev_t

    # latest event of each neighbour before this one in the stream (else the neighbour's initial time)
    y, x = np.divmod(ev_pix, width)
    t_nb = np.full(n, -np.inf)
    for dy, dx in NEIGHBOURS:
        ok = (y + dy >= 0) & (y + dy < height) & (x + dx >= 0) & (x + dx < width)
        nb = np.where(ok, ev_pix + dy * width + dx, 0)
        j = np.searchsorted(key, nb * n + pos) - 1  # the last (pixel, position) key before (nb, this position)
        hit = (j >= 0) & (key[np.maximum(j, 0)] // n == nb)
        t_j = np.where(hit, ev_t[order][np.maximum(j, 0)], t_last_ev0[nb])
        t_nb = np.where(ok, np.maximum(t_nb, t_j), t_nb)

    q = np.full(n, p.q_threshold)
    q = q + np.where(np.isfinite(t_nb), p.sigma_iso * (ev_t - np.where(np.isfinite(t_nb), t_nb, 0.0)), 0.0)
    q = q + np.where(dtp < p.refractory_window_s, p.sigma_ref * dtp, 0.0)
    if p.use_bw:
        tau = tau_pr[ev_pix]
        q = q + (ev_dl * (tau / (tau + dtp))) ** 2  # the photoreceptor lags a step by τ/(τ + Δt) of it
    return q, rank


def akf_events_reference(state, ev_t, ev_pix, ev_dl, p) -> None:
    """The AKF's per-event update applied to ``state`` (a :class:`simspad.methods.akf.FilterArrays`) in place.

    At each event of pixel i at time t: relax (L, P) to t towards L^F (P⁻¹ += R⁻¹·Δt, L − L^F scaled by P/P₀,
    then P += σ_p·Δt, only when Δt > 0), then L and L^F += the event's step, P += Q (:func:`event_noise_reference`)
    and the pixel's last event time becomes t. ``p`` as :class:`simspad.methods.akf.EventUpdateParams`.
    """
    L, P, LF, Rinv, t_upd, t_last_ev, tau_pr = state
    ev_t = np.asarray(ev_t, np.float64)
    ev_pix = np.asarray(ev_pix, np.int64)
    ev_dl = np.asarray(ev_dl, np.float64)
    if ev_t.size == 0:
        return
    q, rank = event_noise_reference(ev_t, ev_pix, ev_dl, t_last_ev.copy(), tau_pr, p.width, p.height, p)
    by_rank = np.argsort(rank, kind="stable")
    bounds = np.searchsorted(rank[by_rank], np.arange(rank.max() + 2))
    for k in range(rank.max() + 1):  # the k-th event of every pixel at once (at most one per pixel)
        e = by_rank[bounds[k]:bounds[k + 1]]
        i, t = ev_pix[e], ev_t[e]
        dt = t - t_upd[i]
        move = dt > 0.0
        p0 = P[i]
        pn = 1.0 / (1.0 / p0 + Rinv[i] * dt)
        L[i] = np.where(move, LF[i] + (pn / p0) * (L[i] - LF[i]), L[i])
        P[i] = np.where(move, pn + p.sigma_p * dt, p0)
        t_upd[i] = np.where(move, t, t_upd[i])
        L[i] += ev_dl[e]
        LF[i] += ev_dl[e]
        P[i] += q[e]
        t_last_ev[i] = t


def nedi_reference(counts, n_bins: int, bin_t_s, batch, t_ref_s: float, q_m2: float, gate_s: float,
                   dcr_cps: float = 0.0, block_px: int = 8192) -> np.ndarray:
    """Φ(f) per pixel solving E[S](Φ) = min(S, n − 1) (Φ = 0 for S = 0), [H, W]; SciPy's vectorised bracketing
    root finder (``scipy.optimize.elementwise.find_root``) on ln Φ, to 10⁻¹³ in ln Φ, ``block_px`` pixels at a
    time (memory: block_px × n_bins values).

    The count is capped at n − 1 as in :func:`simspad.methods.spad_response.estimate_flux` (a saturated pixel has
    no finite solution). The dark count rate must be small enough that every counted pixel has a positive flux."""
    from scipy.optimize import elementwise  # deferred: SciPy ≥ 1.15, only the reference needs it

    shape = counts.shape
    s = np.minimum(np.asarray(counts, np.float64).reshape(-1), n_bins - 1.0)
    n_pix = s.size
    bin_t_s = np.asarray(bin_t_s, np.float64)
    events = batch is not None and len(batch.t_s) > 0
    if events:
        lref = np.bincount(batch.pix, weights=batch.dl * (batch.t_s <= t_ref_s), minlength=n_pix)
        kb = np.searchsorted(bin_t_s, batch.t_s, side="left")  # first bin sampled at or after the event
    dark = np.broadcast_to(np.asarray(dcr_cps, np.float64), shape).reshape(-1)
    out = np.zeros(n_pix)

    for p0 in range(0, n_pix, block_px):
        p1 = min(p0 + block_px, n_pix)
        live = np.nonzero(s[p0:p1] > 0)[0] + p0
        if live.size == 0:
            continue
        if events:  # ℓ(t_k) − ℓ(f) of the block's pixels: their events' steps summed from each one's first bin on
            sel = (batch.pix >= p0) & (batch.pix < p1)
            lev = np.zeros((p1 - p0, bin_t_s.size + 1))
            np.add.at(lev, (batch.pix[sel] - p0, kb[sel]), batch.dl[sel])
            a = np.exp(np.cumsum(lev, axis=1)[:, :-1] - lref[p0:p1, None])[live - p0]
        else:
            a = np.ones((live.size, bin_t_s.size))
        lo = np.full(live.size, np.log(1e-30 / (q_m2 * gate_s)))
        hi = np.log(1e3 / (q_m2 * gate_s * a.min(axis=1)))

        def excess(u, j, a=a, live=live):  # E[S] − S at Φ = e^u, increasing in u, for the pixels live[j]
            j = j.astype(np.int64)  # the solver passes only the unconverged pixels, with their j
            rate = q_m2 * np.exp(u)[:, None] * a[j] + dark[live[j], None]
            return np.sum(-np.expm1(-rate * gate_s), axis=1) - s[live[j]]

        res = elementwise.find_root(excess, (lo, hi), args=(np.arange(live.size),),
                                    tolerances=dict(xatol=1e-13, xrtol=0.0))
        assert np.all(res.success), "the reference's bracket does not hold every root"
        out[live] = np.exp(res.x)
    return out.reshape(shape)
