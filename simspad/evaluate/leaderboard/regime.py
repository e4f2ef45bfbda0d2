"""The regime map: PSNR per method over light level × image speed, and which sensor pair wins where.

A cell is one (lux, speed factor) pair; its PSNR is the mean over the scenes recorded there and its image speed
the median of the recordings' measured ``image_speed_px_s`` (pixels per second, the 50th percentile over pixels
and time of the image motion; NaN for recordings made before the speed axis, which count as factor 1). Per cell:

- every method's PSNR and bandwidth (kHz per pixel, mean over the cell's recordings);
- the difference *best S+E method − best F+E method* (dB): where SPAD + events beat frames + events;
- the Pareto front of PSNR against bandwidth: the methods no other method beats on both (higher or equal PSNR at
  lower or equal bandwidth, one strictly).

Only the methods scored on every recording of the board (:meth:`Board.ranked`) compete in a cell: they are the
ones eligible for the best mark, the best S+E and F+E of the difference and the Pareto front, so every comparison
is over the same recordings. A method covering only part of the board is shown with its PSNR where it has one,
never marked best, and written with ``pareto_front`` false.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simspad.evaluate.leaderboard.board import Board, fmt_number, mean_finite, method_label
from simspad.io.csv_cells import csv_safe

#: The sensor pairs compared on the map (``sensors`` column of results.csv).
SPAD_EVENTS, FRAMES_EVENTS = "S+E", "F+E"


@dataclass
class Regime:
    """PSNR and bandwidth per method and (lux, speed factor) cell."""

    luxes: list[float]
    speeds: list[float]
    """Speed factors, increasing."""
    image_speed_px_s: dict[float, float]
    """Median measured image speed (px/s) of the recordings at each speed factor (NaN: not recorded)."""
    psnr: dict[tuple[str, float, float], float]
    bandwidth_khz: dict[tuple[str, float, float], float]
    methods: list[str]
    sensors: dict[str, str]
    ranked: list[str]
    """The methods scored on every recording of the board: the only ones compared (best, difference, front)."""

    def grid(self, method: str) -> np.ndarray:
        """PSNR [speed, lux] of ``method`` (NaN where it has no result)."""
        return np.array([[self.psnr.get((method, lux, k), math.nan) for lux in self.luxes] for k in self.speeds])

    def best_of_sensors(self, sensors: str) -> tuple[np.ndarray, np.ndarray]:
        """Per cell [speed, lux]: the highest PSNR among ranked methods using ``sensors`` and that method's name."""
        psnr = np.full((len(self.speeds), len(self.luxes)), math.nan)
        name = np.full(psnr.shape, "", dtype=object)
        for m in self.ranked:
            if self.sensors.get(m) != sensors:
                continue
            g = self.grid(m)
            better = np.isfinite(g) & ~(g <= psnr)  # also where psnr is still NaN
            psnr[better], name[better] = g[better], m
        return psnr, name

    def spad_minus_frames(self) -> np.ndarray | None:
        """Best S+E − best F+E PSNR [speed, lux] (dB); None when either pair has no method on the board."""
        se, _ = self.best_of_sensors(SPAD_EVENTS)
        fe, _ = self.best_of_sensors(FRAMES_EVENTS)
        if not (np.isfinite(se).any() and np.isfinite(fe).any()):
            return None
        return se - fe

    def speed_label(self, k: float) -> str:
        """``×k`` and the measured image speed, e.g. ``×8 (410 px/s)``."""
        v = self.image_speed_px_s.get(k, math.nan)
        return f"×{k:g} ({v:.0f} px/s)" if math.isfinite(v) else f"×{k:g} (speed not recorded)"


def build_regime(board: Board) -> Regime:
    """The regime map of a leaderboard's rows (failed runs left out)."""
    psnr, bw, speed = defaultdict(list), defaultdict(list), defaultdict(list)
    for r in board.rows:
        k, lux = r["speed_factor"], float(r["lux"])
        speed[k].append(r["image_speed_px_s"])
        if r.get("error"):
            continue
        psnr[(r["method"], lux, k)].append(r["psnr_db"])
        bw[(r["method"], lux, k)].append(r.get("bandwidth_khz_per_pixel", math.nan))
    image_speed = {}
    for k, v in speed.items():
        finite = [x for x in v if math.isfinite(x)]
        image_speed[k] = float(np.median(finite)) if finite else math.nan
    return Regime(luxes=sorted({lux for _, lux, _ in psnr} | {float(r["lux"]) for r in board.rows}),
                  speeds=sorted(speed), image_speed_px_s=image_speed,
                  psnr={c: mean_finite(v) for c, v in psnr.items()},
                  bandwidth_khz={c: mean_finite(v) for c, v in bw.items()},
                  methods=list(board.methods), sensors={m: board.info[m]["sensors"] for m in board.methods},
                  ranked=board.ranked())


def pareto_front(points: dict[str, tuple[float, float]]) -> set[str]:
    """Names whose (bandwidth, PSNR) no other point dominates (≤ bandwidth and ≥ PSNR, one strictly)."""
    ok = {n: p for n, p in points.items() if all(math.isfinite(x) for x in p)}
    front = set()
    for n, (b, q) in ok.items():
        if not any((b2 <= b and q2 >= q) and (b2 < b or q2 > q) for n2, (b2, q2) in ok.items() if n2 != n):
            front.add(n)
    return front


def cell_points(regime: Regime, lux: float, k: float, ranked_only: bool = True) -> dict[str, tuple[float, float]]:
    """(bandwidth kHz/px, PSNR dB) of every ranked method (every method when not ``ranked_only``) with a finite
    result in the cell (lux, speed factor k)."""
    out = {}
    for m in (regime.ranked if ranked_only else regime.methods):
        b, q = regime.bandwidth_khz.get((m, lux, k), math.nan), regime.psnr.get((m, lux, k), math.nan)
        if math.isfinite(q) and math.isfinite(b) and b > 0:
            out[m] = (b, q)
    return out


def single_speed_note(regime: Regime) -> str | None:
    """The sentence saying the map has a single speed row, or None when it has several."""
    if len(regime.speeds) > 1:
        return None
    return (f"This board has a single speed ({regime.speed_label(regime.speeds[0])}): the maps have one row and show "
            "light level only. A dataset spec with `speed = [1.0, 8.0]` sweeps speed too.")


def regime_cells(board: Board, regime: Regime):
    """The regime table: methods × (lux, speed) PSNR (dB), then best S+E − best F+E per cell.

    Cells are (text, is_best), best = highest PSNR per column among the ranked methods.
    """
    cols = [(lux, k) for k in regime.speeds for lux in regime.luxes]
    header = ["Method"] + [f"{lux:g} lx, {regime.speed_label(k)}" for lux, k in cols]
    body = []
    best = []
    for lux, k in cols:
        vals = {m: regime.psnr.get((m, lux, k), math.nan) for m in regime.ranked}
        finite = [v for v in vals.values() if math.isfinite(v)]
        best.append({m for m, v in vals.items() if finite and v == max(finite)})
    for m in regime.methods:
        body.append([(method_label(board, m), False)] +
                    [(fmt_number(regime.psnr.get((m, lux, k), math.nan)), m in best[j])
                     for j, (lux, k) in enumerate(cols)])
    diff = regime.spad_minus_frames()
    if diff is not None:
        body.append([(f"best {SPAD_EVENTS} − best {FRAMES_EVENTS} (dB)", False)] +
                    [(_signed(diff[regime.speeds.index(k), regime.luxes.index(lux)]), False) for lux, k in cols])
    return header, body


def _signed(v: float) -> str:
    return f"{v:+.2f}" if math.isfinite(v) else "–"


def write_regime_csv(path: Path, board: Board, regime: Regime) -> None:
    """``leaderboard_regime.csv``: one row per (method, lux, speed) with PSNR, bandwidth and Pareto membership,
    then one row per cell for the best S+E − best F+E difference (method ``best_S+E-best_F+E``)."""
    diff = regime.spad_minus_frames()
    se_best, se_name = regime.best_of_sensors(SPAD_EVENTS)
    fe_best, fe_name = regime.best_of_sensors(FRAMES_EVENTS)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["method", "label", "sensors", "lux", "speed_factor", "image_speed_px_s", "psnr_db",
                    "bandwidth_khz_per_pixel", "pareto_front"])
        for k in regime.speeds:
            for lux in regime.luxes:
                front = pareto_front(cell_points(regime, lux, k))
                for m in regime.methods:
                    q = regime.psnr.get((m, lux, k), math.nan)
                    if not math.isfinite(q):
                        continue
                    w.writerow([csv_safe(m), csv_safe(board.info[m]["label"]), csv_safe(regime.sensors[m]), lux, k,
                                regime.image_speed_px_s[k], q, regime.bandwidth_khz.get((m, lux, k), math.nan),
                                "true" if m in front else "false"])
                if diff is not None:
                    i, j = regime.speeds.index(k), regime.luxes.index(lux)
                    w.writerow(["best_S+E-best_F+E", csv_safe(f"{se_name[i, j]} - {fe_name[i, j]}"), "", lux, k,
                                regime.image_speed_px_s[k], diff[i, j], "", ""])
