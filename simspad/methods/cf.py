"""CF (E): complementary filter on events only (Scheerlinck, Barnes, Mahony, ACCV 2018; docs/methods.md).

L̇ = e(t) − α(L − L^F) with L^F = 0 (no frames): per event at a pixel, ``L ← β·L ± c`` with
``β = exp(−α·Δt)`` since the pixel's last update; at an output instant every pixel decays to that time.
``α = 2π·f_cut``; the default cut-off ``f_cut = 0.1 Hz`` (time constant 1.6 s) keeps the high-pass leak far
slower than motion on the time scales scored here (ms to 1 s), while noise and leak events are forgotten over
seconds in long recordings. Without frames the initial image is unknown (L = 0): only changes are recovered. The output ``exp(L)`` has
no absolute scale (scored after an affine log fit, docs/methods.md).
"""

from __future__ import annotations

import numba
import numpy as np

from simspad.methods.event_batches import EventCursor
from simspad.methods.method import Method


@numba.njit(cache=True)
def cf_events(L, t_upd, ev_t, ev_pix, ev_dl, alpha):
    """Per-event complementary-filter update with L^F = 0."""
    for e in range(ev_t.size):
        i = ev_pix[e]
        t = ev_t[e]
        L[i] = np.exp(-alpha * (t - t_upd[i])) * L[i] + ev_dl[e]
        t_upd[i] = t


def cf_decay(L: np.ndarray, t_upd: np.ndarray, t_s: float, alpha: float) -> None:
    """Decay every pixel to ``t_s`` in place."""
    L *= np.exp(-alpha * (t_s - t_upd))
    t_upd[:] = t_s


class CF(Method):
    """CF (E): events-only complementary filter with cut-off ``f_cut_hz``."""

    name = "cf"
    label = "CF (E)"
    full_name = "Complementary filter on events alone, starting from no image"
    citation = "Scheerlinck, Barnes, Mahony, ACCV 2018"
    sensors = "E"
    requires = ("events",)
    absolute_scale = False

    def __init__(self, f_cut_hz: float = 0.1, chunk_s: float = 1e-3):
        self.alpha = 2.0 * np.pi * float(f_cut_hz)
        self.chunk_s = float(chunk_s)

    def _run(self, rec, times_s, tally):
        H, W = int(rec.height), int(rec.width)
        n_pix = H * W
        if times_s.size == 0:
            return
        cursor = EventCursor(rec)
        t0 = min(0.0, float(times_s[0]))
        L = np.zeros(n_pix)
        t_upd = np.full(n_pix, t0)
        t_now = t0
        for t in times_s:
            # Read in bounded chunks so a long gap between instants never loads a long stretch of events.
            while t_now < t:
                t_next = min(t_now + self.chunk_s, t)
                ev = cursor.take(t_now, t_next)
                cf_events(L, t_upd, ev.t_s, ev.pix, ev.dl, self.alpha)
                t_now = t_next
            ev = cursor.take(t_now, np.nextafter(t, np.inf))  # events exactly at t belong to the output
            cf_events(L, t_upd, ev.t_s, ev.pix, ev.dl, self.alpha)
            t_now = np.nextafter(t, np.inf)
            cf_decay(L, t_upd, t, self.alpha)
            yield np.exp(L).reshape(H, W).astype(np.float32)
        tally.cover(t0, float(times_s[-1]))
        tally.add(cursor.n_read / n_pix, 32.0 * cursor.n_read / n_pix)
