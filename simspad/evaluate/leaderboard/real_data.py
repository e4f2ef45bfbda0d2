"""The leaderboard's real-data section: recordings without ground truth (``simspad import``), one table each.

A results directory's ``results.json`` marks each recording with ``ground_truth`` (false for real captures). For
each such recording the methods are listed by their Siemens-star MTF at 0.25 cycles/px, or at 0.40 where the
star cannot measure 0.25 at the recording's resolution (highest first; methods without a value after them, in the
board's order), with the MTF at 0.40 cycles/px, MTF50 and the bandwidth. PSNR
and SSIM do not exist without ground truth and are not shown; the MTF is relative to a perfect print of the star
(:mod:`simspad.evaluate.real_data`). Without a declared star region the MTF cells are "–".
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

from simspad.evaluate.leaderboard.board import Board

REAL_DATA_NOTE = ("Real captures (no ground truth): PSNR and SSIM cannot be measured. MTF = the reconstruction's "
                  "modulation on the calibration's Siemens-star region relative to a perfect print of the star's "
                  "contrast (1 = fully resolved); – = not measurable (no star declared, a frequency outside the "
                  "star's band, or a failed run).")
_COLUMNS = (("mtf_at_0p25_cyc_px", "MTF @ 0.25 cyc/px", 3), ("mtf_at_0p40_cyc_px", "MTF @ 0.40 cyc/px", 3),
            ("mtf50_cyc_px", "MTF50 (cyc/px)", 3), ("bandwidth_khz_per_pixel", "kHz/px", 2))


def real_recordings(results_dirs) -> set[str]:
    """Recordings (``recording`` column values) marked ``ground_truth: false`` in any ``results.json``."""
    out: set[str] = set()
    for d in results_dirs:
        try:
            meta = json.loads((Path(d) / "results.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        for r in (meta.get("recordings") or []) if isinstance(meta, dict) else []:
            if isinstance(r, dict) and r.get("ground_truth") is False and isinstance(r.get("recording"), str):
                out.add(r["recording"])
    return out


def _finite(v) -> bool:
    return isinstance(v, float) and math.isfinite(v)


def _cell(v, digits: int) -> str:
    return f"{v:.{digits}f}" if isinstance(v, float) and math.isfinite(v) else "–"


def real_data_tables(board: Board, real: set[str]) -> list[tuple[str, list[str], list[list[tuple[str, bool]]]]]:
    """(title, header, body) per real recording; body cells are (text, best) like the other tables."""
    out = []
    for rec in sorted(real):
        rows = {r["method"]: r for r in board.rows if r["recording"] == rec}
        if not rows:
            continue
        order = {m: i for i, m in enumerate(board.methods)}

        # ranked by the lowest star frequency any method could be measured at (0.25, else 0.40 cycles/px)
        rank_col = next((c for c in ("mtf_at_0p25_cyc_px", "mtf_at_0p40_cyc_px")
                         if any(_finite(r.get(c)) and not r.get("error") for r in rows.values())),
                        "mtf_at_0p25_cyc_px")

        def key(m):
            v = rows[m].get(rank_col, float("nan")) if not rows[m].get("error") else float("nan")
            ok = _finite(v)
            return (0 if ok else 1, -v if ok else 0.0, order.get(m, len(order)))

        methods = sorted(rows, key=key)
        best = {}
        for col, _, _ in _COLUMNS[:3]:
            vals = [rows[m].get(col) for m in methods if not rows[m].get("error")]
            vals = [v for v in vals if isinstance(v, float) and math.isfinite(v)]
            best[col] = max(vals) if vals else None
        body = []
        for m in methods:
            r = rows[m]
            label = board.info.get(m, {}).get("label", m)
            cells = [(label, False)]
            for col, _, digits in _COLUMNS:
                v = float("nan") if r.get("error") else r.get(col, float("nan"))
                cells.append((_cell(v, digits), best.get(col) is not None and v == best[col]))
            body.append(cells)
        first = next(iter(rows.values()))
        title = f"{first.get('scene', rec)} ({rec})"
        out.append((title, ["Method"] + [h for _, h, _ in _COLUMNS], body))
    return out


def real_data_markdown(board: Board, real: set[str], md_table, md_escape) -> str:
    """The section in markdown (empty without real recordings); ``md_table``/``md_escape`` from the page."""
    tables = real_data_tables(board, real)
    if not tables:
        return ""
    out = ["", "## Real captures (no ground truth)", "", md_escape(REAL_DATA_NOTE), ""]
    for title, header, body in tables:
        out += [f"### {md_escape(title)}", "", md_table(header, body, 1), ""]
    return "\n".join(out)


def real_data_html(board: Board, real: set[str], html_table) -> str:
    """The section in HTML (empty without real recordings); ``html_table`` from the page."""
    tables = real_data_tables(board, real)
    if not tables:
        return ""
    parts = ["<h2>Real captures (no ground truth)</h2>", f"<p class=\"note\">{html.escape(REAL_DATA_NOTE)}</p>"]
    for title, header, body in tables:
        parts += [f"<h3>{html.escape(title)}</h3>", html_table(header, body)]
    return "\n".join(parts) + "\n"
