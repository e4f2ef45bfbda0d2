"""Adaptive SPAD sampling driven by the AKF covariance (reference paper §"Adaptive SPAD sampling"; DESIGN §7).

The SPAD aggregates are candidates on the fixed aggregate grid (0.4 kHz by default). At each candidate window
start the filter's variance P is averaged over square tiles (``tile_px``); a tile requests the new aggregate only
when its mean P exceeds ``ratio`` × the mean variance R₁ that one aggregate would deliver there (the SPAD
response's Var(ln Φ̂) at the filter's predicted irradiance), or an absolute ``threshold`` when one is given.
A Kalman update shrinks P to P·R₁/(P + R₁): the rule reads the sensor only when that cuts the uncertainty by at
least ratio/(1 + ratio) (default ratio 0.25: ≥ 20 %) — a value-of-information rule with no per-scene constant.
Unrequested tiles get no measurement (R⁻¹ = 0): their state integrates events only, and P keeps growing with
the event noise Q and σ_p until they ask again. Only requested aggregates are charged to the bandwidth.
Static regions stop being read once a few aggregates have been averaged; regions crossed by many events
(motion, whose Q raises P) are read at up to the full aggregate rate.
"""

from __future__ import annotations

import numpy as np

from simspad.methods.akf import NediAkf, akf_frames, akf_params_for


class TilePolicy:
    """Per-tile readout decisions for :func:`simspad.methods.akf.akf_frames`."""

    def __init__(self, shape: tuple[int, int], tally, tile_px: int = 16, ratio: float = 0.25,
                 threshold: float | None = None):
        H, W = shape
        ty, tx = (H + tile_px - 1) // tile_px, (W + tile_px - 1) // tile_px
        yy, xx = np.mgrid[0:H, 0:W]
        self.tile_id = ((yy // tile_px) * tx + xx // tile_px).reshape(-1)
        self.n_tiles = ty * tx
        self.tile_px_count = np.bincount(self.tile_id, minlength=self.n_tiles).astype(np.float64)
        self.tally = tally
        self.ratio = float(ratio)
        self.threshold = threshold
        self.requested = 0
        self.candidates = 0

    def _tile_mean(self, P: np.ndarray) -> np.ndarray:
        return np.bincount(self.tile_id, weights=P, minlength=self.n_tiles) / self.tile_px_count

    def select(self, st, m, first: bool) -> np.ndarray:
        pm = self._tile_mean(st.P)
        if first:
            req = np.ones(self.n_tiles, bool)
        elif self.threshold is not None:
            req = pm > self.threshold
        else:
            r1 = m.var_log_predicted(np.exp(st.L + m.level_ref))
            req = pm > self.ratio * self._tile_mean(r1)
        self.requested += int(req.sum())
        self.candidates += self.n_tiles
        mask = req[self.tile_id]
        frac = float(mask.mean())
        if self.tally is not None:
            self.tally.add(frac, frac * m.readout_bits)
        return mask

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

    def __init__(self, aggregate_hz: float | None = None, n_bins: int | None = None, tile_px: int = 16,
                 ratio: float = 0.25, threshold: float | None = None, **akf):
        super().__init__(aggregate_hz, n_bins, **akf)
        self.tile_px = tile_px
        self.ratio = ratio
        self.threshold = threshold
        self.last_policy: TilePolicy | None = None

    def _run(self, rec, times_s, tally):
        shape = (int(rec.height), int(rec.width))
        policy = TilePolicy(shape, tally, self.tile_px, self.ratio, self.threshold)
        self.last_policy = policy
        meas = self._measurements(rec, times_s, tally)
        yield from akf_frames(meas, times_s, shape, akf_params_for(rec, **self.akf), tally, adaptive=policy)
