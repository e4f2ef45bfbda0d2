"""The regime map's figures as PNG bytes: PSNR heatmaps over lux × image speed, the S+E − F+E difference with its
0 dB line drawn on cell edges (:func:`sign_boundary`), and PSNR against bandwidth per cell with the Pareto front.

Rows are speed factors (labelled with the measured image speed in px/s), columns light levels in lux. Every
number drawn is also in ``leaderboard_regime.csv`` and the markdown table.
"""

from __future__ import annotations

import math

import numpy as np

from simspad.evaluate.leaderboard.board import Board, method_label
from simspad.evaluate.leaderboard.plots import _pyplot, figure_png, method_styles, plot_text
from simspad.evaluate.leaderboard.regime import (
    FRAMES_EVENTS,
    SPAD_EVENTS,
    Regime,
    cell_points,
    pareto_front,
)


def _axes_labels(ax, regime: Regime) -> None:
    ax.set_xticks(range(len(regime.luxes)), [f"{lux:g}" for lux in regime.luxes], fontsize=7)
    ax.set_yticks(range(len(regime.speeds)), [regime.speed_label(k) for k in regime.speeds], fontsize=7)
    ax.set_xlabel("scene illuminance (lx)", fontsize=8)
    ax.set_ylabel("speed factor (median image speed, px/s)", fontsize=8)


def _annotate(ax, grid: np.ndarray, fmt: str) -> None:
    for (i, j), v in np.ndenumerate(grid):
        if math.isfinite(v):
            ax.text(j, i, format(v, fmt), ha="center", va="center", fontsize=7,
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.6})


def plot_regime_heatmaps(board: Board, regime: Regime) -> bytes:
    """One PSNR heatmap (dB, shared colour scale) per method over lux × speed."""
    plt = _pyplot()
    n = len(regime.methods)
    ncols = min(4, n)
    nrows = -(-n // ncols)
    h = max(1.6, 0.55 * len(regime.speeds) + 1.3)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.4 * ncols, h * nrows + 0.6), squeeze=False,
                             constrained_layout=True)
    grids = [regime.grid(m) for m in regime.methods]
    # the colour scale spans the ranked methods (a partial one's few cells, drawn clipped, cannot stretch it)
    scaled = [g for m, g in zip(regime.methods, grids) if m in regime.ranked] or grids
    finite = np.concatenate([g[np.isfinite(g)] for g in scaled] + [np.empty(0)])
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    im = None
    for ax, m, g in zip(axes.flat, regime.methods, grids):
        im = ax.imshow(g, cmap="viridis", vmin=vmin, vmax=vmax, aspect="auto", origin="lower")
        _annotate(ax, g, ".1f")
        _axes_labels(ax, regime)
        ax.set_title(plot_text(method_label(board, m)), fontsize=8)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="PSNR (dB), mean over scenes")
    fig.suptitle("PSNR over light level × image speed", fontsize=10)
    return figure_png(fig)


def sign_boundary(diff: np.ndarray) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The 0 dB line of a cell grid [row, col] drawn on cell edges: the edge between two adjacent finite cells of
    opposite sign (one > 0, the other < 0), as ((x0, y0), (x1, y1)) in image coordinates (cell centres at
    integers). Cells are measurements, not samples of a smooth field: a line through their interiors (an
    interpolated contour) would claim a crossing inside a cell that nothing measured."""
    out = []
    rows, cols = diff.shape
    for i in range(rows):
        for j in range(cols):
            v = diff[i, j]
            if j + 1 < cols and v * diff[i, j + 1] < 0:  # NaN compares False: no edge next to a missing cell
                out.append(((j + 0.5, i - 0.5), (j + 0.5, i + 0.5)))
            if i + 1 < rows and v * diff[i + 1, j] < 0:
                out.append(((j - 0.5, i + 0.5), (j + 0.5, i + 0.5)))
    return out


def plot_spad_minus_frames(regime: Regime) -> bytes | None:
    """Best S+E − best F+E PSNR (dB) over lux × speed, with the 0 dB contour; None without both pairs."""
    diff = regime.spad_minus_frames()
    if diff is None:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, max(2.2, 0.6 * len(regime.speeds) + 1.6)), constrained_layout=True)
    lim = float(np.nanmax(np.abs(diff))) if np.isfinite(diff).any() else 1.0
    lim = lim if lim > 0 else 1.0
    im = ax.imshow(diff, cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto", origin="lower")
    _annotate(ax, diff, "+.1f")
    _axes_labels(ax, regime)
    title = f"best {SPAD_EVENTS} − best {FRAMES_EVENTS} (dB); red: {SPAD_EVENTS} wins"
    segments = sign_boundary(diff)
    for (x0, y0), (x1, y1) in segments:
        ax.plot([x0, x1], [y0, y1], color="k", linewidth=1.8, solid_capstyle="projecting")
    if segments:
        title += "; black line: where the winner changes"
    ax.set_title(title, fontsize=8)
    fig.colorbar(im, ax=ax, label="PSNR difference (dB)")
    return figure_png(fig)


def plot_pareto_cells(board: Board, regime: Regime) -> bytes:
    """PSNR against bandwidth in every (lux, speed) cell; Pareto-optimal methods ringed and joined."""
    plt = _pyplot()
    styles = method_styles(board)
    nr, nc = len(regime.speeds), len(regime.luxes)
    fig, axes = plt.subplots(nr, nc, figsize=(2.6 * nc + 2.6, 2.3 * nr + 0.6), squeeze=False, sharex=True,
                             constrained_layout=True)
    for i, k in enumerate(regime.speeds):
        for j, lux in enumerate(regime.luxes):
            ax = axes[nr - 1 - i, j]  # fastest speed on top, as on the heatmaps
            pts = cell_points(regime, lux, k, ranked_only=False)  # partial methods drawn, never on the front
            front = pareto_front(cell_points(regime, lux, k))
            for m, (b, q) in pts.items():
                st = styles[m]
                ax.plot([b], [q], st["marker"], color=st["color"], markersize=6,
                        markeredgecolor="k" if m in front else st["color"], markeredgewidth=1.4 if m in front else 0.5)
            if front:
                fp = sorted(pts[m] for m in front)
                ax.step([p[0] for p in fp], [p[1] for p in fp], where="post", color="k", lw=0.8, alpha=0.6)
            ax.set_xscale("log")
            ax.grid(True, which="both", alpha=0.3)
            ax.tick_params(labelsize=7)
            ax.set_title(f"{lux:g} lx, {regime.speed_label(k)}", fontsize=7)
            if j == 0:
                ax.set_ylabel("PSNR (dB)", fontsize=7)
            if i == 0:
                ax.set_xlabel("bandwidth (kHz per pixel)", fontsize=7)
    handles = [plt.Line2D([], [], linestyle="", marker=styles[m]["marker"], color=styles[m]["color"],
                          label=plot_text(method_label(board, m))) for m in regime.methods]
    handles.append(plt.Line2D([], [], linestyle="-", color="k", marker="o", markerfacecolor="none",
                              label="Pareto front (ringed)"))
    fig.legend(handles=handles, loc="outside right upper", fontsize=7)
    fig.suptitle("PSNR against bandwidth per cell", fontsize=10)
    return figure_png(fig)
