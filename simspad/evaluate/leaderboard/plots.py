"""The leaderboard's figures as PNG bytes: PSNR versus lux, PSNR versus bandwidth, and image strips.

Every user-supplied string drawn on a figure has its ``$`` escaped (:func:`plot_text`), so matplotlib never
parses it as mathtext.
"""

from __future__ import annotations

import io
import math

import numpy as np
from PIL import Image

from simspad.evaluate.leaderboard.board import (
    Board,
    lux_levels,
    lux_means,
    mean_finite,
    method_label,
    scene_column,
)
from simspad.io.results_dir import read_csv

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


def plot_budget_fronts(board: Board, fronts: dict[float, list[tuple[str, float, float, float]]]) -> bytes | None:
    """PSNR against bandwidth per light level, one panel per lux: every method with both figures (partial ones
    hollow), the Pareto front of the ranked methods (``fronts``, from :func:`tables.budget_fronts`) ringed and
    joined by the staircase of the best PSNR within each budget. None when no lux level has a front."""
    if not any(fronts.values()):
        return None
    plt = _pyplot()
    styles = method_styles(board)
    means = lux_means(board)
    luxes = [lux for lux in lux_levels(board) if fronts.get(lux)]
    fig, axes = plt.subplots(1, len(luxes), figsize=(2.9 * len(luxes) + 2.4, 3.0), squeeze=False,
                             constrained_layout=True)
    for ax, lux in zip(axes[0], luxes):
        on_front = {m for m, *_ in fronts[lux]}
        for m in board.methods:
            b = mean_finite(board.info[m]["bw_khz_by_lux"].get(lux, []))
            q = means[m][lux]
            if not (math.isfinite(b) and math.isfinite(q) and b > 0):
                continue
            st = styles[m]
            partial = board.is_partial(m)
            ax.plot([b], [q], st["marker"], color=st["color"], markersize=6,
                    markerfacecolor="none" if partial else st["color"],
                    markeredgecolor="k" if m in on_front else st["color"], markeredgewidth=1.4 if m in on_front else 1)
        ax.step([f[1] for f in fronts[lux]], [f[3] for f in fronts[lux]], where="post", color="k", lw=0.8,
                alpha=0.6)
        ax.set_xscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.set_title(f"{lux:g} lx", fontsize=8)
        ax.set_xlabel("bandwidth budget (kHz per pixel)", fontsize=7)
    axes[0][0].set_ylabel("best PSNR within budget (dB)", fontsize=7)
    handles = [plt.Line2D([], [], linestyle="", marker=styles[m]["marker"], color=styles[m]["color"],
                          markerfacecolor="none" if board.is_partial(m) else styles[m]["color"],
                          label=plot_text(method_label(board, m))) for m in board.methods]
    handles.append(plt.Line2D([], [], linestyle="-", color="k", marker="o", markerfacecolor="none",
                              label="Pareto front of the ranked methods (ringed)"))
    fig.legend(handles=handles, loc="outside right upper", fontsize=7)
    fig.suptitle("PSNR at a bandwidth budget, per light level", fontsize=10)
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


def strip_instant_s(board: Board, recording: str) -> float:
    """The instant (s) the strip of ``recording`` shows: the frame evaluate and score save as images (the middle
    evaluation instant, ``n_frames // 2``), read from a source directory's ``frames.csv``; NaN when none has it."""
    for m in board.methods:
        row = next((r for r in board.rows if r["method"] == m and r["recording"] == recording
                    and not r.get("error")), None)
        src = board.sources.get((m, recording))
        if row is None or src is None or not (src / "frames.csv").is_file():
            continue
        frame = int(row.get("n_frames", 0)) // 2
        for f in _frames_csv(src / "frames.csv"):
            if f.get("method") == m and f.get("recording") == recording and f.get("frame") == frame:
                t = f.get("t_s")
                if isinstance(t, float) and math.isfinite(t):
                    return t
    return float("nan")


def _frames_csv(path) -> list[dict]:
    try:
        return read_csv(path)
    except (OSError, UnicodeDecodeError, ValueError):
        return []


def strip_title(board: Board, recording: str) -> str:
    """``fan ×16 @ 1 lx, t = 15.0 ms (recordings/fan/fan_1lx_x16.h5)``: scene, speed, light level, instant shown."""
    row = next(r for r in board.rows if r["recording"] == recording)
    t = strip_instant_s(board, recording)
    when = f", t = {1e3 * t:.1f} ms" if math.isfinite(t) else ""
    return f"{scene_column(row)} @ {float(row['lux']):g} lx{when} ({recording})"


def strip_png(board: Board, recording: str, scene: str, lux: float, title: str | None = None) -> bytes | None:
    """GT beside each method at the chosen instant, from the crops saved by evaluate/score; ``title`` above it
    (default: scene and lux)."""
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
    fig.suptitle(plot_text(title or f"{scene} @ {lux:g} lx"), fontsize=9)
    return figure_png(fig)
