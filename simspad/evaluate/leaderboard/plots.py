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


_MARKERS = "osD^vP*Xh<>p"


def method_styles(board: Board) -> dict[str, dict]:
    """A colour and marker per method (tab10 colours, then markers), the same on every figure."""
    plt = _pyplot()
    colors = plt.get_cmap("tab10").colors
    return {m: {"color": colors[i % len(colors)], "marker": _MARKERS[(i // len(colors) + i) % len(_MARKERS)]}
            for i, m in enumerate(board.methods)}


def plot_psnr_vs_lux(board: Board) -> bytes:
    """Mean PSNR over scenes versus scene illuminance, one line per method."""
    plt = _pyplot()
    means = lux_means(board)
    styles = method_styles(board)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for m in board.methods:
        luxes = [l for l in lux_levels(board) if math.isfinite(means[m][l])]
        if luxes:
            ax.plot(luxes, [means[m][l] for l in luxes], "-", marker=styles[m]["marker"], color=styles[m]["color"],
                    label=plot_text(method_label(board, m)))
    ax.set_xscale("log")
    ax.set_xlabel("scene illuminance (lx)")
    ax.set_ylabel("PSNR (dB), mean over scenes")
    ax.set_title("PSNR versus light level")
    ax.grid(True, which="both", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    else:  # every method failed (no finite PSNR): say so instead of an empty legend
        ax.text(0.5, 0.5, "no method has a finite PSNR", transform=ax.transAxes, ha="center", va="center")
    return figure_png(fig)


def plot_psnr_vs_bandwidth(board: Board) -> bytes:
    """Mean PSNR over recordings versus mean bandwidth, one point per method.

    Methods are told apart by colour and marker in a legend beside the axes, never by text next to the points:
    methods of equal bandwidth and PSNR (NEDI+AKF and its adaptive variant at full readout) would overlap.
    """
    plt = _pyplot()
    styles = method_styles(board)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for m in board.methods:
        i = board.info[m]
        bw, p = i["bw_khz_mean"], i["psnr_mean"]
        if math.isfinite(bw) and math.isfinite(p) and bw > 0:
            ax.plot([bw], [p], linestyle="", marker=styles[m]["marker"], color=styles[m]["color"], markersize=8,
                    alpha=0.85, label=plot_text(method_label(board, m)))
    ax.set_xscale("log")
    ax.set_xlabel("bandwidth (kHz per pixel)")
    ax.set_ylabel("PSNR (dB), mean over recordings")
    ax.set_title("PSNR versus bandwidth")
    ax.grid(True, which="both", alpha=0.3)
    if ax.lines:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    return figure_png(fig)


def strip_keys(board: Board) -> tuple[list[tuple[str, float, str]], str | None]:
    """(scene, lux, recording) of the recordings shown as image strips, and a note when some are left out.

    Every scene is shown at the same light levels: the levels all scenes share, spread evenly, as many as fit in
    :data:`MAX_STRIPS` strips; the note says which levels are shown and why when that is not all of them.
    """
    recs = sorted({(r["scene"], float(r["lux"]), r["recording"]) for r in board.rows})
    scenes = sorted({s for s, _, _ in recs})
    by_scene: dict[str, set[float]] = {s: set() for s in scenes}
    per_cell: dict[tuple[str, float], int] = {}
    for s, l, _ in recs:  # one pass: a results.csv of 20 000 rows took minutes with a scan per recording
        by_scene[s].add(l)
        per_cell[(s, l)] = per_cell.get((s, l), 0) + 1
    shared = sorted(set.intersection(*by_scene.values())) if by_scene else []
    per_level = max(1, max(per_cell.values())) if recs else 1
    n_levels = max(1, MAX_STRIPS // max(1, len(scenes) * per_level))
    levels = shared
    if len(shared) > n_levels:
        levels = [shared[i] for i in np.linspace(0, len(shared) - 1, n_levels).round().astype(int)]
    chosen = [x for x in recs if x[1] in set(levels)][:MAX_STRIPS]
    all_levels = sorted({l for _, l, _ in recs})
    note = None
    if levels != all_levels:
        why = [] if len(levels) == len(shared) else [f"at most {MAX_STRIPS} strips"]
        if len(shared) < len(all_levels):
            why.append("the other levels are missing for some scenes")
        note = (f"Strips show every scene at {', '.join(f'{l:g}' for l in levels) or 'no common'} lx "
                f"({'; '.join(why)}).")
    return chosen, note


def strip_png(board: Board, recording: str, scene: str, lux: float) -> bytes | None:
    """GT beside each method at the chosen instant, from the crops saved by evaluate/score."""
    plt = _pyplot()

    panels = []
    gt = None
    rows = {r["method"]: r for r in board.rows if r["recording"] == recording}
    for m in board.methods:
        src = board.sources.get((m, recording))
        row = rows.get(m)
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
