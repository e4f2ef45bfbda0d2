"""Adaptive SPAD sampling driven by the AKF covariance (reference paper §"Adaptive SPAD sampling"; docs/methods.md).

The SPAD aggregates are candidates on the fixed aggregate grid (0.4 kHz by default). At each candidate window
start the filter's variance P is averaged over square tiles (``tile_px``), and a tile requests the new aggregate
when either

- its mean P exceeds ``threshold`` (the paper's absolute rule); default ``(c/2)²``, c the sensor's mean nominal
  contrast threshold: a log-intensity uncertainty above half an event step is too coarse for events to refine;
- or its mean P exceeds ``ratio`` × the mean variance R₁ that one aggregate would deliver there (the SPAD
  response's Var(ln Φ̂) at the filter's predicted irradiance). A Kalman update shrinks P to P·R₁/(P + R₁): with
  the default ratio 1, a readout is requested whenever it would at least halve the uncertainty (value of
  information, scale-free).

In dim light one aggregate is noisy (large R₁) and the absolute rule keeps the SPAD read; in bright light R₁ is
small and the ratio rule reads only where events have eroded the estimate. ``threshold=None`` or ``ratio=None``
switch either rule off. A tile is also read at least every ``max_interval`` candidate windows (default 8: a 50 Hz
refresh at the 0.4 kHz grid), because errors that produce no events (a missed or mis-sized change) cannot raise P
and only a readout reveals them. Unrequested tiles get no measurement (R⁻¹ = 0): their state integrates events
only, and P keeps growing with the event noise Q (threshold mismatch, photoreceptor bandwidth, isolation) and σ_p
until they ask again; only requested aggregates are charged to the bandwidth. What the two rules and the refresh
save and cost on the mini dataset: docs/methods.md ("SimSPAD's measurements behind the methods' choices").

Adaptive integration time (the paper: "adaptively changing the integration time of SPADs"): a tile that is not
read keeps counting, so when it is read its aggregate holds every bin since its previous readout (at most
``max_windows`` windows; then the in-pixel counter restarts). That aggregate is deblurred by NEDI over its whole
span with the events, ``ceil(log2(n + 1))`` bits are charged for its n bins, and the readout decision uses the
variance of that longer aggregate (``integrate=True``). Default off (docs/methods.md: events from slow, dim
photoreceptors do not deblur long spans well).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from simspad.methods.akf import NediAkf, akf_frames, akf_params_for
from simspad.methods.event_batches import EventBatch, event_thresholds
from simspad.methods.method import aggregate_bits
from simspad.methods.nedi import nedi_deblur
from simspad.methods.spad_response import SpadResponse, floor_flux, log_flux_variance


@dataclass(frozen=True)
class ReadoutRules:
    """When a tile reads its SPAD aggregate (see the module docstring); ``None`` switches a rule off.

    Attributes
    ----------
    tile_px : int
        Side of the square tiles (pixels).
    ratio : float or None
        Read when the tile's mean P exceeds ``ratio`` × the variance one aggregate would deliver.
    threshold : float or None
        Read when the tile's mean P exceeds this (log-irradiance²).
    integrate : bool
        An unread tile keeps counting, for at most ``max_windows`` windows.
    max_windows : int
        Longest integration, in candidate windows (with ``integrate``).
    max_interval : int or None
        Read a tile at least every ``max_interval`` candidate windows.
    """

    tile_px: int = 16
    ratio: float | None = 1.0
    threshold: float | None = None
    integrate: bool = False
    max_windows: int = 16
    max_interval: int | None = None


class TilePolicy:
    """Per-tile readout decisions (and re-aggregation) for :func:`simspad.methods.akf.akf_frames`."""

    def __init__(self, shape: tuple[int, int], tally, resp: SpadResponse, rules: ReadoutRules = ReadoutRules()):
        tile_px, ratio, threshold = rules.tile_px, rules.ratio, rules.threshold
        integrate, max_windows, max_interval = rules.integrate, rules.max_windows, rules.max_interval
        H, W = shape
        ty, tx = (H + tile_px - 1) // tile_px, (W + tile_px - 1) // tile_px
        yy, xx = np.mgrid[0:H, 0:W]
        self.tile_id = ((yy // tile_px) * tx + xx // tile_px).reshape(-1)
        self.n_tiles = ty * tx
        self.tile_px_count = np.bincount(self.tile_id, minlength=self.n_tiles).astype(np.float64)
        self.tally = tally
        self.resp = resp
        self.dcr = np.asarray(resp.dcr_cps, dtype=np.float64).reshape(-1)
        self.ratio = ratio
        self.threshold = threshold
        self.max_interval = max_interval
        if ratio is None and threshold is None:
            raise ValueError("adaptive sampling needs a ratio or a threshold")
        self.max_windows = int(max_windows) if integrate else 1
        self.history: deque = deque(maxlen=self.max_windows)
        self.j = -1
        self.last_read = np.zeros(self.n_tiles, np.int64)
        self.requested = 0
        self.candidates = 0
        self.bins_read = 0.0
        self.tile_reads = np.zeros(self.n_tiles, np.int64)

    def _tile_mean(self, v: np.ndarray) -> np.ndarray:
        return np.bincount(self.tile_id, weights=v, minlength=self.n_tiles) / self.tile_px_count

    def _start(self, j: int) -> np.ndarray:
        """First window integrated by each tile's counter if it is read at window ``j``."""
        lr = self.last_read
        return lr + ((j - lr) // self.max_windows) * self.max_windows

    def select(self, st, m, first: bool):
        self.j += 1
        j = self.j
        self.history.append(m)
        n_win = m.raw_bin_t.size  # SPAD windows carry their raw counts and bin times
        start = self._start(j)
        n_acc_tile = (j - start + 1) * n_win
        if first:
            req = np.ones(self.n_tiles, bool)
        else:
            pm = self._tile_mean(st.P)
            req = np.zeros(self.n_tiles, bool)
            if self.threshold is not None:
                req |= pm > self.threshold
            if self.ratio is not None:
                pred = np.exp(st.L + m.level_ref)
                r1 = log_flux_variance(pred, n_acc_tile[self.tile_id], self.resp.q_m2, self.resp.gate_s, self.dcr)
                req |= pm > self.ratio * self._tile_mean(r1)
            if self.max_interval is not None:
                req |= (j + 1 - self.last_read) >= self.max_interval
        self.requested += int(req.sum())
        self.candidates += self.n_tiles
        self.tile_reads += req
        mask = req[self.tile_id]
        m_out = self._reaggregate(m, j, start, req) if np.any(req & (start < j)) else m
        self.last_read[req] = j + 1
        if self.tally is not None:
            bits = np.array([aggregate_bits(int(n)) for n in n_acc_tile])
            self.tally.add(float(mask.mean()), float(np.sum((bits * self.tile_px_count)[req])) / mask.size)
        self.bins_read += float(np.sum((n_acc_tile * self.tile_px_count)[req])) / mask.size
        return mask, m_out

    def _reaggregate(self, m, j: int, start: np.ndarray, req: np.ndarray):
        """Measurement whose requested pixels hold NEDI over all the bins since their tile's last readout."""
        flux = m.flux_ref.copy()
        var = m.var_log.copy()
        lref = m.level_ref.copy()
        n_win = m.raw_bin_t.size
        n_pp = np.full(flux.size, float(n_win))
        hist = list(self.history)
        for s in np.unique(start[req & (start < j)]):
            tiles = np.nonzero(req & (start == s))[0]
            pix = np.nonzero(np.isin(self.tile_id, tiles))[0]
            recs = hist[len(hist) - 1 - (j - s):]
            counts = np.sum([r.raw_counts[pix] for r in recs], axis=0)
            bin_t = np.concatenate([r.raw_bin_t for r in recs])
            local = np.full(flux.size, -1, np.int64)
            local[pix] = np.arange(pix.size)
            ts, ps, ds = [], [], []
            for r in recs:
                keep = local[r.events.pix] >= 0
                ts.append(r.events.t_s[keep])
                ps.append(local[r.events.pix[keep]])
                ds.append(r.events.dl[keep])
            batch = EventBatch(np.concatenate(ts), np.concatenate(ps), np.concatenate(ds), recs[0].a_s, m.b_s)
            a0, b_nom = recs[0].a_s, m.a_s + m.duration_s
            f = 0.5 * (a0 + b_nom)
            n_acc = int(bin_t.size)
            phi, v, lr = nedi_deblur(counts.astype(np.float64), n_acc, bin_t, batch, f, self.resp.q_m2,
                                     self.resp.gate_s, self.dcr[pix])
            before = batch.t_s < m.a_s
            l_at_a = np.bincount(batch.pix[before], weights=batch.dl[before], minlength=pix.size)
            flux[pix], var[pix], lref[pix] = phi, v, lr - l_at_a
            n_pp[pix] = n_acc
        q, g, dcr = self.resp.q_m2, self.resp.gate_s, self.dcr

        def var_model(fl):
            return log_flux_variance(fl, n_pp, q, g, dcr)

        return replace(m, flux_ref=flux, var_log=var, level_ref=lref, floor_flux=floor_flux(n_pp, q, g),
                       var_log_model=var_model)

    def after(self, st, m, mask: np.ndarray) -> None:
        """Nothing to remember: the rule depends on the current P and the next aggregate only."""

    @property
    def readout_fraction(self) -> float:
        """Requested / candidate tile aggregates so far."""
        return self.requested / self.candidates if self.candidates else 0.0


class AdaptiveNediAkf(NediAkf):
    """Adaptive NEDI+AKF (S+E): NEDI+AKF reading a SPAD aggregate only where the filter is uncertain."""

    name = "adaptive_nedi_akf"
    label = "Adaptive NEDI+AKF (S+E)"
    full_name = "NEDI+AKF reading SPAD aggregates only where the filter's variance asks for them"
    citation = "adaptive SPAD sampling of Muglikar et al., IEEE TPAMI 2025"

    def __init__(self, aggregate_hz: float | None = None, n_bins: int | None = None, tile_px: int = 16,
                 ratio: float | None = 1.0, threshold: float | str | None = "auto", integrate: bool = False,
                 max_windows: int = 16, max_interval: int | None = 8, **akf):
        super().__init__(aggregate_hz, n_bins, **akf)
        self.max_interval = max_interval
        self.tile_px = tile_px
        self.ratio = ratio
        self.threshold = threshold
        self.integrate = integrate
        self.max_windows = max_windows
        self.last_policy: TilePolicy | None = None

    def _run(self, rec, times_s, tally):
        shape = (int(rec.height), int(rec.width))
        threshold = self.threshold
        if threshold == "auto":
            c_on, c_off, _ = event_thresholds(rec)
            threshold = (0.25 * (c_on + c_off)) ** 2  # (c/2)², c the mean nominal threshold
        rules = ReadoutRules(self.tile_px, self.ratio, threshold, self.integrate, self.max_windows, self.max_interval)
        policy = TilePolicy(shape, tally, SpadResponse.from_recording(rec), rules)
        self.last_policy = policy
        meas = self._measurements(rec, times_s, tally)
        yield from akf_frames(meas, times_s, shape, akf_params_for(rec, **self.akf), tally, adaptive=policy)
