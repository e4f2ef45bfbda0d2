"""Writing a leaderboard: ``leaderboard.md``, ``leaderboard.csv``, ``leaderboard_regime.csv``,
``leaderboard.html`` and the PNG files the markdown links (``leaderboard_*.png``, ``leaderboard_strips/``), each
written atomically.
"""

from __future__ import annotations

from pathlib import Path

from simspad.errors import SimSpadError
from simspad.evaluate.leaderboard.board import build_board
from simspad.evaluate.leaderboard.html_page import render_html
from simspad.evaluate.leaderboard.markdown_page import render_markdown
from simspad.evaluate.leaderboard.plots import plot_psnr_vs_bandwidth, plot_psnr_vs_lux, strip_keys, strip_png
from simspad.evaluate.leaderboard.regime import build_regime, write_regime_csv
from simspad.evaluate.leaderboard.regime_plots import plot_pareto_cells, plot_regime_heatmaps, plot_spad_minus_frames
from simspad.evaluate.leaderboard.tables import write_csv_table
from simspad.io.atomic import atomic_path, ensure_writable_dir
from simspad.io.results_dir import slug


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
        _write_bytes(out_dir / regime_files[name], png)
    with atomic_path(out_dir / "leaderboard_regime.csv") as tmp:
        write_regime_csv(tmp, board, regime)
    strips, strip_files = [], []
    keys, strip_note = strip_keys(board)
    for scene, lux, rec in keys:
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
        tmp.write_text(render_markdown(board, plot_files, strip_files, regime, regime_files, strip_note),
                       encoding="utf-8")
    html_path = out_dir / "leaderboard.html"
    with atomic_path(html_path) as tmp:
        tmp.write_text(render_html(board, plots, strips, regime, regime_pngs, strip_note), encoding="utf-8")
    return html_path
