"""Event stream helpers shared by the event-based methods.

Events are read in time windows from a recording (``rec.events.window(t0_s, t1_s)``, docs/format.md: ``t`` int64 µs on
the recording's time base, ``p`` 1 ON / 0 OFF) and turned into per-event log-irradiance increments
``dl = +threshold_on`` (ON) or ``−threshold_off`` (OFF): the nominal contrast thresholds of the sensor (docs/methods.md:
"event contrast threshold c is the sensor's nominal one"). Noise labels are never used (real data has none).

The level of a pixel, ``ℓ(t) = Σ_{events e at the pixel, t_e ≤ t} dl_e``, is the event estimate of
``ln Φ(t) − ln Φ(t₀)``; EDI/NEDI use ``Φ(t) = Φ(f)·exp(ℓ(t) − ℓ(f))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from simspad.errors import InputError


@dataclass
class EventBatch:
    """Events of one time window, sorted by time.

    Attributes
    ----------
    t_s : ndarray float64
        Event times (s, recording time base).
    pix : ndarray int64
        Linear pixel index ``y·W + x``.
    dl : ndarray float64
        Signed log increment of each event.
    t0_s, t1_s : float
        The window ``[t0_s, t1_s)`` the batch covers.
    """

    t_s: np.ndarray
    pix: np.ndarray
    dl: np.ndarray
    t0_s: float
    t1_s: float

    def __len__(self) -> int:
        return int(self.t_s.size)

    def upto(self, t_s: float) -> int:
        """Number of events with time ≤ ``t_s``."""
        return int(np.searchsorted(self.t_s, t_s, side="right"))

    @classmethod
    def empty(cls, t0_s: float, t1_s: float) -> "EventBatch":
        return cls(np.zeros(0), np.zeros(0, np.int64), np.zeros(0), t0_s, t1_s)


def event_thresholds(rec) -> tuple[float, float, float]:
    """Nominal (threshold_on, threshold_off, threshold_sigma) from the ``/events`` attrs."""
    a = rec.events.attrs
    try:
        c_on = float(a["threshold_on"])
        c_off = float(a.get("threshold_off", c_on))
        sigma = float(a.get("threshold_sigma", 0.0))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"event attrs incomplete or not numeric ({exc})", path=rec.path, field="/events attrs")
    if not (c_on > 0 and c_off > 0):
        raise InputError("threshold_on and threshold_off must be > 0", path=rec.path, field="/events attrs")
    return c_on, c_off, sigma


class EventCursor:
    """Reads a recording's events window by window, in time order, never holding more than one window.

    Parameters
    ----------
    rec : Recording
    on_dl, off_dl : float, optional
        Log increments of ON and OFF events; default the nominal thresholds from the attrs.
    """

    def __init__(self, rec, on_dl: float | None = None, off_dl: float | None = None):
        c_on, c_off, _ = event_thresholds(rec)
        self.rec = rec
        self.width = int(rec.width)
        self.height = int(rec.height)
        self.on_dl = c_on if on_dl is None else float(on_dl)
        self.off_dl = c_off if off_dl is None else float(off_dl)
        self.n_read = 0

    def take(self, t0_s: float, t1_s: float) -> EventBatch:
        """Events with ``t0_s ≤ t < t1_s`` (seconds)."""
        if not t1_s > t0_s:
            return EventBatch.empty(t0_s, t1_s)
        # A 1 µs margin each side, then an exact filter: the reader's own rounding can neither drop nor repeat
        # an event at a window edge.
        ev = self.rec.events.window(max(t0_s - 1e-6, 0.0), t1_s + 1e-6)
        t = np.asarray(ev["t_us"] if "t_us" in ev else ev["t"], dtype=np.int64).astype(np.float64) * 1e-6
        keep = (t >= t0_s) & (t < t1_s)
        t = t[keep]
        x = np.asarray(ev["x"])[keep].astype(np.int64)
        y = np.asarray(ev["y"])[keep].astype(np.int64)
        p = np.asarray(ev["p"])[keep]
        self._check_addresses(x, y, t0_s)
        if t.size > 1 and np.any(np.diff(t) < 0):
            order = np.argsort(t, kind="stable")
            t, x, y, p = t[order], x[order], y[order], p[order]
        dl = np.where(p > 0, self.on_dl, -self.off_dl)
        self.n_read += int(t.size)
        return EventBatch(t, y * self.width + x, dl, t0_s, t1_s)


    def _check_addresses(self, x: np.ndarray, y: np.ndarray, t0_s: float) -> None:
        """InputError when an event lies outside the sensor: the kernels index per-pixel state with ``y·W + x``.

        :func:`~simspad.io.recording.open_recording` refuses such files already; this guard keeps the kernels
        safe for a recording built around an h5py file by hand.
        """
        for name, v, limit in (("x", x, self.width), ("y", y, self.height)):
            bad = v >= limit
            if bad.any():
                k = int(np.argmax(bad))
                raise InputError(f"event at {t0_s:.6f} s or later: {name} = {int(v[k])} outside the sensor "
                                 f"(expected < {limit})", path=self.rec.path, field=f"/events/{name}")


def group_by_pixel(pix: np.ndarray, n_pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """Stable order grouping events by pixel (time order kept within a pixel) and CSR offsets [n_pixels + 1]."""
    order = np.argsort(pix, kind="stable")
    offsets = np.zeros(n_pixels + 1, dtype=np.int64)
    np.cumsum(np.bincount(pix, minlength=n_pixels), out=offsets[1:])
    return order, offsets


class PixelEvents(NamedTuple):
    """A window's events grouped per pixel (:func:`group_by_pixel` and the batch's times and steps)."""

    order: np.ndarray
    """Event indices, by pixel then time."""
    offsets: np.ndarray
    """[N + 1] pixel p's events are ``order[offsets[p]:offsets[p + 1]]``."""
    t_s: np.ndarray
    """Event times (s)."""
    dl: np.ndarray
    """Signed log steps (±c)."""


def levels_at(batch: EventBatch, t_s: float, n_pixels: int, start: int = 0,
              base: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Per-pixel level at ``t_s`` (events with time ≤ t_s), incrementally from ``base`` after ``start`` events.

    Returns the level array [n_pixels] (float64) and the index of the next unconsumed event.
    """
    stop = max(batch.upto(t_s), start)
    lev = np.zeros(n_pixels) if base is None else base
    if stop > start:
        lev = lev + np.bincount(batch.pix[start:stop], weights=batch.dl[start:stop], minlength=n_pixels)
    return lev, stop


@numba.njit(cache=True)
def mean_exp_level(events: PixelEvents, t0, t1, t_ref, out_mean, out_lref) -> None:
    """Per pixel: ``(1/(t1−t0))∫_{t0}^{t1} exp(ℓ(t) − ℓ(t_ref)) dt`` and ``ℓ(t_ref)`` (ℓ relative to the batch start).

    The EDI blur integral (Pan et al. 2019) with ℓ piecewise constant between events.
    """
    order, offsets, ev_t, ev_dl = events
    n_pix = offsets.size - 1
    span = t1 - t0
    for p in range(n_pix):
        a, b = offsets[p], offsets[p + 1]
        if a == b:
            out_mean[p] = 1.0
            out_lref[p] = 0.0
            continue
        lref = 0.0
        for k in range(a, b):
            e = order[k]
            if ev_t[e] <= t_ref:
                lref += ev_dl[e]
        acc = 0.0
        lev = 0.0
        t_prev = t0
        for k in range(a, b):
            e = order[k]
            te = ev_t[e]
            if te > t0:
                hi = te if te < t1 else t1
                if hi > t_prev:
                    acc += (hi - t_prev) * np.exp(lev - lref)
                    t_prev = hi
            lev += ev_dl[e]
        if t1 > t_prev:
            acc += (t1 - t_prev) * np.exp(lev - lref)
        out_mean[p] = acc / span
        out_lref[p] = lref
