"""The leaderboard's figures as PNG bytes: PSNR versus lux, PSNR versus bandwidth, and image strips.

Every user-supplied string drawn on a figure has its ``$`` escaped (:func:`plot_text`), so matplotlib never
parses it as mathtext.
"""

from __future__ import annotations

import io
import math

import numpy as np
from PIL import Image

from simspad.evaluate.leaderboard.board import Board, lux_levels, lux_means, method_label

#: Most recordings shown as image strips (spread evenly over the sorted recordings).
MAX_STRIPS = 15


def _pyplot():
    """matplotlib.pyplot with the non-interactive Agg backend."""
    import matplotlib  # deferred: matplotlib is slow to import and only the figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after choosing the backend

    return plt


def plot_text(text: str) -> str:
    """``text`` with ``$`` escaped (never mathtext)."""
    return str(text).replace("$", r"\$")


def figure_png(fig) -> bytes:
    """The figure as PNG bytes (no software tag, so the bytes do not depend on the matplotlib version); closes it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    _pyplot().close(fig)
    return buf.getvalue()


def plot_psnr_vs_lux(board: Board) -> bytes:
    """Mean PSNR over scenes versus scene illuminance, one line per method."""
    plt = _pyplot()
    means = lux_means(board)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for m in board.methods:
        luxes = [l for l in lux_levels(board) if math.isfinite(means[m][l])]
        if luxes:
            ax.plot(luxes, [means[m][l] for l in luxes], "o-", label=plot_text(method_label(board, m)))
    ax.set_xscale("log")
    ax.set_xlabel("scene illuminance (lx)")
    ax.set_ylabel("PSNR (dB), mean over scenes")
    ax.set_title("PSNR versus light level")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return figure_png(fig)


def plot_psnr_vs_bandwidth(board: Board) -> bytes:
    """Mean PSNR over recordings versus mean bandwidth, one point per method."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for m in board.methods:
        i = board.info[m]
        bw, p = i["bw_khz_mean"], i["psnr_mean"]
        if math.isfinite(bw) and math.isfinite(p) and bw > 0:
            ax.plot([bw], [p], "o", markersize=8, label=plot_text(method_label(board, m)))
            ax.annotate(plot_text(i["label"]), (bw, p), textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("bandwidth (kHz per pixel)")
    ax.set_ylabel("PSNR (dB), mean over recordings")
    ax.set_title("PSNR versus bandwidth")
    ax.grid(True, which="both", alpha=0.3)
    if ax.lines:
        ax.legend(fontsize=8)
    return figure_png(fig)


def strip_keys(board: Board) -> list[tuple[str, float, str]]:
    """(scene, lux, recording) of the recordings shown as image strips (at most MAX_STRIPS, spread evenly)."""
    recs = sorted({(r["scene"], float(r["lux"]), r["recording"]) for r in board.rows})
    if len(recs) > MAX_STRIPS:
        recs = [recs[i] for i in np.linspace(0, len(recs) - 1, MAX_STRIPS).round().astype(int)]
    return recs


def strip_png(board: Board, recording: str, scene: str, lux: float) -> bytes | None:
    """GT beside each method at the chosen instant, from the crops saved by evaluate/score."""
    plt = _pyplot()

    panels = []
    gt = None
    for m in board.methods:
        src = board.sources.get((m, recording))
        row = next((r for r in board.rows if r["method"] == m and r["recording"] == recording), None)
        if src is None or row is None or not row.get("image"):
            continue
        pair = src / row["image"]
        one = pair.with_name(pair.name[: -len("_vs_gt.png")] + ".png")
        if gt is None and (one.parent / "gt.png").is_file():
            gt = np.asarray(Image.open(one.parent / "gt.png"))
        if one.is_file():
            panels.append((method_label(board, m), np.asarray(Image.open(one))))
    if gt is None or not panels:
        return None
    n = 1 + len(panels)
    h, w = gt.shape[:2]
    fig, axes = plt.subplots(1, n, figsize=(min(2.2 * n, 22), 2.4 * h / max(w, 1) + 0.5))
    for ax, (title, img) in zip(np.atleast_1d(axes), [("ground truth", gt)] + panels):
        ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(plot_text(title), fontsize=8)
        ax.axis("off")
    fig.suptitle(plot_text(f"{scene} @ {lux:g} lx"), fontsize=9)
    return figure_png(fig)
