"""Writing a leaderboard: ``leaderboard.md``, ``leaderboard.csv``, ``leaderboard_regime.csv``,
``leaderboard.html`` and the PNG files the markdown links (``leaderboard_*.png``, ``leaderboard_strips/``), each
written atomically, and the marker ``.simspad-leaderboard`` listing them (:mod:`simspad.io.output_dirs`).
"""

from __future__ import annotations

import json
from pathlib import Path

from simspad.errors import SimSpadError
from simspad.evaluate.leaderboard.board import _results_json, build_board
from simspad.evaluate.leaderboard.html_page import _html_table, render_html
from simspad.evaluate.leaderboard.markdown_page import md_escape, md_table, render_markdown
from simspad.evaluate.leaderboard.real_data import real_data_html, real_data_markdown, real_recordings
from simspad.evaluate.leaderboard.plots import (
    plot_budget_fronts,
    plot_psnr_vs_bandwidth,
    plot_psnr_vs_lux,
    strip_keys,
    strip_png,
    strip_title,
)
from simspad.evaluate.leaderboard.regime import build_regime, write_regime_csv
from simspad.evaluate.leaderboard.regime_plots import plot_pareto_cells, plot_regime_heatmaps, plot_spad_minus_frames
from simspad.evaluate.leaderboard.tables import budget_fronts, write_csv_table
from simspad.io.atomic import atomic_path
from simspad.io.output_dirs import check_no_link, claim_output_dir, owned_dir_in_place, remove_stale_files, write_marker
from simspad.io.results_dir import slug


def _legacy_output(path: Path) -> set[str] | None:
    """A folder written before markers: a leaderboard (``leaderboard.html``) or a results folder (``results.json``
    of format ``simspad-results``, or a ``results.csv`` written by another tool), where the leaderboard goes by
    default. Nothing of it is deleted: empty set."""
    if (path / "leaderboard.html").is_file() or (path / "results.csv").is_file():
        return set()
    try:
        meta = json.loads((path / "results.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return set() if isinstance(meta, dict) and meta.get("format") == "simspad-results" else None


def build_leaderboard(results_dirs, out_dir=None, preview=None) -> Path:
    """Write leaderboard.md/.csv/.html (and the PNGs the markdown links) into ``out_dir``; return the HTML path.

    ``out_dir`` (default: the first results directory) must be new, empty, a results folder or a leaderboard
    folder (:mod:`simspad.io.output_dirs`); it is locked while written, other files in it are kept, and the files
    of the previous leaderboard that this one no longer has (strips of recordings gone) are deleted.

    ``preview`` (optional): a callable ``(recording_path, out_path)`` writing a short GIF of a recording
    (``simspad.analysis.preview.write_short_preview``, passed in by the CLI: the analysis layer is a sibling of
    this one); each strip then links a preview of its recording, where the recording is found.
    """
    results_dirs = [Path(d) for d in results_dirs]
    if not results_dirs:
        raise SimSpadError("at least one results directory is required", field="RESULTS_DIR")
    out_dir = Path(out_dir) if out_dir is not None else results_dirs[0]
    previous = claim_output_dir(out_dir, "leaderboard", legacy=_legacy_output, also=("evaluate", "score")) or set()
    with owned_dir_in_place(out_dir, "leaderboard", legacy=_legacy_output, also=("evaluate", "score")):
        written = _write_leaderboard(results_dirs, out_dir, preview)
        remove_stale_files(out_dir, previous - written)
        write_marker(out_dir, "leaderboard", written)
    return out_dir / "leaderboard.html"


def _recording_path(results_dirs: list[Path], rec: str) -> Path | None:
    """The recording ``rec`` (its path relative to the evaluated dataset, as results.csv names it) for its
    preview: under the dataset a results directory's ``results.json`` names as its target, else under the folders
    above the results directory (``output/mini/results`` lies in the dataset); None where it is not found."""
    for d in results_dirs:
        target = _results_json(d).get("target")
        candidates = ([Path(target)] if isinstance(target, str) and target else []) + [d.parent, d.parent.parent]
        for c in candidates:
            path = c if c.is_file() and c.name == Path(rec).name else c / rec
            if path.suffix in (".h5", ".hdf5") and path.is_file():
                return path
    return None


def _write_leaderboard(results_dirs: list[Path], out_dir: Path, preview=None) -> set[str]:
    """Write the leaderboard's files into ``out_dir``; return their paths relative to it."""
    written = set()

    def write_bytes(rel: str, data: bytes) -> None:
        with atomic_path(out_dir / rel) as tmp:
            tmp.write_bytes(data)
        written.add(rel)

    board = build_board(results_dirs)
    plots = {"PSNR versus lux": plot_psnr_vs_lux(board), "PSNR versus bandwidth": plot_psnr_vs_bandwidth(board)}
    budget = plot_budget_fronts(board, budget_fronts(board))
    if budget is not None:
        plots["PSNR at a bandwidth budget"] = budget
    plot_files = {}
    for name, png in plots.items():
        fname = f"leaderboard_{slug(name.lower().replace(' ', '_'))}.png"
        write_bytes(fname, png)
        plot_files[name] = fname
    regime = build_regime(board)
    regime_figures = [("PSNR over light level and image speed", "psnr", plot_regime_heatmaps(board, regime)),
                      ("best S+E minus best F+E", "se_minus_fe", plot_spad_minus_frames(regime)),
                      ("PSNR against bandwidth per cell", "pareto", plot_pareto_cells(board, regime))]
    regime_pngs, regime_files = {}, {}
    for name, short, png in regime_figures:
        if png is None:
            continue
        regime_pngs[name] = png
        regime_files[name] = f"leaderboard_regime_{short}.png"
        write_bytes(regime_files[name], png)
    with atomic_path(out_dir / "leaderboard_regime.csv") as tmp:
        write_regime_csv(tmp, board, regime)
    written.add("leaderboard_regime.csv")
    strips, strip_files, previews = [], [], {}
    keys, strip_note = strip_keys(board)
    for scene, lux, rec in keys:
        title = strip_title(board, rec)
        png = strip_png(board, rec, scene, lux, title)
        if png is None:
            continue
        strips.append((title, png))
        fname = f"leaderboard_strips/{slug(Path(rec).stem)}.png"
        check_no_link(out_dir, fname)  # a link named leaderboard_strips would take the strips elsewhere
        (out_dir / "leaderboard_strips").mkdir(exist_ok=True)
        write_bytes(fname, png)
        strip_files.append((title, fname))
        rec_path = _recording_path(results_dirs, rec) if preview is not None else None
        if rec_path is not None:
            gif = f"leaderboard_strips/{slug(Path(rec).stem)}.gif"
            check_no_link(out_dir, gif)
            try:
                preview(rec_path, out_dir / gif)
            except SimSpadError:
                continue  # a recording that cannot be previewed keeps its strip, without a preview
            written.add(gif)
            previews[title] = (gif, (out_dir / gif).read_bytes())
    with atomic_path(out_dir / "leaderboard.csv") as tmp:
        write_csv_table(tmp, board)
    real = real_recordings(results_dirs)  # recordings without ground truth: a section of their own
    with atomic_path(out_dir / "leaderboard.md") as tmp:
        tmp.write_text(render_markdown(board, plot_files, strip_files, regime, regime_files, strip_note,
                                       {t: f for t, (f, _) in previews.items()})
                       + real_data_markdown(board, real, md_table, md_escape), encoding="utf-8")
    with atomic_path(out_dir / "leaderboard.html") as tmp:
        page = render_html(board, plots, strips, regime, regime_pngs, strip_note,
                           {t: gif for t, (_, gif) in previews.items()})
        tmp.write_text(page.replace("</body></html>", real_data_html(board, real, _html_table) + "</body></html>"),
                       encoding="utf-8")
    written |= {"leaderboard.csv", "leaderboard.md", "leaderboard.html"}
    return written
