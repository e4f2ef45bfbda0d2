"""The leaderboard's tables: cells of (text, is_best) for the renderers, and ``leaderboard.csv``.

Best value per column is marked among the methods scored on every recording of the board (:func:`best_ranked`):
highest PSNR, SSIM and MTF, lowest bandwidth. :func:`budget_tables` ranks by PSNR at a bandwidth budget, per light
level (the Pareto front of PSNR against bandwidth). Texts are unescaped; the HTML and markdown renderers escape
them.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

from simspad.evaluate.metrics import STAR_FREQS_CYC_PX
from simspad.io import csv_cells
from simspad.evaluate.leaderboard.board import (
    Board,
    best_ranked,
    fmt_bandwidth,
    fmt_number,
    lux_levels,
    lux_means,
    mean_finite,
    method_label,
)
from simspad.evaluate.leaderboard.regime import pareto_front


def summary_cells(board: Board):
    """The summary table: each method's bandwidth and mean PSNR / SSIM over all recordings."""
    header = ["Rank", "Method", "Sensors", "Recordings", "Bandwidth (kHz/px)", "Bits/px/s", "Mean PSNR (dB)",
              "Mean SSIM"]
    best = [best_ranked(board, {m: board.info[m][k] for m in board.methods}, higher=h)
            for k, h in (("bw_khz_mean", False), ("bw_bits_mean", False), ("psnr_mean", True), ("ssim_mean", True))]
    body = []
    ranked = board.ranked()
    for m in board.methods:
        i = board.info[m]
        rank = str(ranked.index(m) + 1) if m in ranked else "–"
        body.append([(rank, False), (method_label(board, m), False), (i["sensors"], False),
                     (f"{board.coverage(m)}/{len(board.recordings)}", False),
                     (fmt_bandwidth(i["bw_khz_mean"]), m in best[0]), (fmt_bandwidth(i["bw_bits_mean"]), m in best[1]),
                     (fmt_number(i["psnr_mean"]), m in best[2]),
                     (fmt_number(i["ssim_mean"], 3), m in best[3])])
    return header, body


def table_cells(board: Board, lux: float | None = None):
    """Methods × scenes (PSNR, dB) with bandwidth, at one light level (``lux``) or over all (scene, lux) columns.

    Cells are (text, is_best) with the text unescaped; best = highest PSNR, lowest bandwidth.
    """
    columns = [(s, l) for s, l in board.columns if lux is None or l == lux]
    bw_key = "bw_khz_by_lux" if lux is not None else None

    def bandwidth(m, kind):
        i = board.info[m]
        if lux is None:
            return i["bw_khz_mean"] if kind == "khz" else i["bw_bits_mean"]
        return mean_finite(i[bw_key if kind == "khz" else "bw_bits_by_lux"].get(lux, []))

    def mean_psnr(m):
        return mean_finite([board.psnr.get((m, s, l), float("nan")) for s, l in columns])

    header = ["Method", "Sensors", "Bandwidth (kHz/px)", "Bits/px/s"] + \
        [s if lux is not None else f"{s} @ {l:g} lx" for s, l in columns] + ["Mean PSNR"]
    best_cols = [best_ranked(board, {m: board.psnr.get((m, s, l), float("nan")) for m in board.methods})
                 for s, l in columns]
    best_bw = best_ranked(board, {m: bandwidth(m, "khz") for m in board.methods}, higher=False)
    best_bits = best_ranked(board, {m: bandwidth(m, "bits") for m in board.methods}, higher=False)
    best_mean = best_ranked(board, {m: mean_psnr(m) for m in board.methods})
    body = []
    for m in board.methods:
        cells = [(method_label(board, m), False), (board.info[m]["sensors"], False),
                 (fmt_bandwidth(bandwidth(m, "khz")), m in best_bw),
                 (fmt_bandwidth(bandwidth(m, "bits")), m in best_bits)]
        cells += [(fmt_number(board.psnr.get((m, s, l), float("nan"))), m in best_cols[j])
                  for j, (s, l) in enumerate(columns)]
        cells.append((fmt_number(mean_psnr(m)), m in best_mean))
        body.append(cells)
    return header, body


def lux_table(board: Board):
    luxes = lux_levels(board)
    means = lux_means(board)
    best = [best_ranked(board, {m: means[m][l] for m in board.methods}) for l in luxes]
    header = ["Method"] + [f"{l:g} lx" for l in luxes]
    body = [[(method_label(board, m), False)] + [(fmt_number(means[m][l]), m in best[j]) for j, l in enumerate(luxes)]
            for m in board.methods]
    return header, body


def star_tables(board: Board) -> list[tuple[str, tuple]]:
    """(title, (header, body)) of each Siemens-star figure (MTF at the fixed frequencies, MTF50); [] without a star.

    Cells are methods × (scene, lux) of the star recordings; best = highest.
    """
    cols = sorted({(s, l) for (_, s, l), v in board.star.items() if v})
    if not cols:
        return []
    out = []
    for key, title in STAR_FIGURES:
        vals = {(m, s, l): board.star.get((m, s, l), {}).get(key, float("nan")) for m in board.methods
                for s, l in cols}
        best = [best_ranked(board, {m: vals[(m, s, l)] for m in board.methods}) for s, l in cols]
        header = ["Method"] + [f"{s} @ {l:g} lx" for s, l in cols]
        body = [[(method_label(board, m), False)] + [(fmt_number(vals[(m, s, l)], 3), m in best[j])
                                                     for j, (s, l) in enumerate(cols)] for m in board.methods]
        out.append((title, (header, body)))
    return out


#: The Siemens-star columns of results.csv shown on the leaderboard, with their table titles.
STAR_FIGURES = tuple((f"mtf_at_{f:.2f}_cyc_px".replace(".", "p"), f"MTF at {f:g} cycles/px")
                     for f in STAR_FREQS_CYC_PX) + (("mtf50_cyc_px", "MTF50 (cycles/px)"),)

PREAMBLE = ("PSNR in dB on display-mapped frames (white point: 99th percentile of the ground truth over the "
            "sequence; sRGB transfer curve). Best per column in bold, among the methods scored on every recording. "
            "Bandwidth: mean over recordings. Marks († and partial) are explained in the glossary at the end.")


def _text(v, fmt: str = "{}") -> str:
    """``v`` formatted with ``fmt``; – when absent or not finite; as plain text when ``fmt`` does not fit it (a
    hand-edited results.json may hold a string where a number belongs: shown, escaped by the renderers)."""
    if v is None or v == "" or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    try:
        return fmt.format(v)
    except (TypeError, ValueError):
        return str(v)


def about_cells(board: Board):
    """What this board ranks: one row per results directory (kind, dataset, spec hash, seed, SimSPAD version,
    creation time, evaluation rate); – where its ``results.json`` does not say."""
    header = ["Results", "Kind", "Dataset", "Spec hash", "Seed", "SimSPAD", "Created (UTC)", "Evaluation rate (Hz)",
              "Methods"]
    body = [[(_text(a["directory"]), False), (_text(a["kind"]), False), (_text(a["dataset"]), False),
             (_text(a["spec_hash"], "{:.12}"), False), (_text(a["seed"]), False), (_text(a["simspad_version"]), False),
             (_text(a["created_utc"]), False), (_text(a["rate_hz"], "{:g}"), False),
             (", ".join(a["methods"]) or "–", False)] for a in board.about]
    return header, body


def recording_cells(board: Board):
    """Every recording of the board: scene, speed, lux, resolution, duration, seed and render settings (samples
    per pixel, keyframe spacing); – where no ``results.json`` says."""
    header = ["Recording", "Scene", "Speed", "Lux", "Resolution (px)", "Duration (ms)", "Seed", "Render spp",
              "Convergence", "Render noise", "Keyframes ≤ px apart", "Keyframe rate ≥ (Hz)"]
    rows = {r["recording"]: r for r in board.rows}
    body = []
    for rec in board.recordings:
        i = board.recording_info.get(rec, {})
        r = rows.get(rec, {})
        k = i.get("speed_factor", r.get("speed_factor"))
        size = f"{i['width']}×{i['height']}" if "width" in i and "height" in i else "–"
        dur = i.get("duration_s")
        body.append([(rec, False), (_text(i.get("scene", r.get("scene"))), False), (_text(k, "×{:g}"), False),
                     (_text(i.get("lux", r.get("lux")), "{:g}"), False), (size, False),
                     (_text(1e3 * dur if isinstance(dur, (int, float)) else None, "{:g}"), False),
                     (_text(i.get("seed")), False), (_text(i.get("spp")), False),
                     (_text({"off": "path traced"}.get(i.get("convergence"), i.get("convergence"))), False),
                     (_text(100 * i["render_noise_relative"] if "render_noise_relative" in i else None, "{:.1f} %"),
                      False),
                     (_text(i.get("max_flow_px"), "{:g}"), False), (_text(i.get("min_rate_hz"), "{:g}"), False)])
    return header, body


ABOUT_NOTE = ("What this board ranks: the results directories merged (a later one overrides an earlier one's "
              "method on the same recording) and every recording scored, with what the results say of it. A "
              "recording's render settings are its samples per pixel, how its radiance was converged (path traced: "
              "every keyframe path-traced at that many samples), its render noise (the median per-pixel relative "
              "error of one keyframe against converged light, measured by rendering keyframe 0 twice with "
              "independent seeds: the ground truth carries it too) and the keyframe spacing (at most that many "
              "pixels of image motion between rendered keyframes, at least that rate); the ground truth is "
              "interpolated between keyframes.")


def ranking_rule(board: Board) -> str:
    """The sentence stating how the summary ranks methods, with this board's recording count."""
    n = len(board.recordings)
    return (f"Rank: the methods scored on all {n} recordings of this board, by mean PSNR over those recordings "
            "(highest first; equal means share the name order). Only they compete: every bold mark in every table "
            "is the best among them, so a column, cell or mean is only ever compared over the same recordings. "
            "A method scored on fewer recordings (partial k/N) is shown, after them, without a rank and never in "
            "bold. The rank ignores bandwidth: the best PSNR within a bandwidth budget is in the section PSNR at a "
            "bandwidth budget.")


BANDWIDTH_NOTE = ("Bandwidth: what a method reads from its sensors per pixel and second, as readouts (kHz per "
                  "pixel) and as bits (Bits/px/s), summed over the sensors it uses. A SPAD binary frame is one "
                  "1-bit readout; an aggregate of n SPAD frames one readout of ceil(log2(n + 1)) bits; a "
                  "conventional frame one readout of its bit depth (12 bits for the blackfly_s preset); an event "
                  "one 32-bit readout. Reading every SPAD frame of the SwissSPAD2 preset is 97.7 kHz and 97 656 "
                  "bits/px/s; aggregating 244 of them, 0.4 kHz and 3200 bits/px/s.")


BUDGET_NOTE = ("Per light level, the methods no other ranked method beats on both PSNR and bandwidth (the Pareto "
               "front), cheapest first: with a budget of at least the listed bandwidth, the method on that row is "
               "the best PSNR affordable. PSNR is the mean over the scenes at that level (as in the table per "
               "light level), bandwidth the mean over its recordings, kHz of readouts per pixel. Only methods "
               "scored on every recording take part. The figure PSNR at a bandwidth budget (under Plots) draws "
               "the same fronts.")


def budget_fronts(board: Board) -> dict[float, list[tuple[str, float, float, float]]]:
    """Per lux level, the Pareto front of PSNR against bandwidth among the ranked methods, cheapest first:
    ``[(method, bandwidth kHz/px, bits/px/s, PSNR dB), ...]``; PSNR increases along it."""
    means = lux_means(board)
    out = {}
    for lux in lux_levels(board):
        pts, bits = {}, {}
        for m in board.ranked():
            i = board.info[m]
            b, q = mean_finite(i["bw_khz_by_lux"].get(lux, [])), means[m][lux]
            if math.isfinite(b) and math.isfinite(q) and b > 0:
                pts[m], bits[m] = (b, q), mean_finite(i["bw_bits_by_lux"].get(lux, []))
        front = pareto_front(pts)
        out[lux] = sorted(((m, pts[m][0], bits[m], pts[m][1]) for m in front), key=lambda x: (x[1], -x[3], x[0]))
    return out


def budget_tables(board: Board) -> list[tuple[float, tuple]]:
    """(lux, (header, body)) of the PSNR-at-a-bandwidth-budget table of each light level; [] when no ranked
    method has both figures. Cells are (text, is_best) with is_best False (each row is the best at its budget)."""
    header = ["Budget ≥ (kHz/px)", "Best method within budget", "Sensors", "Bits/px/s", "PSNR (dB)"]
    out = []
    for lux, front in budget_fronts(board).items():
        if not front:
            continue
        body = [[(fmt_bandwidth(b), False), (method_label(board, m), False), (board.info[m]["sensors"], False),
                 (fmt_bandwidth(bits), False), (fmt_number(q), False)] for m, b, bits, q in front]
        out.append((lux, (header, body)))
    return out

REGIME_NOTE = ("PSNR (dB, mean over scenes) per light level and image speed. Speed rows are the dataset's speed "
               "factors, labelled with the median image speed measured in their recordings (px/s). The last row "
               "is the best SPAD + events method minus the best frames + events method: positive where SPAD + "
               "events wins. Numbers also in leaderboard_regime.csv.")

MTF_NOTE = ("Siemens star: the reconstruction's contrast relative to the ground truth's along circles around the "
            "star's centre (1 = as sharp as the ground truth). MTF at a fixed frequency tells methods apart even "
            "when they keep more than half the contrast up to Nyquist (0.5 cycles/px), where MTF50 cannot be "
            "measured. – = not measurable: a frequency below the lowest the star's outer circle carries at this "
            "resolution (n cycles / (2π × radius)), an MTF50 that is not reached by Nyquist or already passed at "
            "the lowest measured frequency, or a failed run.")


def csv_safe(value):
    """A text cell that a spreadsheet would run as a formula (``=``, ``+``, ``-``, ``@``, tab, CR first) gets a
    leading apostrophe (the OWASP rule); numbers pass unchanged: :func:`simspad.io.csv_cells.csv_safe`, the one
    rule of every CSV SimSPAD writes."""
    return csv_cells.csv_safe(value)


def csv_column(scene_column: str, lux: float) -> str:
    """The ASCII ``leaderboard.csv`` header of a (scene column, lux) PSNR column: ``psnr_db_fan_x16_100lx``.

    Spaces and other non-identifier characters become ``_``, ``×k`` becomes ``xk``, so the header is one token that
    any CSV reader, spreadsheet or dataframe library takes as written."""
    name = re.sub(r"[^A-Za-z0-9.]+", "_", scene_column.replace("×", "x")).strip("_")
    return f"psnr_db_{name}_{lux:g}lx"


def write_csv_table(path: Path, board: Board) -> None:
    cols = ["method", "label", "sensors", "absolute_scale", "bandwidth_khz_per_pixel",
            "bandwidth_bits_per_pixel_s"] + [csv_column(s, l) for s, l in board.columns] + \
        ["mean_psnr_db", "mean_ssim", "errors"]
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for m in board.methods:
            i = board.info[m]
            w.writerow([csv_safe(m), csv_safe(i["label"]), csv_safe(i["sensors"]), "true" if i["absolute_scale"] else "false",
                        i["bw_khz_mean"], i["bw_bits_mean"]] +
                       [board.psnr.get((m, s, l), float("nan")) for s, l in board.columns] +
                       [i["psnr_mean"], i["ssim_mean"], len(i["errors"])])
