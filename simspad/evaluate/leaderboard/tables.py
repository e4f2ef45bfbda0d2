"""The leaderboard's tables: cells of (text, is_best) for the renderers, and ``leaderboard.csv``.

Best value per column is marked: highest PSNR, SSIM and MTF50, lowest bandwidth. Texts are unescaped; the HTML and
markdown renderers escape them.
"""

from __future__ import annotations

import csv
from pathlib import Path

from simspad.evaluate.metrics import STAR_FREQS_CYC_PX
from simspad.io import csv_cells
from simspad.evaluate.leaderboard.board import (
    Board,
    best_of,
    best_ranked,
    fmt_bandwidth,
    fmt_number,
    lux_levels,
    lux_means,
    mean_finite,
    method_label,
)


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
    best_cols = [best_of({m: board.psnr.get((m, s, l), float("nan")) for m in board.methods}) for s, l in columns]
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
        best = [best_of({m: vals[(m, s, l)] for m in board.methods}) for s, l in cols]
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


def write_csv_table(path: Path, board: Board) -> None:
    cols = ["method", "label", "sensors", "absolute_scale", "bandwidth_khz_per_pixel",
            "bandwidth_bits_per_pixel_s"] + [f"psnr_db[{s}@{l:g}lx]" for s, l in board.columns] + \
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
