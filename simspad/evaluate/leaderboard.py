"""``simspad leaderboard``: merge results directories into a leaderboard (markdown, CSV, self-contained HTML).

Input: one or more results directories written by ``simspad evaluate`` or ``simspad score`` (``results.csv``,
``images/``). When two directories score the same method on the same recording, the later one wins.

Output (in ``--out``, default the first results directory):

- ``leaderboard.md``   the table (methods × scenes × lux, PSNR in dB, with bandwidth), the mean PSNR per lux
                       level, the plots and the image strips as PNG files beside it;
- ``leaderboard.csv``  the same table, one row per method, one column per (scene, lux);
- ``leaderboard.html`` one file with everything embedded (plots and strips as base64 PNG, inline CSS, no
                       script and no external asset).

Best value per column is marked (bold; highest PSNR, lowest bandwidth). Methods scored without absolute scale
(after the log-affine alignment of DESIGN §8) are marked †. Every user-supplied string (method names, labels,
scenes, sensors, error messages) is escaped with :func:`html.escape` in HTML and markdown (and ``|``
in markdown cells; ``$`` in plot text so matplotlib never parses it as mathtext).
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simspad.errors import SimSpadError
from simspad.io.atomic import atomic_path, ensure_writable_dir
from simspad.io.results_dir import read_csv, slug

DAGGER = "†"
MAX_STRIPS = 15


@dataclass
class Board:
    """The merged results: rows, methods (in ranking order), (scene, lux) columns and per-method info."""

    rows: list[dict]
    methods: list[str]
    columns: list[tuple[str, float]]
    info: dict[str, dict]
    psnr: dict[tuple[str, str, float], float]
    sources: dict[tuple[str, str], Path]
    mtf50: dict[tuple[str, str, float], float]


def load_results(results_dirs) -> list[tuple[dict, Path]]:
    """Rows of every ``results.csv`` with the directory they came from; later directories override."""
    merged: dict[tuple[str, str], tuple[dict, Path]] = {}
    for d in results_dirs:
        d = Path(d)
        csv_path = d / "results.csv"
        if not csv_path.is_file():
            raise SimSpadError("not a results directory (results.csv missing)", path=d)
        try:
            rows = read_csv(csv_path)
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise SimSpadError(f"unreadable ({exc})", path=csv_path) from None
        for i, r in enumerate(rows):
            for col in ("method", "scene", "lux", "psnr_db", "recording"):
                if col not in r:
                    raise SimSpadError("column missing", path=csv_path, field=col)
            merged[(r["method"], r["recording"])] = (r, d)
    if not merged:
        raise SimSpadError("no results rows", path=Path(results_dirs[0]))
    return list(merged.values())


def _mean(values) -> float:
    v = [x for x in values if isinstance(x, float) and math.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def build_board(results_dirs) -> Board:
    loaded = load_results(results_dirs)
    rows = [r for r, _ in loaded]
    sources = {(r["method"], r["recording"]): d for r, d in loaded}
    info: dict[str, dict] = {}
    per_cell: dict[tuple[str, str, float], list[float]] = defaultdict(list)
    for r in rows:
        m = info.setdefault(r["method"], {"label": r.get("label") or r["method"], "sensors": r.get("sensors", ""),
                                          "absolute_scale": r.get("absolute_scale", True), "bw_khz": [],
                                          "bw_bits": [], "psnr": [], "ssim": [], "errors": [],
                                          "bw_khz_by_lux": defaultdict(list), "bw_bits_by_lux": defaultdict(list)})
        if r.get("error"):
            m["errors"].append(r["error"])
            continue
        per_cell[(r["method"], r["scene"], float(r["lux"]))].append(r["psnr_db"])
        m["bw_khz"].append(r.get("bandwidth_khz_per_pixel", float("nan")))
        m["bw_bits"].append(r.get("bandwidth_bits_per_pixel_s", float("nan")))
        m["bw_khz_by_lux"][float(r["lux"])].append(r.get("bandwidth_khz_per_pixel", float("nan")))
        m["bw_bits_by_lux"][float(r["lux"])].append(r.get("bandwidth_bits_per_pixel_s", float("nan")))
        m["psnr"].append(r["psnr_db"])
        m["ssim"].append(r.get("ssim", float("nan")))
    psnr = {k: _mean(v) for k, v in per_cell.items()}
    mtf = {(r["method"], r["scene"], float(r["lux"])): r.get("mtf50_cyc_px", float("nan")) for r in rows
           if not r.get("error") and math.isfinite(r.get("mtf50_cyc_px", float("nan")))}
    columns = sorted({(r["scene"], float(r["lux"])) for r in rows})
    for m in info.values():
        m["bw_khz_mean"] = _mean(m["bw_khz"])
        m["bw_bits_mean"] = _mean(m["bw_bits"])
        m["psnr_mean"] = _mean(m["psnr"])
        m["ssim_mean"] = _mean(m["ssim"])
    methods = sorted(info, key=lambda k: (-(info[k]["psnr_mean"]) if math.isfinite(info[k]["psnr_mean"])
                                          else math.inf, k))
    return Board(rows, methods, columns, info, psnr, sources, mtf)


def _best(values: dict[str, float], higher: bool = True) -> set[str]:
    finite = {k: v for k, v in values.items() if math.isfinite(v)}
    if not finite:
        return set()
    target = max(finite.values()) if higher else min(finite.values())
    return {k for k, v in finite.items() if v == target}


def _label(board: Board, method: str) -> str:
    i = board.info[method]
    return f"{i['label']}{'' if i['absolute_scale'] else ' ' + DAGGER}"


def _f(v: float, digits: int = 2) -> str:
    return f"{v:.{digits}f}" if isinstance(v, float) and math.isfinite(v) else "–"


def _bw(v: float) -> str:
    if not (isinstance(v, float) and math.isfinite(v)):
        return "–"
    return f"{v:.3g}" if v < 1000 else f"{v:.0f}"


def _lux_levels(board: Board) -> list[float]:
    return sorted({lux for _, lux in board.columns})


def _lux_means(board: Board) -> dict[str, dict[float, float]]:
    out: dict[str, dict[float, float]] = {}
    for m in board.methods:
        out[m] = {lux: _mean([board.psnr.get((m, s, l), float("nan")) for s, l in board.columns if l == lux])
                  for lux in _lux_levels(board)}
    return out


# -- tables -----------------------------------------------------------------------------------------------------

def summary_cells(board: Board):
    """The summary table: each method's bandwidth and mean PSNR / SSIM over all recordings."""
    header = ["Method", "Sensors", "Bandwidth (kHz/px)", "Bits/px/s", "Mean PSNR (dB)", "Mean SSIM"]
    best = [_best({m: board.info[m][k] for m in board.methods}, higher=h)
            for k, h in (("bw_khz_mean", False), ("bw_bits_mean", False), ("psnr_mean", True), ("ssim_mean", True))]
    body = []
    for m in board.methods:
        i = board.info[m]
        body.append([(_label(board, m), False), (i["sensors"], False), (_bw(i["bw_khz_mean"]), m in best[0]),
                     (_bw(i["bw_bits_mean"]), m in best[1]), (_f(i["psnr_mean"]), m in best[2]),
                     (_f(i["ssim_mean"], 3), m in best[3])])
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
        return _mean(i[bw_key if kind == "khz" else "bw_bits_by_lux"].get(lux, []))

    def mean_psnr(m):
        return _mean([board.psnr.get((m, s, l), float("nan")) for s, l in columns])

    header = ["Method", "Sensors", "Bandwidth (kHz/px)", "Bits/px/s"] + \
        [s if lux is not None else f"{s} @ {l:g} lx" for s, l in columns] + ["Mean PSNR"]
    best_cols = [_best({m: board.psnr.get((m, s, l), float("nan")) for m in board.methods}) for s, l in columns]
    best_bw = _best({m: bandwidth(m, "khz") for m in board.methods}, higher=False)
    best_bits = _best({m: bandwidth(m, "bits") for m in board.methods}, higher=False)
    best_mean = _best({m: mean_psnr(m) for m in board.methods})
    body = []
    for m in board.methods:
        cells = [(_label(board, m), False), (board.info[m]["sensors"], False),
                 (_bw(bandwidth(m, "khz")), m in best_bw), (_bw(bandwidth(m, "bits")), m in best_bits)]
        cells += [(_f(board.psnr.get((m, s, l), float("nan"))), m in best_cols[j]) for j, (s, l) in enumerate(columns)]
        cells.append((_f(mean_psnr(m)), m in best_mean))
        body.append(cells)
    return header, body


def _md_escape(text: str) -> str:
    return html.escape(str(text)).replace("|", "\\|").replace("\n", " ")


def _md_table(header, body, text_columns: int = 2) -> str:
    lines = ["| " + " | ".join(_md_escape(h) for h in header) + " |",
             "|" + "|".join(["---"] * text_columns + ["---:"] * (len(header) - text_columns)) + "|"]
    for row in body:
        lines.append("| " + " | ".join(f"**{_md_escape(t)}**" if b and t != "–" else _md_escape(t)
                                      for t, b in row) + " |")
    return "\n".join(lines)


def lux_table(board: Board):
    luxes = _lux_levels(board)
    means = _lux_means(board)
    best = [_best({m: means[m][l] for m in board.methods}) for l in luxes]
    header = ["Method"] + [f"{l:g} lx" for l in luxes]
    body = [[(_label(board, m), False)] + [(_f(means[m][l]), m in best[j]) for j, l in enumerate(luxes)]
            for m in board.methods]
    return header, body


def mtf_table(board: Board):
    """MTF50 (cycles/px) of the Siemens-star recordings, or None when there are none."""
    cols = sorted({(s, l) for _, s, l in board.mtf50})
    if not cols:
        return None
    best = [_best({m: board.mtf50.get((m, s, l), float("nan")) for m in board.methods}) for s, l in cols]
    header = ["Method"] + [f"{s} @ {l:g} lx" for s, l in cols]
    body = [[(_label(board, m), False)] + [(_f(board.mtf50.get((m, s, l), float("nan")), 3), m in best[j])
                                           for j, (s, l) in enumerate(cols)] for m in board.methods]
    return header, body


MTF_NOTE = ("MTF50 in cycles per pixel relative to the ground truth (0.5 = stays above half contrast up to "
            "Nyquist; – = already below 0.5 at the lowest measured frequency, or no star).")


def write_csv_table(path: Path, board: Board) -> None:
    import csv

    cols = ["method", "label", "sensors", "absolute_scale", "bandwidth_khz_per_pixel",
            "bandwidth_bits_per_pixel_s"] + [f"psnr_db[{s}@{l:g}lx]" for s, l in board.columns] + \
        ["mean_psnr_db", "mean_ssim", "errors"]
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for m in board.methods:
            i = board.info[m]
            w.writerow([m, i["label"], i["sensors"], "true" if i["absolute_scale"] else "false",
                        i["bw_khz_mean"], i["bw_bits_mean"]] +
                       [board.psnr.get((m, s, l), float("nan")) for s, l in board.columns] +
                       [i["psnr_mean"], i["ssim_mean"], len(i["errors"])])


# -- plots ------------------------------------------------------------------------------------------------------

def _plot_text(text: str) -> str:
    return str(text).replace("$", r"\$")


def _figure_png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    import matplotlib.pyplot as plt

    plt.close(fig)
    return buf.getvalue()


def plot_psnr_vs_lux(board: Board) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    means = _lux_means(board)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for m in board.methods:
        luxes = [l for l in _lux_levels(board) if math.isfinite(means[m][l])]
        if luxes:
            ax.plot(luxes, [means[m][l] for l in luxes], "o-", label=_plot_text(_label(board, m)))
    ax.set_xscale("log")
    ax.set_xlabel("scene illuminance (lx)")
    ax.set_ylabel("PSNR (dB), mean over scenes")
    ax.set_title("PSNR versus light level")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _figure_png(fig)


def plot_psnr_vs_bandwidth(board: Board) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for m in board.methods:
        i = board.info[m]
        bw, p = i["bw_khz_mean"], i["psnr_mean"]
        if math.isfinite(bw) and math.isfinite(p) and bw > 0:
            ax.plot([bw], [p], "o", markersize=8, label=_plot_text(_label(board, m)))
            ax.annotate(_plot_text(i["label"]), (bw, p), textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("bandwidth (kHz per pixel)")
    ax.set_ylabel("PSNR (dB), mean over recordings")
    ax.set_title("PSNR versus bandwidth")
    ax.grid(True, which="both", alpha=0.3)
    if ax.lines:
        ax.legend(fontsize=8)
    return _figure_png(fig)


def _strip_keys(board: Board) -> list[tuple[str, float, str]]:
    """(scene, lux, recording) of the recordings shown as image strips (at most MAX_STRIPS, spread evenly)."""
    recs = sorted({(r["scene"], float(r["lux"]), r["recording"]) for r in board.rows})
    if len(recs) > MAX_STRIPS:
        recs = [recs[i] for i in np.linspace(0, len(recs) - 1, MAX_STRIPS).round().astype(int)]
    return recs


def strip_png(board: Board, recording: str, scene: str, lux: float) -> bytes | None:
    """GT beside each method at the chosen instant, from the crops saved by evaluate/score."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

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
            panels.append((_label(board, m), np.asarray(Image.open(one))))
    if gt is None or not panels:
        return None
    n = 1 + len(panels)
    h, w = gt.shape[:2]
    fig, axes = plt.subplots(1, n, figsize=(min(2.2 * n, 22), 2.4 * h / max(w, 1) + 0.5))
    for ax, (title, img) in zip(np.atleast_1d(axes), [("ground truth", gt)] + panels):
        ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(_plot_text(title), fontsize=8)
        ax.axis("off")
    fig.suptitle(_plot_text(f"{scene} @ {lux:g} lx"), fontsize=9)
    return _figure_png(fig)


# -- writers ----------------------------------------------------------------------------------------------------

_CSS = """body{font-family:system-ui,Helvetica,Arial,sans-serif;margin:24px;color:#222;background:#fff}
table{border-collapse:collapse;margin:12px 0;font-size:13px}th,td{border:1px solid #bbb;padding:4px 8px}
th{background:#eef2f7}td.num{text-align:right;font-variant-numeric:tabular-nums}td.best{background:#d9f2d9;
font-weight:bold}img{max-width:100%;border:1px solid #ddd;margin:6px 0}h1{font-size:22px}h2{font-size:17px;
margin-top:28px}.note{color:#555;font-size:12px}.plots{display:flex;flex-wrap:wrap;gap:12px}
.plots img{max-width:48%}"""


def _html_table(header, body) -> str:
    out = ["<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for row in body:
        cells = []
        for j, (t, best) in enumerate(row):
            cls = ("num" if j > 0 and _is_number(t) else "") + (" best" if best and t != "–" else "")
            cells.append(f"<td class=\"{cls.strip()}\">{html.escape(t)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return text == "–"
    return True


def _img_tag(png: bytes, alt: str) -> str:
    return f"<img alt=\"{html.escape(alt)}\" src=\"data:image/png;base64,{base64.b64encode(png).decode()}\">"


def _errors(board: Board) -> list[tuple[str, str]]:
    return [(board.info[m]["label"], e) for m in board.methods for e in board.info[m]["errors"]]


def render_html(board: Board, plots: dict[str, bytes], strips: list[tuple[str, bytes]]) -> str:
    lheader, lbody = lux_table(board)
    parts = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
             "<title>SimSPAD leaderboard</title>", f"<style>{_CSS}</style></head><body>",
             "<h1>SimSPAD leaderboard</h1>",
             "<p class=\"note\">PSNR in dB (display-mapped: white point = 99th percentile of ground truth, sRGB "
             f"curve; DESIGN §8). Best per column in bold. {DAGGER} scored after a per-frame least-squares "
             "affine fit in log space (no absolute scale). Bandwidth: mean over recordings.</p>",
             "<h2>Summary over all recordings</h2>", _html_table(*summary_cells(board)),
             "<h2>Mean PSNR per light level (dB)</h2>", _html_table(lheader, lbody),
             "<h2>Methods × scenes at each light level (PSNR, dB)</h2>"]
    for lux in _lux_levels(board):
        parts += [f"<h3>{lux:g} lx</h3>", _html_table(*table_cells(board, lux))]
    mt = mtf_table(board)
    if mt is not None:
        parts += ["<h2>Siemens star: MTF50</h2>", f"<p class=\"note\">{html.escape(MTF_NOTE)}</p>", _html_table(*mt)]
    parts.append("<h2>Plots</h2>")
    parts.append("<div class=\"plots\">" + "".join(_img_tag(png, name) for name, png in plots.items()) + "</div>")
    if strips:
        parts.append("<h2>Reconstructions at the chosen instant (ground truth first)</h2>")
        for title, png in strips:
            parts.append(f"<h3>{html.escape(title)}</h3>{_img_tag(png, title)}")
    errs = _errors(board)
    if errs:
        parts.append("<h2>Failed runs</h2><ul>" + "".join(
            f"<li>{html.escape(m)}: {html.escape(e)}</li>" for m, e in errs) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def render_markdown(board: Board, plot_files: dict[str, str], strip_files: list[tuple[str, str]]) -> str:
    lheader, lbody = lux_table(board)
    out = ["# SimSPAD leaderboard", "",
           f"PSNR in dB (DESIGN §8 display mapping). Best per column in bold. {DAGGER}: scored after a per-frame "
           "least-squares affine fit in log space (no absolute scale). Bandwidth: mean over recordings.", "",
           "## Summary over all recordings", "", _md_table(*summary_cells(board)), "",
           "## Mean PSNR per light level (dB)", "", _md_table(lheader, lbody, 1), "",
           "## Methods × scenes at each light level (PSNR, dB)", ""]
    for lux in _lux_levels(board):
        out += [f"### {lux:g} lx", "", _md_table(*table_cells(board, lux)), ""]
    mt = mtf_table(board)
    if mt is not None:
        out += ["## Siemens star: MTF50", "", _md_escape(MTF_NOTE), "", _md_table(*mt, 1), ""]
    out += ["## Plots", ""]
    out += [f"![{_md_escape(name)}]({f})" for name, f in plot_files.items()]
    if strip_files:
        out += ["", "## Reconstructions at the chosen instant (ground truth first)", ""]
        out += [f"![{_md_escape(t)}]({f})" for t, f in strip_files]
    errs = _errors(board)
    if errs:
        out += ["", "## Failed runs", ""] + [f"- {_md_escape(m)}: {_md_escape(e)}" for m, e in errs]
    return "\n".join(out) + "\n"


def _write_bytes(path: Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def build_leaderboard(results_dirs, out_dir=None) -> Path:
    """Write leaderboard.md/.csv/.html (and the PNGs the markdown links) into ``out_dir``; return the HTML path."""
    results_dirs = [Path(d) for d in results_dirs]
    if not results_dirs:
        raise SimSpadError("at least one results directory is required", field="RESULTS_DIR")
    out_dir = ensure_writable_dir(Path(out_dir) if out_dir is not None else results_dirs[0])
    board = build_board(results_dirs)
    plots = {"PSNR versus lux": plot_psnr_vs_lux(board), "PSNR versus bandwidth": plot_psnr_vs_bandwidth(board)}
    plot_files = {}
    for name, png in plots.items():
        fname = f"leaderboard_{slug(name.lower().replace(' ', '_'))}.png"
        _write_bytes(out_dir / fname, png)
        plot_files[name] = fname
    strips, strip_files = [], []
    for scene, lux, rec in _strip_keys(board):
        png = strip_png(board, rec, scene, lux)
        if png is None:
            continue
        title = f"{scene} @ {lux:g} lx ({rec})"
        strips.append((title, png))
        fname = f"leaderboard_strips/{slug(Path(rec).stem)}.png"
        (out_dir / "leaderboard_strips").mkdir(exist_ok=True)
        _write_bytes(out_dir / fname, png)
        strip_files.append((title, fname))
    with atomic_path(out_dir / "leaderboard.csv") as tmp:
        write_csv_table(tmp, board)
    with atomic_path(out_dir / "leaderboard.md") as tmp:
        tmp.write_text(render_markdown(board, plot_files, strip_files), encoding="utf-8")
    html_path = out_dir / "leaderboard.html"
    with atomic_path(html_path) as tmp:
        tmp.write_text(render_html(board, plots, strips), encoding="utf-8")
    return html_path


def leaderboard_from_cli(results_dirs, out_dir=None) -> Path:
    """The ``simspad leaderboard`` command; prints the leaderboard's path last."""
    import click

    path = build_leaderboard(results_dirs, out_dir)
    click.echo(f"wrote {path.with_suffix('.md')} and {path.with_suffix('.csv')}")
    click.echo(f"leaderboard: {path}")
    return path
